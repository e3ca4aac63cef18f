r"""First integrals of the three-dimensional Suslov problem (``J = diag(J1, J2, J3)``, ``omega_3 = 0``).

Equations (3.1) with the constraint ``omega_3 = 0`` and, optionally, the gyroscopic torque
``eps Gamma x omega``:

.. math::

    J_1\dot\omega_1 = \Gamma_2 V_3 - \Gamma_3 V_2 - \epsilon\Gamma_3\omega_2,\qquad
    J_2\dot\omega_2 = \Gamma_3 V_1 - \Gamma_1 V_3 + \epsilon\Gamma_3\omega_1,\qquad
    \dot\Gamma = \Gamma\times\omega

(``V_i = dV/dGamma_i``; the third row only fixes the multiplier). Each function below is an exact
first integral of that system, derived by differentiating along it (the derivations are in the
docstrings and the integrals are checked along DOP853 trajectories in ``tests/test_analytic.py``).
All functions are batched: ``omega`` (..., 3) with ``omega_3 = 0``, ``Gamma`` (..., 3) → (...).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from . import _checks as C

__all__ = ["family3_integral", "gyroscopic3_free_integrals", "gyroscopic3_linear_integral",
           "gyroscopic3_quadratic_integral", "kharlamova3_integral", "klebsh_tisserand3_integral",
           "lagrange3_integral"]


def _J(J: Any) -> np.ndarray:
    J = C.as_array(J, "J")
    if J.shape != (3,) or np.any(J <= 0.0):
        raise ValueError(f"J must be the principal moments (J1, J2, J3), shape (3,), all > 0, got {J}")
    return J


def _omega(omega: Any) -> np.ndarray:
    omega = C.as_array(omega, "omega", tail=(3,))
    if np.any(np.abs(omega[..., 2]) > 1e-10 * (1.0 + np.linalg.norm(omega, axis=-1))):
        raise ValueError("omega must satisfy the constraint omega_3 = 0")
    return omega


def _Gamma(Gamma: Any) -> np.ndarray:
    Gamma = C.as_array(Gamma, "Gamma", tail=(3,))
    C.check_unit(Gamma, "Gamma")
    return Gamma


def lagrange3_integral(omega: Any, Gamma: Any, J: Any) -> np.ndarray:
    """Lagrange case (``J1 = J2``, ``V = B3 Gamma_3``): ``F = <J omega, Gamma>``.

    ``d/dt (J1 w1 G1 + J1 w2 G2) = B3 G2 G1 - J1 w1 G3 w2 - B3 G1 G2 + J1 w2 G3 w1 = 0``; the
    multiplier is ``lambda = (J2 - J1) w1 w2 = 0``.
    """
    J = _J(J)
    if J[0] != J[1]:
        raise ValueError(f"J: the Lagrange case needs J1 = J2, got {J.tolist()}")
    return np.sum(J * _omega(omega) * _Gamma(Gamma), axis=-1)


def kharlamova3_integral(omega: Any, J: Any, B: Any) -> np.ndarray:
    """Kharlamova case (``V = B1 Gamma_1 + B2 Gamma_2``): ``F = J1 w1 B1 + J2 w2 B2``.

    ``J1 w1' = -B2 G3``, ``J2 w2' = B1 G3``. ``B`` has shape (2,).
    """
    J = _J(J)
    B = C.as_array(B, "B")
    if B.shape != (2,):
        raise ValueError(f"B must be (B1, B2), shape (2,), got {B.shape}")
    w = _omega(omega)
    return J[0] * w[..., 0] * B[0] + J[1] * w[..., 1] * B[1]


def klebsh_tisserand3_integral(omega: Any, Gamma: Any, J: Any, eps: float) -> np.ndarray:
    r"""Klebsh–Tisserand case (``V = eps <J Gamma, Gamma>/2``): ``F = <J w, J w>/2 - <A Gamma, Gamma>/2``,
    ``A = eps det(J) J^-1 = eps diag(J2 J3, J1 J3, J1 J2)``.

    On ``|Gamma| = 1`` it equals the family integral with ``v1 = eps (J1 - J3) G1^2/2``,
    ``v2 = eps (J2 - J3) G2^2/2`` minus the constant ``eps J1 J2 / 2``.
    """
    J = _J(J)
    eps = C.as_scalar(eps, "eps")
    w, G = _omega(omega), _Gamma(Gamma)
    A = eps * np.array([J[1] * J[2], J[0] * J[2], J[0] * J[1]])
    return 0.5 * np.sum((J * w) ** 2, axis=-1) - 0.5 * np.sum(A * G * G, axis=-1)


def family3_integral(omega: Any, Gamma: Any, J: Any, v1: Callable[[np.ndarray, np.ndarray], np.ndarray],
                     v2: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    r"""The family ``V = v1(G1, G2^2 + G3^2) + v2(G2, G1^2 + G3^2)``: ``F = <J w, J w>/2 + J2 v1 + J1 v2``.

    Derivation: along the flow ``d v1/dt = -G3 w2 (dv1/dx - 2 G1 dv1/ds)`` and
    ``d v2/dt = G3 w1 (dv2/dx - 2 G2 dv2/ds)``, while ``v1`` contributes
    ``J2 w2 G3 (dv1/dx - 2 G1 dv1/ds)`` and ``v2`` contributes ``-J1 w1 G3 (dv2/dx - 2 G2 dv2/ds)`` to
    ``d/dt <J w, J w>/2``: the weights are ``J2`` on ``v1`` and ``J1`` on ``v2`` as in the paper.
    (The derivation does not need ``J1 != J2``.)

    ``v1(x, s)`` and ``v2(x, s)`` are vectorised callables of two arrays.
    """
    J = _J(J)
    w, G = _omega(omega), _Gamma(Gamma)
    g1, g2, g3 = G[..., 0], G[..., 1], G[..., 2]
    return (0.5 * np.sum((J * w) ** 2, axis=-1) + J[1] * np.asarray(v1(g1, g2 * g2 + g3 * g3))
            + J[0] * np.asarray(v2(g2, g1 * g1 + g3 * g3)))


def gyroscopic3_free_integrals(omega: Any, Gamma: Any, J: Any, eps: float) -> np.ndarray:
    """Gyroscopic, ``V = 0``: ``(J1 w1 - eps G1, J2 w2 - eps G2)``, shape (..., 2).

    ``J1 w1' = -eps G3 w2 = eps G1'`` and ``J2 w2' = eps G3 w1 = eps G2'``.
    """
    J = _J(J)
    eps = C.as_scalar(eps, "eps")
    w, G = _omega(omega), _Gamma(Gamma)
    return J[:2] * w[..., :2] - eps * G[..., :2]


def gyroscopic3_linear_integral(omega: Any, Gamma: Any, J: Any, eps: float, B: Any) -> np.ndarray:
    """Gyroscopic, ``V = B1 G1 + B2 G2``: ``F = B1 (J1 w1 - eps G1) + B2 (J2 w2 - eps G2)``.

    ``J1 w1' = -G3 (B2 + eps w2)``, ``J2 w2' = G3 (B1 + eps w1)``; so
    ``d/dt (B1 J1 w1 + B2 J2 w2) = eps G3 (B2 w1 - B1 w2) = eps d/dt (B1 G1 + B2 G2)``.
    """
    J = _J(J)
    eps = C.as_scalar(eps, "eps")
    B = C.as_array(B, "B")
    if B.shape != (2,):
        raise ValueError(f"B must be (B1, B2), shape (2,), got {B.shape}")
    F2 = gyroscopic3_free_integrals(omega, Gamma, J, eps)
    return B[0] * F2[..., 0] + B[1] * F2[..., 1]


def gyroscopic3_quadratic_integral(omega: Any, Gamma: Any, J: Any, eps: float, a: Any) -> np.ndarray:
    r"""Gyroscopic, ``V = (a1 G1^2 + a2 G2^2 + a3 G3^2)/2``; with ``b_i = a_i - a3``:

    .. math::

        F = J_1J_2(b_2\omega_1^2 + b_1\omega_2^2) + b_1(J_1b_1 - \epsilon^2)\Gamma_1^2
            + b_2(J_2b_2 - \epsilon^2)\Gamma_2^2 + 2\epsilon(J_1b_1\omega_1\Gamma_1 + J_2b_2\omega_2\Gamma_2).

    Derivation: the ansatz ``alpha_1 w1^2 + alpha_2 w2^2 + beta_1 G1^2 + beta_2 G2^2
    + eps (delta_1 w1 G1 + delta_2 w2 G2) + eps^2 (g_1 G1^2 + g_2 G2^2)`` is an integral iff
    ``beta_1 = alpha_2 b1/J2``, ``beta_2 = alpha_1 b2/J1``, ``delta_1 b2/J1 = delta_2 b1/J2``,
    ``2 alpha_2/J2 - 2 alpha_1/J1 = delta_1 - delta_2`` and ``g_i = -delta_i/(2 J_i)``: a
    two-parameter family, spanned by ``2 E`` (``delta = 0``) and the ``F`` above
    (``delta_i = 2 J_i b_i``), valid for every ``a`` and ``J``.
    """
    J = _J(J)
    eps = C.as_scalar(eps, "eps")
    a = C.as_array(a, "a")
    if a.shape != (3,):
        raise ValueError(f"a must be (a1, a2, a3), shape (3,), got {a.shape}")
    w, G = _omega(omega), _Gamma(Gamma)
    b1, b2 = a[0] - a[2], a[1] - a[2]
    J1, J2 = J[0], J[1]
    w1, w2, g1, g2 = w[..., 0], w[..., 1], G[..., 0], G[..., 1]
    return (J1 * J2 * (b2 * w1 ** 2 + b1 * w2 ** 2) + b1 * (J1 * b1 - eps ** 2) * g1 ** 2
            + b2 * (J2 * b2 - eps ** 2) * g2 ** 2 + 2.0 * eps * (J1 * b1 * w1 * g1 + J2 * b2 * w2 * g2))
