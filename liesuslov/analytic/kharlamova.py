r"""The n-dimensional Kharlamova case in closed form (Fedorov–Kozlov constraints, ``V = sum B_i Gamma_i``).

Equations (4.5): ``(I_i + I_n) u_i' = B_i Gamma_n``, ``Gamma_i' = -Gamma_n u_i`` (``i < n``),
``Gamma_n' = sum_i Gamma_i u_i``, with ``u = (Omega_1n, ..., Omega_{n-1,n})`` and all ``B_i != 0``.

Solution
--------
Write ``c_i = (I_i + I_n)/B_i`` and ``x(t) = int_0^t Gamma_n``. Then, exactly,

.. math::

    u_i = u_i^0 + x/c_i,\qquad \Gamma_i = \Gamma_i^0 - u_i^0 x - \frac{x^2}{2c_i}\ (i<n),\qquad
    \dot x = \Gamma_n,\qquad \Gamma_n^2 = P(x) = 1 - \sum_{i<n}\Gamma_i(x)^2 .

``x`` is the shift of the paper's ``omega_1 = c_1 u_1`` (coordinates (4.6)): ``omega_1 = omega_1^0 + x``,
and ``P4(omega_1) = P(omega_1 - omega_1^0)`` is the paper's quartic; (4.8) are the formulas for
``Gamma_i`` above. ``P(0) = (Gamma_n^0)^2 >= 0`` and the leading coefficient is
``-sum_i 1/(4 c_i^2) < 0``, so ``omega_1`` oscillates between the adjacent roots ``xi1 <= omega_1^0 <= xi2``
with period ``T = 2 int_{xi1}^{xi2} d omega_1 / sqrt(P4)``, or tends to a double root (``T = inf``).

With ``P = A (x - xi1)(xi2 - x) Q(x)``, ``Q`` monic quadratic positive on the interval (its roots
real on one side, or complex), and ``x = xi1 + (xi2 - xi1) sin^2 theta``, Carlson's formula for
a quartic (DLMF 19.29.4 with one limit at a root) gives the time from ``xi1``

.. math::

    t(\theta) = \frac{2}{\sqrt A}\,\sin\theta\; R_F\big(\cos^2\theta\,Q(\xi_1),\; f_3(x) f_4(\xi_1),\;
        f_4(x) f_3(\xi_1)\big),\qquad \frac{dt}{d\theta} = \frac{2}{\sqrt{A\,Q(x)}},

``f_3 f_4 = Q`` the two linear factors positive on the interval (complex conjugate for a complex
pair). ``T/2 = t(pi/2)``; the state at time ``t`` inverts ``t(theta)`` (monotone, smooth) by a
safeguarded Newton iteration; ``Gamma_n = dx/dt = +-sqrt(A) (xi2 - xi1) sin theta cos theta sqrt(Q(x))``.
"""

from __future__ import annotations

from math import comb
from typing import Any

import numpy as np
from scipy.special import elliprf

from . import _checks as C

__all__ = ["KharlamovaMotion", "kharlamova_coordinates", "kharlamova_from_coordinates",
           "kharlamova_integrals", "kharlamova_partial_energies", "kharlamova_quartic"]


def _params(I: Any, B: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    I = C.diagonal_mass(I, "I")
    n = I.shape[0]
    B = C.as_array(B, "B")
    if B.shape != (n - 1,):
        raise ValueError(f"B must have shape (n - 1,) = ({n - 1},) for I of shape ({n},), got {B.shape}")
    if np.any(B == 0.0):
        raise ValueError(f"B: the Kharlamova case needs every B_i != 0 (i < n), got {B.tolist()}")
    return I, B, (I[:-1] + I[-1]) / B


def _state(u: Any, Gamma: Any, n: int) -> tuple[np.ndarray, np.ndarray]:
    u = C.as_array(u, "u", tail=(n - 1,))
    Gamma = C.as_array(Gamma, "Gamma", tail=(n,))
    C.check_unit(Gamma, "Gamma")
    return u, Gamma


def kharlamova_coordinates(u: Any, Gamma: Any, I: Any, B: Any) -> tuple[np.ndarray, np.ndarray]:
    r"""The coordinates (4.6): ``omega_1 = c_1 u_1``, ``omega_i = c_i u_i - c_1 u_1``,
    ``gamma_1 = -c_1 Gamma_1``, ``gamma_i = -c_i Gamma_i + c_1 Gamma_1`` (``2 <= i < n``),
    ``gamma_n = Gamma_n``; ``c_i = (I_i + I_n)/B_i``.

    Parameters
    ----------
    u : array_like, shape (..., n-1)
        ``(Omega_1n, ..., Omega_{n-1,n})``.
    Gamma : array_like, shape (..., n)
        Unit vector.
    I : array_like, shape (n,)
    B : array_like, shape (n-1,)

    Returns
    -------
    omega : ndarray, shape (..., n-1)
    gamma : ndarray, shape (..., n)

    In these coordinates (4.5) reads (4.7): ``omega_1' = gamma_n``, ``omega_i' = 0``,
    ``gamma_i' = gamma_n omega_i``.
    """
    I, B, c = _params(I, B)
    n = I.shape[0]
    u = C.as_array(u, "u", tail=(n - 1,))
    Gamma = C.as_array(Gamma, "Gamma", tail=(n,))
    cu = c * u
    cG = c * Gamma[..., :-1]
    omega = np.concatenate([cu[..., :1], cu[..., 1:] - cu[..., :1]], axis=-1)
    gamma = np.concatenate([-cG[..., :1], -cG[..., 1:] + cG[..., :1], Gamma[..., -1:]], axis=-1)
    return omega, gamma


def kharlamova_from_coordinates(omega: Any, gamma: Any, I: Any, B: Any) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`kharlamova_coordinates`: ``(omega (..., n-1), gamma (..., n)) -> (u, Gamma)``."""
    I, B, c = _params(I, B)
    n = I.shape[0]
    omega = C.as_array(omega, "omega", tail=(n - 1,))
    gamma = C.as_array(gamma, "gamma", tail=(n,))
    w1, g1 = omega[..., :1], gamma[..., :1]
    cu = np.concatenate([w1, omega[..., 1:] + w1], axis=-1)
    cG = np.concatenate([-g1, -(gamma[..., 1:-1] + g1)], axis=-1)
    return cu / c, np.concatenate([cG / c, gamma[..., -1:]], axis=-1)


def kharlamova_integrals(u: Any, I: Any, B: Any) -> np.ndarray:
    """The integrals ``F_ij = (I_i + I_n)/B_i Omega_in - (I_j + I_n)/B_j Omega_jn``.

    Parameters
    ----------
    u : array_like, shape (..., n-1)
    I : array_like, shape (n,)
    B : array_like, shape (n-1,)

    Returns
    -------
    F : ndarray, shape (..., n-1, n-1)
        Antisymmetric, ``F[..., i, j] = c_i u_i - c_j u_j`` (0-based indices).
    """
    I, B, c = _params(I, B)
    u = C.as_array(u, "u", tail=(I.shape[0] - 1,))
    cu = c * u
    return cu[..., :, None] - cu[..., None, :]


def kharlamova_partial_energies(u: Any, Gamma: Any, I: Any, B: Any) -> np.ndarray:
    """``E_i = (I_i + I_n) Omega_in^2 / 2 + B_i Gamma_i`` (``i < n``), each conserved; ``E = sum_i E_i``.

    Shapes: ``u`` (..., n-1), ``Gamma`` (..., n) → (..., n-1).
    """
    I, B, _ = _params(I, B)
    n = I.shape[0]
    u = C.as_array(u, "u", tail=(n - 1,))
    Gamma = C.as_array(Gamma, "Gamma", tail=(n,))
    return 0.5 * (I[:-1] + I[-1]) * u ** 2 + B * Gamma[..., :-1]


def _shift_coefficients(p: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """Ascending coefficients of ``P(y - x0)`` from those of ``P(x)`` (last axis), batched."""
    deg = p.shape[-1] - 1
    out = np.zeros_like(p)
    for k in range(deg + 1):
        for j in range(k + 1):
            out[..., j] += p[..., k] * comb(k, j) * (-x0) ** (k - j)
    return out


def _quartic_x(u: np.ndarray, Gamma: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Ascending coefficients of ``P(x) = 1 - sum_i (Gamma_i - u_i x - x^2/(2 c_i))^2``."""
    a, b, d = Gamma[..., :-1], u, 0.5 / c
    p0 = Gamma[..., -1] ** 2
    p1 = 2.0 * np.sum(a * b, axis=-1)
    p2 = -np.sum(b * b - 2.0 * a * d, axis=-1)
    p3 = -2.0 * np.sum(b * d, axis=-1)
    p4 = np.broadcast_to(-np.sum(d * d), p0.shape)
    return np.stack([p0, p1, p2, p3, p4], axis=-1)


def kharlamova_quartic(u: Any, Gamma: Any, I: Any, B: Any) -> np.ndarray:
    r"""Coefficients, highest degree first, of ``P4`` with ``(d omega_1/dt)^2 = P4(omega_1)``.

    ``P4(omega_1) = 1 - (B_1/(I_1+I_n))^2 gamma_1^2 - sum_{i>=2} (B_i/(I_i+I_n))^2 (gamma_1 + gamma_i)^2``
    with ``gamma`` expressed through ``omega_1`` by (4.8) from the state ``(u, Gamma)``.

    Shapes: ``u`` (..., n-1), ``Gamma`` (..., n) → (..., 5).
    """
    I, B, c = _params(I, B)
    u, Gamma = _state(u, Gamma, I.shape[0])
    batch = C.broadcast_batch((u, 1), (Gamma, 1))
    u = np.broadcast_to(u, batch + u.shape[-1:])
    Gamma = np.broadcast_to(Gamma, batch + Gamma.shape[-1:])
    px = _quartic_x(u, Gamma, c)
    return _shift_coefficients(px, c[0] * u[..., 0])[..., ::-1]


def _polyval_asc(p: np.ndarray, x: np.ndarray) -> np.ndarray:
    out = np.zeros(np.broadcast_shapes(p.shape[:-1], np.shape(x)), dtype=np.result_type(p, x))
    for k in range(p.shape[-1] - 1, -1, -1):
        out = out * x + p[..., k]
    return out


class KharlamovaMotion:
    r"""Closed-form motion of the n-dimensional Kharlamova case from the state ``(u0, Gamma0)`` (batched).

    Parameters
    ----------
    u0 : array_like, shape (..., n-1)
        ``(Omega_1n, ..., Omega_{n-1,n})`` at ``t = 0``.
    Gamma0 : array_like, shape (..., n)
        Unit vector at ``t = 0``.
    I : array_like, shape (n,)
        Diagonal mass tensor, ``n >= 3``.
    B : array_like, shape (n-1,)
        ``V = sum_{i<n} B_i Gamma_i``, every ``B_i != 0``.
    asymptotic_tol : float
        A root of ``P4`` within ``asymptotic_tol * (xi2 - xi1)`` of an end of the oscillation interval
        makes it a double root: the motion is asymptotic and ``T = inf``. The roots of a quartic
        given to rounding are only ``sqrt(eps)``-accurate at a double root, hence the default.

    Attributes
    ----------
    omega1_0 : ndarray, shape (...)
        ``omega_1 = c_1 u_1`` at ``t = 0``.
    quartic : ndarray, shape (..., 5)
        ``P4`` in ``omega_1``, highest degree first (see :func:`kharlamova_quartic`).
    quartic_roots : ndarray of complex, shape (..., 4)
        Its roots, in ``omega_1``.
    bracket : ndarray, shape (..., 2)
        The adjacent real roots ``(xi1, xi2)`` with ``xi1 <= omega_1(0) <= xi2`` (``omega_1`` coordinates).
    kind : ndarray of str, shape (...)
        ``"periodic"``, ``"asymptotic"`` (a double root at an end: ``omega_1`` tends to it) or
        ``"equilibrium"`` (``Gamma_n = Gamma_n' = 0``: a fixed point).
    period : ndarray, shape (...)
        ``T = 2 int_{xi1}^{xi2} d omega_1 / sqrt(P4)``; ``inf`` when asymptotic, ``nan`` at an equilibrium.
        The whole state ``(u, Gamma)`` has period ``T``.
    """

    def __init__(self, u0: Any, Gamma0: Any, I: Any, B: Any, *, asymptotic_tol: float = 1e-7) -> None:
        I, B, c = _params(I, B)
        n = I.shape[0]
        u0, Gamma0 = _state(u0, Gamma0, n)
        self.I, self.B, self.n, self._c = I, B, n, c
        self.batch_shape = C.broadcast_batch((u0, 1), (Gamma0, 1))
        u0 = np.broadcast_to(u0, self.batch_shape + (n - 1,)).reshape(-1, n - 1)
        Gamma0 = np.broadcast_to(Gamma0, self.batch_shape + (n,)).reshape(-1, n)
        Gamma0 = Gamma0 / np.linalg.norm(Gamma0, axis=-1, keepdims=True)
        self._u0, self._G0 = u0, Gamma0
        self.u0 = u0.reshape(self.batch_shape + (n - 1,))
        self.Gamma0 = Gamma0.reshape(self.batch_shape + (n,))
        self._tol = float(asymptotic_tol)
        self._setup()

    # ------------------------------------------------------------------------------------------ setup
    def _setup(self) -> None:
        u0, G0, c = self._u0, self._G0, self._c
        nb = u0.shape[0]
        px = _quartic_x(u0, G0, c)
        self._px = px
        A = -px[:, 4]
        comp = np.zeros((nb, 4, 4))
        comp[:, 1:, :-1] = np.eye(3)
        comp[:, :, -1] = -px[:, :4] / px[:, 4:5]
        roots = np.linalg.eigvals(comp)
        scale = np.maximum(1.0, np.max(np.abs(roots), axis=-1))
        # A start near a turning point (Gamma_n(0) ~ 1e-8 or less): the root near 0, -P(0)/P'(0) = -Gamma_n^2/p1
        # to first order, is below the eigenvalues' rounding and may come out on the wrong side of 0 (a bracket
        # [0, 0]); its first-order value has the right side and is exact to (Gamma_n^2/p1)^2. Only for a
        # simple root (|p2 r| << |p1|): near a separatrix the root is one of a close pair.
        i0 = np.argmin(np.abs(roots), axis=-1)
        p1 = px[:, 1]
        linear = -px[:, 0] / np.where(p1 != 0.0, p1, 1.0)
        tiny = ((np.abs(roots[np.arange(nb), i0]) <= 16.0 * np.finfo(float).eps * scale) & (p1 != 0.0)
                & (np.abs(px[:, 2] * linear) <= 1e-3 * np.abs(p1)))
        roots[np.arange(nb)[tiny], i0[tiny]] = linear[tiny]
        realish = np.abs(roots.imag) <= self._tol * scale[:, None]
        re = roots.real
        # Near a separatrix a complex pair of P approaches the real axis (imaginary part ~ the distance
        # to the separatrix, e.g. Gamma_n(0) when the motion starts on top of the unstable equilibrium):
        # such a pair is no turning point, the motion passes it slowly (T grows like log). A pair within
        # asymptotic_tol of the axis is a real (or double) root only if P <= 0 at its real part up to
        # rounding: a split real pair has P < 0 between its roots, a complex pair P > 0 there.
        P_re = _polyval_asc(px[:, None, :], re)
        P_noise = 64.0 * np.finfo(float).eps * _polyval_asc(np.abs(px)[:, None, :], np.abs(re))
        realish &= (roots.imag == 0.0) | (P_re <= P_noise)
        Gn0 = G0[:, -1]
        equilibrium = (np.abs(Gn0) <= 1e-15) & (np.abs(p1) <= 1e-14 * (1.0 + np.linalg.norm(u0, axis=-1)))
        # choose xi1 <= 0 <= xi2 (a root at 0 when Gamma_n = 0 is the end the motion leaves from)
        at_zero = (Gn0 == 0.0) & ~equilibrium
        cand_lo = np.where(realish & (re <= 0.0), re, -np.inf)
        cand_hi = np.where(realish & (re >= 0.0), re, np.inf)
        zero_col = np.arange(4)[None, :] == i0[:, None]
        cand_lo = np.where(at_zero[:, None] & zero_col, -np.inf, cand_lo)
        cand_hi = np.where(at_zero[:, None] & zero_col, np.inf, cand_hi)
        j1 = np.argmax(cand_lo, axis=-1)
        j2 = np.argmin(cand_hi, axis=-1)
        xi1 = np.take_along_axis(cand_lo, j1[:, None], -1)[:, 0]
        xi2 = np.take_along_axis(cand_hi, j2[:, None], -1)[:, 0]
        xi1 = np.where(at_zero & (p1 > 0.0), 0.0, xi1)      # leaves 0 upwards: 0 is the lower end
        xi2 = np.where(at_zero & (p1 <= 0.0), 0.0, xi2)
        xi1 = np.where(equilibrium, 0.0, xi1)
        xi2 = np.where(equilibrium, 0.0, xi2)
        if np.any(~np.isfinite(xi1) | ~np.isfinite(xi2)):
            raise RuntimeError("KharlamovaMotion: no real root of P4 on one side of omega_1(0); "
                               "the quartic is inconsistent with the state (please report)")
        # Newton polish of the two ends (simple roots; guarded)
        for _ in range(3):
            for xi in (xi1, xi2):
                f = _polyval_asc(px, xi)
                df = _polyval_asc(px[:, 1:] * np.arange(1, 5), xi)
                ok = (df != 0.0) & (xi != 0.0) & ~equilibrium
                new = xi - np.where(ok, f / np.where(ok, df, 1.0), 0.0)
                better = np.abs(_polyval_asc(px, new)) < np.abs(f)
                xi[...] = np.where(ok & better, new, xi)
        xi1 = np.minimum(xi1, 0.0)
        xi2 = np.maximum(xi2, 0.0)
        # deflate: P = -A (x - xi1)(x - xi2)(x^2 + p x + q)
        s, pr = xi1 + xi2, xi1 * xi2
        p = px[:, 3] / (-A) + s
        q = np.where(pr != 0.0, -px[:, 0] / (A * np.where(pr != 0.0, pr, 1.0)), px[:, 2] / (-A) + s * p - pr)
        disc = p * p - 4.0 * q
        sq = np.sqrt(np.abs(disc))
        r_lo = np.where(disc >= 0.0, -0.5 * (p + sq), -0.5 * p)    # roots of Q (real parts when complex)
        r_hi = np.where(disc >= 0.0, -0.5 * (p - sq), -0.5 * p)
        im = np.where(disc >= 0.0, 0.0, 0.5 * sq)
        width = xi2 - xi1
        gap_hi = np.hypot(np.minimum(np.abs(r_lo - xi2), np.abs(r_hi - xi2)), im)
        gap_lo = np.hypot(np.minimum(np.abs(r_lo - xi1), np.abs(r_hi - xi1)), im)
        tol = self._tol * np.where(width > 0.0, width, 1.0)
        asym_hi = (gap_hi <= tol) & (gap_hi <= gap_lo) & ~equilibrium
        asym_lo = (gap_lo <= tol) & ~asym_hi & ~equilibrium
        kind = np.where(equilibrium, "equilibrium", np.where(asym_hi | asym_lo, "asymptotic", "periodic"))
        # a double root at an end: polish it as the simple root of P' and deflate it exactly
        dpx = px[:, 1:] * np.arange(1.0, 5.0)
        d2px = dpx[:, 1:] * np.arange(1.0, 4.0)
        asym = asym_hi | asym_lo
        r2 = np.where(asym_lo, xi1, xi2)
        for _ in range(4):
            d1 = _polyval_asc(dpx, r2)
            d2 = _polyval_asc(d2px, r2)
            ok = asym & (d2 != 0.0)
            r2 = r2 - np.where(ok, d1 / np.where(ok, d2, 1.0), 0.0)
        xi1 = np.where(asym_lo, np.minimum(r2, 0.0), xi1)
        xi2 = np.where(asym_hi, np.maximum(r2, 0.0), xi2)
        other = np.where(asym_lo, xi2, xi1)                 # the simple end
        prod = other * r2 * r2
        r4_sum = -px[:, 3] / px[:, 4] - other - 2.0 * r2
        r4 = np.where(prod != 0.0, px[:, 0] / (px[:, 4] * np.where(prod != 0.0, prod, 1.0)), r4_sum)
        # reflected frame x' = ref * x, with any double root at the upper end xi2'
        ref = np.where(asym_lo, -1.0, 1.0)
        a1 = np.where(asym_lo, -xi2, xi1)
        a2 = np.where(asym_lo, -xi1, xi2)
        pp = ref * p
        rl = np.where(asym_lo, -r_hi, r_lo)
        rh = np.where(asym_lo, -r_lo, r_hi)
        cplx = (disc < 0.0) & ~asym
        above = ~cplx & (rl >= a2 - tol) & ~asym         # both real roots of Q above xi2' (else below xi1')
        # double root: Q = (x - xi2')(x - r4'), r4' >= xi2'
        r4 = np.maximum(ref * r4, a2)
        self._F = dict(A=A, a1=a1, a2=a2, ref=ref, cplx=cplx, above=above, asym=asym,
                       rl=rl, rh=rh, re=-0.5 * pp, im=im, r4=r4, eq=equilibrium)
        self._xi1, self._xi2 = xi1, xi2
        self._kind = kind
        half = np.where(equilibrium, np.nan, self._t_of_theta(np.full(nb, 0.5 * np.pi), np.arange(nb)))
        half = np.where(asym, np.inf, half)
        self._half = half
        # phase of the initial point (time since xi1' on the ascending branch, signed by Gamma_n')
        w = np.where(a2 > a1, a2 - a1, 1.0)
        th0 = np.arctan2(np.sqrt(np.clip(-a1 / w, 0.0, 1.0)), np.sqrt(np.clip(a2 / w, 0.0, 1.0)))
        t0 = self._t_of_theta(th0, np.arange(nb))
        gn0 = ref * Gn0
        at_lo, at_hi = (a1 == 0.0), (a2 == 0.0)
        # +1 when x' increases right after t = 0 (Gamma_n' > 0, or at the lower turning point), else -1
        self._ascending = np.where(at_lo | ((gn0 > 0.0) & ~at_hi), 1.0, -1.0)
        self._tau0 = np.where(equilibrium, 0.0, self._ascending * t0)
        self._roots_x = roots

    # --------------------------------------------------------------------------------- elliptic core
    def _factors(self, x: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``f3(x), f4(x)`` (complex for a complex pair) in the reflected frame for batch indices ``k``."""
        F = self._F
        a2 = F["a2"][k]
        cplx, above, asym = F["cplx"][k], F["above"][k], F["asym"][k]
        z = F["re"][k] + 1j * F["im"][k]
        f3 = np.where(cplx, x - z, np.where(above, F["rl"][k] - x, x - F["rl"][k]))
        f4 = np.where(cplx, x - np.conj(z), np.where(above, F["rh"][k] - x, x - F["rh"][k]))
        f3 = np.where(asym, a2 - x, f3)
        f4 = np.where(asym, F["r4"][k] - x, f4)
        return f3, f4

    def _t_of_theta(self, th: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Time from ``xi1'`` to ``x' = xi1' + (xi2' - xi1') sin^2 th`` (ascending), ``th`` in [0, pi/2]."""
        F = self._F
        a1, a2, A = F["a1"][k], F["a2"][k], F["A"][k]
        s, c = np.sin(th), np.cos(th)
        x = a1 + (a2 - a1) * s * s
        f3x, f4x = self._factors(x, k)
        f31, f41 = self._factors(a1, k)
        Q1 = (f31 * f41).real
        with np.errstate(divide="ignore", invalid="ignore"):
            val = elliprf((c * c * Q1).astype(complex), f3x * f41, f4x * f31).real
        return 2.0 / np.sqrt(A) * s * val

    def _invert(self, tau: np.ndarray, k: np.ndarray) -> np.ndarray:
        """``th`` in [0, pi/2] with ``t(th) = tau``, ``tau`` in [0, T/2] (vectorised safeguarded Newton)."""
        F = self._F
        a1, a2, A = F["a1"][k], F["a2"][k], F["A"][k]
        half = self._half[k]
        lo = np.zeros_like(tau)
        hi = np.full_like(tau, 0.5 * np.pi)
        th = np.where(np.isfinite(half), 0.5 * np.pi * np.clip(tau / np.where(np.isfinite(half), half, 1.0),
                                                               0.0, 1.0), 0.25 * np.pi)
        for _ in range(200):
            val = self._t_of_theta(th, k) - tau
            lo = np.where(val <= 0.0, th, lo)
            hi = np.where(val >= 0.0, th, hi)
            x = a1 + (a2 - a1) * np.sin(th) ** 2
            f3, f4 = self._factors(x, k)
            Q = np.maximum((f3 * f4).real, 0.0)
            new = th - val * 0.5 * np.sqrt(A * Q)
            bad = ~((new > lo) & (new < hi))
            new = np.where(bad, 0.5 * (lo + hi), new)
            step = np.abs(new - th)
            th = new
            if float(np.max(step, initial=0.0)) <= 4e-16 or float(np.max(hi - lo, initial=0.0)) <= 4e-16:
                break
        return th

    # ------------------------------------------------------------------------------------ properties
    def _out(self, a: np.ndarray) -> np.ndarray:
        return a.reshape(self.batch_shape + a.shape[1:])

    @property
    def omega1_0(self) -> np.ndarray:
        return self._out(self._c[0] * self._u0[:, 0])

    @property
    def quartic(self) -> np.ndarray:
        return self._out(_shift_coefficients(self._px, self._c[0] * self._u0[:, 0])[:, ::-1])

    @property
    def quartic_roots(self) -> np.ndarray:
        return self._out(self._roots_x + (self._c[0] * self._u0[:, 0])[:, None])

    @property
    def bracket(self) -> np.ndarray:
        w0 = self._c[0] * self._u0[:, 0]
        return self._out(np.stack([w0 + self._xi1, w0 + self._xi2], axis=-1))

    @property
    def kind(self) -> np.ndarray:
        return self._out(self._kind)

    @property
    def period(self) -> np.ndarray:
        return self._out(2.0 * self._half)

    # ------------------------------------------------------------------------------------ evaluation
    def time_of(self, omega1: Any) -> np.ndarray:
        r"""The time ``t`` with ``omega_1(t) = omega1`` on the arc of the motion through ``t = 0``.

        ``t = int_{omega_1(0)}^{omega1} dw / (s sqrt(P4(w)))``, the paper's quadrature with its sign ``s``
        that of ``Gamma_n(0)`` (``omega_1' = Gamma_n``): the arc runs between the turning points before and
        after ``t = 0`` (at a turning point, from it), on which ``omega_1`` is monotone.

        Parameters
        ----------
        omega1 : array_like, shape broadcastable to ``batch_shape``
            Values in ``[xi1, xi2]`` (``bracket``).

        Returns
        -------
        ndarray
            Positive when the motion reaches ``omega1`` after ``t = 0``, negative when it passed it before;
            ``|t| <= period / 2``. ``omega1(time_of(w)) == w``.
        """
        w = C.as_array(omega1, "omega1")
        shape = np.broadcast_shapes(w.shape, self.batch_shape)
        w = np.broadcast_to(w, shape)
        k = np.broadcast_to(np.arange(int(np.prod(self.batch_shape, dtype=int))).reshape(self.batch_shape),
                            shape).reshape(-1)
        x = w.reshape(-1) - self._c[0] * self._u0[k, 0]
        lo, hi = self._xi1[k], self._xi2[k]
        span = np.maximum(hi - lo, 1.0)
        if np.any((x < lo - 1e-12 * span) | (x > hi + 1e-12 * span)):
            raise ValueError("omega1 must lie in the oscillation interval [xi1, xi2] (see .bracket)")
        F = self._F
        xr = F["ref"][k] * x
        a1, a2 = F["a1"][k], F["a2"][k]
        wdt = np.where(a2 > a1, a2 - a1, 1.0)
        th = np.arctan2(np.sqrt(np.clip((xr - a1) / wdt, 0.0, 1.0)),
                        np.sqrt(np.clip((a2 - xr) / wdt, 0.0, 1.0)))
        th0 = np.arctan2(np.sqrt(np.clip(-a1 / wdt, 0.0, 1.0)), np.sqrt(np.clip(a2 / wdt, 0.0, 1.0)))
        out = self._ascending[k] * (self._t_of_theta(th, k) - self._t_of_theta(th0, k))
        out = np.where(F["eq"][k], 0.0, out)
        return out.reshape(shape)

    def omega1(self, t: Any) -> np.ndarray:
        """``omega_1(t) = c_1 u_1(t)``, shape ``t.shape + batch_shape``."""
        x, _ = self._x_gn(t)
        w0 = self._c[0] * self._u0[:, 0]
        t = np.asarray(t, dtype=float)
        return (x + w0).reshape(t.shape + self.batch_shape)

    def _x_gn(self, t: Any) -> tuple[np.ndarray, np.ndarray]:
        t = C.times(t)
        nb = self._u0.shape[0]
        tt = np.broadcast_to(t.reshape(-1)[:, None], (t.size, nb))
        k = np.broadcast_to(np.arange(nb)[None, :], tt.shape)
        F = self._F
        tau = self._tau0[k] + tt
        T = 2.0 * self._half[k]
        periodic = np.isfinite(T)
        Ts = np.where(periodic, T, 1.0)
        tau = np.where(periodic, tau - Ts * np.round(tau / Ts), tau)
        sgn = np.where(tau >= 0.0, 1.0, -1.0)
        th = self._invert(np.abs(tau).reshape(-1), k.reshape(-1)).reshape(tau.shape)
        a1, a2, A = F["a1"][k], F["a2"][k], F["A"][k]
        s, c = np.sin(th), np.cos(th)
        xr = a1 + (a2 - a1) * s * s
        f3, f4 = self._factors(xr.reshape(-1), k.reshape(-1))
        Q = np.maximum((f3 * f4).real, 0.0).reshape(xr.shape)
        gn = sgn * np.sqrt(A) * (a2 - a1) * s * c * np.sqrt(Q)
        ref = F["ref"][k]
        eq = F["eq"][k]
        x = np.where(eq, 0.0, ref * xr)
        gn = np.where(eq, self._G0[k, -1], ref * gn)
        return x, gn

    def state(self, t: Any) -> tuple[np.ndarray, np.ndarray]:
        """The state at the times ``t``.

        Parameters
        ----------
        t : array_like, any shape

        Returns
        -------
        u : ndarray, shape ``t.shape + batch_shape + (n-1,)``
        Gamma : ndarray, shape ``t.shape + batch_shape + (n,)``
        """
        t = C.times(t)
        x, gn = self._x_gn(t)
        c, u0, G0 = self._c, self._u0, self._G0
        xe = x[..., None]
        u = u0 + xe / c
        Gp = G0[:, :-1] - u0 * xe - xe * xe / (2.0 * c)
        Gamma = np.concatenate([Gp, gn[..., None]], axis=-1)
        shape = t.shape + self.batch_shape
        return u.reshape(shape + (self.n - 1,)), Gamma.reshape(shape + (self.n,))
