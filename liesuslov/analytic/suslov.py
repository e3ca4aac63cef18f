r"""Suslov's problem without potential: asymptotic points, which one is approached, the 3-D solution.

n = 3, vector form
------------------
``J`` a symmetric positive definite 3x3 matrix acting on ``omega``, constraint ``omega_3 = 0``
(``a = e3``, not an eigenvector of ``J``): ``J omega' = J omega x omega + lambda e3``. Its first two
rows give, with ``J_D = J[:2, :2]``, ``b = (J13, J23) != 0`` and ``R(x, y) = (-y, x)``,

.. math::

    J_D\dot\omega = \langle b, \omega\rangle\, R\,\omega,\qquad
    \dot\omega = \frac{\langle b,\omega\rangle}{\det J_D}\, R J_D\,\omega .

The energy ``h = omega^T J_D omega / 2`` is conserved and ``omega`` runs along the ellipse; the
fixed points are its intersections with the line ``<b, omega> = 0``. Writing
``omega = C e(psi + psi_b)``, ``C = sqrt(2h) J_D^{-1/2}``, ``e(x) = (cos x, sin x)``, the angle ``psi``
measured from ``C b / |C b|`` obeys ``psi' = kappa cos psi`` with ``kappa = |C b| / sqrt(det J_D)``:

.. math::

    \sin\psi(t) = \tanh(\kappa t + s_0),\qquad \cos\psi(t) = \pm\,\mathrm{sech}(\kappa t + s_0),
    \qquad s_0 = \operatorname{artanh}\sin\psi_0,

the sign of ``cos psi`` being that of ``cos psi_0`` (a tanh law along the ellipse). Hence
``omega -> w_+ = mu R b`` (``mu > 0``, energy ``h``) as ``t -> +inf`` and ``-> w_- = -w_+`` as
``t -> -inf``, for every initial condition except the fixed points themselves.

n-dimensional, Fedorov–Kozlov constraints
-----------------------------------------
General symmetric mass tensor ``I`` (n x n), ``Omega = sum_i u_i E_in``. Projecting ``J(Omega') = [M, Omega]``
on ``D`` (``Omega^2 = -u u^T - |u|^2 e_n e_n^T``) gives

.. math::

    K\dot u = u\,(b\cdot u) - |u|^2\, b,\qquad K = I_{[:n-1,:n-1]} + I_{nn}\,\mathrm{Id},\quad
    b = (I_{1n}, \dots, I_{n-1,n}),

with energy ``h = u^T K u / 2``. The fixed points on the ellipsoid are ``u = +-mu b``. The function
``L(u) = b^T K u`` decreases strictly, ``dL/dt = (b.u)^2 - |u|^2 |b|^2 <= 0`` (Cauchy–Schwarz, equality
only at the fixed points), so every trajectory tends to ``w_+ = -mu b`` as ``t -> +inf`` (the
minimum of ``L``) and to ``w_- = +mu b`` as ``t -> -inf``; linearising at ``+mu b`` gives the operator
``mu |b|^2 K^-1 P_perp`` with positive eigenvalues transverse to ``b``: ``w_-`` is a repeller. For
``n = 3`` (``u = (omega_2, -omega_1)``, ``J = tr(I) Id - I``) this is the vector form above.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import as_float_array, unit_vectors
from . import _checks as C

__all__ = ["Suslov3Free", "suslov3_asymptotic_points", "suslov3_energy", "suslov_asymptotic_points",
           "suslov_energy", "suslov_limits", "suslov_lyapunov", "suslov_reduced_field"]

_R = np.array([[0.0, -1.0], [1.0, 0.0]])


# ============================================================================================ n = 3
def _J3(J: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    J = C.symmetric_matrix(J, "J", n=3)
    b = J[:2, 2]
    if np.all(b == 0.0):
        raise ValueError("J: e3 is an eigenvector of J (J13 = J23 = 0); then omega is constant and there are "
                         "no asymptotic points")
    return J, J[:2, :2], b


def _omega3(omega: Any) -> np.ndarray:
    omega = C.as_array(omega, "omega", tail=(3,))
    if np.any(np.abs(omega[..., 2]) > 1e-10 * (1.0 + np.linalg.norm(omega, axis=-1))):
        raise ValueError("omega must satisfy the constraint omega_3 = 0")
    return omega


def suslov3_energy(omega: Any, J: Any) -> np.ndarray:
    """``h = <J omega, omega>/2`` with ``omega_3 = 0``; ``omega`` (..., 3), ``J`` (3, 3) → (...)."""
    J = C.symmetric_matrix(J, "J", n=3)
    w = _omega3(omega)[..., :2]
    return 0.5 * np.einsum("...i,ij,...j->...", w, J[:2, :2], w)


def suslov3_asymptotic_points(J: Any, energy: Any, a: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """The points ``w_+`` (limit as ``t -> +inf``) and ``w_- = -w_+`` (``t -> -inf``) on the energy ellipse.

    For the constraint ``<a, omega> = 0`` with any unit vector ``a`` (default ``e3``):
    ``w_+ = mu (a x J a)``, ``mu >= 0`` fixed by ``<J w, w>/2 = h``. (A rotation Q with ``Q a = e3``
    maps the problem to ``a = e3`` with ``Q J Q^T``, where ``w_+ = mu e3 x (Q J Q^T) e3 = mu (-J23, J13, 0)``;
    the cross product commutes with rotations, so ``w_+ = mu Q^T (e3 x Q J a) = mu a x J a``.)

    Parameters
    ----------
    J : array_like, shape (3, 3)
        Symmetric positive definite, ``a`` not an eigenvector (``a x J a != 0``).
    energy : array_like, shape (...)
        ``h >= 0``.
    a : array_like, shape (3,), optional
        Unit constraint vector (``|a| = 1`` within 1e-8; normalised). Default ``e3``.

    Returns
    -------
    w_plus, w_minus : ndarray, shape (..., 3)
        ``w_+ = mu (a x J a)``: for ``a = e3``, ``mu (-J23, J13, 0)``.
    """
    if a is None:
        J, _, _ = _J3(J)
        a = np.array([0.0, 0.0, 1.0])
    else:
        J = C.symmetric_matrix(J, "J", n=3)
        a = unit_vectors(as_float_array(a, "a", tail=(3,)), "a")
        if a.ndim != 1:
            raise ValueError(f"a must be one unit vector of shape (3,), got shape {a.shape}")
    h = C.as_array(energy, "energy")
    if np.any(h < 0.0):
        raise ValueError("energy must be nonnegative")
    d = np.cross(a, J @ a)
    if np.linalg.norm(d) <= 1e-12 * np.linalg.norm(J):
        raise ValueError("a is an eigenvector of J (a x J a = 0): omega is then constant and there are no "
                         "asymptotic points")
    mu = np.sqrt(2.0 * h / (d @ J @ d))
    wp = mu[..., None] * d
    return wp, -wp


class Suslov3Free:
    r"""Explicit solution of the 3-D Suslov problem with ``V = 0`` (batched over ``omega0``).

    Parameters
    ----------
    omega0 : array_like, shape (..., 3)
        Initial angular velocity with ``omega_3 = 0``.
    J : array_like, shape (3, 3)
        Symmetric positive definite, ``e3`` not an eigenvector.
    tol : float
        Initial data within ``tol`` (relative, on the unit circle ``C^-1 omega``) of ``w_+-`` are
        taken as the fixed point itself.

    Attributes
    ----------
    energy : ndarray, shape (...)
    w_plus, w_minus : ndarray, shape (..., 3)
        Asymptotic points (see :func:`suslov3_asymptotic_points`).
    rate : ndarray, shape (...)
        ``kappa = |C b| / sqrt(det J_D)``: the approach is ``~ exp(-kappa |t|)``.
    limit_plus, limit_minus : ndarray, shape (..., 3)
        ``lim omega(t)`` as ``t -> +inf`` and ``t -> -inf`` (``w_+``, ``w_-``, except at a fixed point).
    """

    def __init__(self, omega0: Any, J: Any, *, tol: float = 1e-12) -> None:
        J, JD, b = _J3(J)
        w0 = _omega3(omega0)
        self.batch_shape = w0.shape[:-1]
        self.J = J
        w = w0[..., :2]
        h = 0.5 * np.einsum("...i,ij,...j->...", w, JD, w)
        lam, V = np.linalg.eigh(JD)
        Jmh = V @ np.diag(lam ** -0.5) @ V.T             # J_D^{-1/2}
        Jph = V @ np.diag(lam ** 0.5) @ V.T
        self._h = h
        self._Cunit = Jmh                                 # C = sqrt(2h) J_D^{-1/2}
        rt = np.sqrt(2.0 * h)
        Cb = rt[..., None] * (Jmh @ b)
        nCb = np.linalg.norm(Cb, axis=-1)
        pos = nCb > 0.0
        chat = np.where(pos[..., None], Cb / np.where(pos, nCb, 1.0)[..., None], np.array([1.0, 0.0]))
        e0 = np.where(pos[..., None], (w @ Jph) / np.where(pos, rt, 1.0)[..., None], chat)   # C^-1 omega0
        self._chat = chat
        self._sin0 = np.sum(e0 * (chat @ _R.T), axis=-1)
        self._cos0 = np.sum(e0 * chat, axis=-1)
        self._kappa = nCb / np.sqrt(np.linalg.det(JD))
        fixed = np.abs(self._cos0) <= tol              # at w_+ or w_- (to tol): stays there
        with np.errstate(divide="ignore"):
            self._s0 = np.where(fixed, np.where(self._sin0 > 0.0, np.inf, -np.inf),
                                np.arcsinh(self._sin0 / np.where(fixed, 1.0, np.abs(self._cos0))))
        self._sig = np.where(self._cos0 >= 0.0, 1.0, -1.0)
        self.w_plus, self.w_minus = suslov3_asymptotic_points(J, h)
        fixed_minus = np.isneginf(self._s0)
        fixed_plus = np.isposinf(self._s0)
        self.limit_plus = np.where(fixed_minus[..., None], self.w_minus, self.w_plus)
        self.limit_minus = np.where(fixed_plus[..., None], self.w_plus, self.w_minus)

    @property
    def energy(self) -> np.ndarray:
        return self._h

    @property
    def rate(self) -> np.ndarray:
        return self._kappa

    def omega(self, t: Any) -> np.ndarray:
        """``omega(t)``, shape ``t.shape + batch_shape + (3,)``, from the tanh law."""
        t = C.times(t)
        tt = t.reshape(t.shape + (1,) * len(self.batch_shape))
        s = self._kappa * tt + self._s0
        fin = np.isfinite(s)
        sf = np.where(fin, s, 0.0)
        ex = np.exp(-2.0 * np.abs(sf))
        sin = np.where(fin, np.tanh(sf), np.sign(s))
        sech = np.where(fin, 2.0 * np.sqrt(ex) / (1.0 + ex), 0.0)
        cos = self._sig * sech
        e = cos[..., None] * self._chat + sin[..., None] * (self._chat @ _R.T)
        w = np.sqrt(2.0 * self._h)[..., None] * (e @ self._Cunit.T)
        return np.concatenate([w, np.zeros(w.shape[:-1] + (1,))], axis=-1)


# ============================================================================================ n-D
def _mass(I: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    I = C.symmetric_matrix(I, "I", positive=False)
    n = I.shape[0]
    if n < 3:
        raise ValueError(f"I must be n x n with n >= 3, got {I.shape}")
    lam = np.linalg.eigvalsh(I)
    if np.any((lam[:, None] + lam[None, :])[~np.eye(n, dtype=bool)] <= 0.0):
        raise ValueError("I: the inertia operator J(Omega) = I Omega + Omega I needs lambda_i + lambda_j > 0 "
                         f"for the eigenvalues of I, got {lam.tolist()}")
    K = I[:-1, :-1] + I[-1, -1] * np.eye(n - 1)
    b = I[:-1, -1].copy()
    return I, K, b


def _b_nonzero(b: np.ndarray) -> None:
    if np.all(b == 0.0):
        raise ValueError("I: I_in = 0 for all i < n, so D is an eigenspace of J and Omega is constant; there "
                         "are no asymptotic points")


def suslov_energy(u: Any, I: Any) -> np.ndarray:
    """``h = u^T K u / 2``, ``K = I[:n-1, :n-1] + I_nn Id``; ``u`` (..., n-1), ``I`` (n, n) → (...)."""
    I, K, _ = _mass(I)
    u = C.as_array(u, "u", tail=(I.shape[0] - 1,))
    return 0.5 * np.einsum("...i,ij,...j->...", u, K, u)


def suslov_reduced_field(u: Any, I: Any) -> np.ndarray:
    """``u' = K^-1 (u (b.u) - |u|^2 b)``, the reduced Fedorov–Kozlov equation with ``V = 0``; (..., n-1)."""
    I, K, b = _mass(I)
    u = C.as_array(u, "u", tail=(I.shape[0] - 1,))
    rhs = u * (u @ b)[..., None] - np.sum(u * u, axis=-1)[..., None] * b
    return np.linalg.solve(K, rhs[..., None])[..., 0]


def suslov_lyapunov(u: Any, I: Any) -> np.ndarray:
    """``L(u) = b^T K u``, strictly decreasing along non-stationary motions; (..., n-1) → (...)."""
    I, K, b = _mass(I)
    u = C.as_array(u, "u", tail=(I.shape[0] - 1,))
    return u @ (K @ b)


def suslov_asymptotic_points(I: Any, energy: Any) -> tuple[np.ndarray, np.ndarray]:
    """``w_+ = -mu b`` (limit as ``t -> +inf``) and ``w_- = +mu b`` (``t -> -inf``), ``u^T K u / 2 = h``.

    Parameters
    ----------
    I : array_like, shape (n, n)
        Symmetric mass tensor with ``b = (I_1n, ..., I_{n-1,n}) != 0``.
    energy : array_like, shape (...)

    Returns
    -------
    w_plus, w_minus : ndarray, shape (..., n-1)
    """
    I, K, b = _mass(I)
    _b_nonzero(b)
    h = C.as_array(energy, "energy")
    if np.any(h < 0.0):
        raise ValueError("energy must be nonnegative")
    mu = np.sqrt(2.0 * h / (b @ K @ b))
    wm = mu[..., None] * b
    return -wm, wm


def suslov_limits(u0: Any, I: Any, *, tol: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """``lim u(t)`` as ``t -> +inf`` and as ``t -> -inf`` for the initial data ``u0`` (..., n-1).

    ``w_+`` and ``w_-`` respectively, except when ``u0`` is a fixed point (within ``tol`` relative),
    which is its own limit both ways.
    """
    I, K, b = _mass(I)
    _b_nonzero(b)
    u0 = C.as_array(u0, "u0", tail=(I.shape[0] - 1,))
    h = 0.5 * np.einsum("...i,ij,...j->...", u0, K, u0)
    wp, wm = suslov_asymptotic_points(I, h)
    scale = np.maximum(np.linalg.norm(wp, axis=-1), np.finfo(float).tiny)
    at_m = np.linalg.norm(u0 - wm, axis=-1) <= tol * scale
    at_p = np.linalg.norm(u0 - wp, axis=-1) <= tol * scale
    lim_p = np.where(at_m[..., None], wm, wp)
    lim_m = np.where(at_p[..., None], wp, wm)
    return lim_p, lim_m
