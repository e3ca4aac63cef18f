r"""The n-dimensional Klebsh–Tisserand case on its invariant tori (``V = 1/2 sum_i B_i Gamma_i^2``).

Equations (4.9), corrected: ``(I_i + I_n) u_i' = (B_i - B_n) Gamma_i Gamma_n`` (the paper prints
``B_1 - B_n``), ``Gamma_i' = -Gamma_n u_i`` (``i < n``), ``Gamma_n' = sum_i Gamma_i u_i``.

Integrals and energy
--------------------
``F_i = (B_i - B_n) Gamma_i^2 + (I_i + I_n) u_i^2`` (``i < n``), and on ``|Gamma| = 1``

.. math::

    E = \tfrac12\sum_{i<n}(I_i+I_n)u_i^2 + \tfrac12\sum_i B_i\Gamma_i^2
      = \tfrac12\Big(B_n + \sum_{i<n}F_i\Big)

(the paper prints ``n B_n``).

Tori and angles
---------------
For ``B_i > B_n`` each ``{F_i = c_i}`` is an ellipse in the plane ``(u_i, Gamma_i)``; with
``u_i = sqrt(c_i/(I_i+I_n)) sin phi_i`` and ``Gamma_i = sqrt(c_i/(B_i-B_n)) cos phi_i``,
``d phi_i / dt = Gamma_n omega_i``, ``omega_i = sqrt((B_i - B_n)/(I_i + I_n))``: the flow is linear,
``phi_i = phi_i^0 + omega_i tau``, in the time ``d tau = Gamma_n dt``. If

.. math::

    \sum_{i<n}\frac{c_i}{B_i - B_n} < 1

(the paper's (4.10) prints ``c_1/(B_i - B_n)`` as first term) then
``Gamma_n^2 = 1 - sum_i c_i cos^2 phi_i/(B_i - B_n) >= 1 - sum_i c_i/(B_i - B_n) > 0``: ``Gamma_n`` keeps
its sign ``sigma`` and the variety ``T_c`` is two disjoint tori. On them

.. math::

    t(\tau) = \int_0^\tau \frac{d\tau'}{\Gamma_n(\tau')} ,\qquad \Gamma_n(\tau) = \sigma\sqrt{\delta + \sum_i
        \frac{c_i}{B_i - B_n}\sin^2(\varphi_i^0 + \omega_i\tau)},\quad \delta = 1 - \sum_i\frac{c_i}{B_i-B_n},

is strictly monotone (``|dt/d tau| in [1, delta^-1/2]``); it is computed by composite Gauss–Legendre
quadrature on panels shorter than the analyticity radius of the integrand and inverted by
Newton's method inside the panel found by bisection of the cumulative sums.

Through Gamma_n = 0 (``delta <= 0``, opt-in: ``allow_crossing=True``)
----------------------------------------------------------------------
When (4.10) fails, ``R(tau) = delta + sum_i alpha_i sin^2(phi_i^0 + omega_i tau)`` (``= Gamma_n^2``,
``alpha_i = c_i/(B_i - B_n)``) has zeros on both sides of ``tau = 0``: the tau-time is singular there,
the motion is not. With ``tau_- < 0 < tau_+`` the nearest zeros, ``tau`` rises from ``tau_-`` to ``tau_+``
while ``Gamma_n = +sqrt(R) > 0``; at ``tau_+`` ``Gamma_n`` changes sign (``Gamma_n' = R'(tau_+)/2 < 0``)
and ``tau`` goes back to ``tau_-`` with ``Gamma_n = -sqrt(R)``. So the motion is periodic in t, for
every n, with period

.. math::

    T = 2\int_{\tau_-}^{\tau_+}\frac{d\tau}{\sqrt{R(\tau)}}
      = 2\int_0^{\pi/2}\frac{2\,\Delta\sin\theta\cos\theta}{\sqrt{R(\tau_- + \Delta\sin^2\theta)}}\,d\theta,
    \qquad \Delta = \tau_+ - \tau_-,

a smooth integrand (``R`` has simple zeros at both ends). Near an end ``tau_e`` ``R`` is evaluated as
``sum_i alpha_i sin(omega_i (tau - tau_e)) sin(phi_i(tau) + phi_i(tau_e))`` (``sin^2 a - sin^2 b =
sin(a - b) sin(a + b)``), so the integrand keeps full relative accuracy up to the ends; the end panels are
graded geometrically (near ``delta = 0`` a zero is almost double and the integrand peaks there, so T grows
like ``log(1/|delta|)``). The zeros are found by sampling R and its local minima. Not covered (ValueError):
a start exactly on a double zero, and no zero within 8000 periods of the fastest angle.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _checks as C

__all__ = ["KlebshTisserandMotion", "klebsh_tisserand_angles", "klebsh_tisserand_energy",
           "klebsh_tisserand_frequencies", "klebsh_tisserand_integrals", "klebsh_tisserand_two_tori"]

_GL_X, _GL_W = np.polynomial.legendre.leggauss(20)


def _params(I: Any, B: Any, *, tori: bool) -> tuple[np.ndarray, np.ndarray]:
    I = C.diagonal_mass(I, "I")
    n = I.shape[0]
    B = C.as_array(B, "B")
    if B.shape != (n,):
        raise ValueError(f"B must have shape (n,) = ({n},) like I, got {B.shape}")
    if tori and np.any(B[:-1] <= B[-1]):
        raise ValueError(f"B: the Klebsh–Tisserand tori need B_i > B_n for all i < n, got {B.tolist()}")
    return I, B


def klebsh_tisserand_integrals(u: Any, Gamma: Any, I: Any, B: Any) -> np.ndarray:
    """``F_i = (B_i - B_n) Gamma_i^2 + (I_i + I_n) Omega_in^2``, ``i < n`` (integrals for any ``B``).

    Shapes: ``u`` (..., n-1), ``Gamma`` (..., n), ``I`` (n,), ``B`` (n,) → (..., n-1).
    """
    I, B = _params(I, B, tori=False)
    n = I.shape[0]
    u = C.as_array(u, "u", tail=(n - 1,))
    Gamma = C.as_array(Gamma, "Gamma", tail=(n,))
    return (B[:-1] - B[-1]) * Gamma[..., :-1] ** 2 + (I[:-1] + I[-1]) * u ** 2


def klebsh_tisserand_energy(F: Any, B: Any) -> np.ndarray:
    """The energy from the integrals: ``E = (B_n + F_1 + ... + F_{n-1}) / 2`` (on ``|Gamma| = 1``).

    Shapes: ``F`` (..., n-1), ``B`` (n,) → (...). The paper's ``(n B_n + sum F_i)/2`` is a misprint.
    """
    B = C.as_array(B, "B", ndim_min=1)
    if B.ndim != 1:
        raise ValueError(f"B must have shape (n,), got {B.shape}")
    F = C.as_array(F, "F", tail=(B.shape[0] - 1,))
    return 0.5 * (B[-1] + np.sum(F, axis=-1))


def klebsh_tisserand_two_tori(c: Any, B: Any) -> np.ndarray:
    """Condition (4.10), corrected: ``sum_{i<n} c_i / (B_i - B_n) < 1`` (``T_c`` is two disjoint tori).

    Shapes: ``c`` (..., n-1) nonnegative values of the ``F_i``, ``B`` (n,) with ``B_i > B_n`` → bool (...).
    """
    B = C.as_array(B, "B", ndim_min=1)
    if B.ndim != 1 or B.shape[0] < 2:
        raise ValueError(f"B must have shape (n,), got {B.shape}")
    if np.any(B[:-1] <= B[-1]):
        raise ValueError(f"B: the Klebsh–Tisserand tori need B_i > B_n for all i < n, got {B.tolist()}")
    c = C.as_array(c, "c", tail=(B.shape[0] - 1,))
    if np.any(c < 0.0):
        raise ValueError("c: the values of F_i are nonnegative when B_i > B_n")
    return np.sum(c / (B[:-1] - B[-1]), axis=-1) < 1.0


def klebsh_tisserand_frequencies(I: Any, B: Any) -> np.ndarray:
    """``omega_i = sqrt((B_i - B_n)/(I_i + I_n))``, (n-1,): ``d phi_i/d tau`` (``d tau = Gamma_n dt``)."""
    I, B = _params(I, B, tori=True)
    return np.sqrt((B[:-1] - B[-1]) / (I[:-1] + I[-1]))


def klebsh_tisserand_angles(u: Any, Gamma: Any, I: Any, B: Any) -> tuple[np.ndarray, np.ndarray]:
    """Torus coordinates: ``c_i = F_i`` and ``phi_i`` with ``u_i = sqrt(c_i/(I_i+I_n)) sin phi_i``,
    ``Gamma_i = sqrt(c_i/(B_i-B_n)) cos phi_i``.

    Shapes: ``u`` (..., n-1), ``Gamma`` (..., n) → ``c`` (..., n-1), ``phi`` (..., n-1) in (-pi, pi].
    """
    I, B = _params(I, B, tori=True)
    n = I.shape[0]
    u = C.as_array(u, "u", tail=(n - 1,))
    Gamma = C.as_array(Gamma, "Gamma", tail=(n,))
    a = np.sqrt(B[:-1] - B[-1])
    k = np.sqrt(I[:-1] + I[-1])
    X, Y = a * Gamma[..., :-1], k * u
    return X * X + Y * Y, np.arctan2(Y, X)


class KlebshTisserandMotion:
    r"""Closed-form motion on a Klebsh–Tisserand torus, in ``tau`` and in ``t`` (batched over initial data).

    Parameters
    ----------
    u0 : array_like, shape (..., n-1)
        ``(Omega_1n, ..., Omega_{n-1,n})`` at ``t = 0``.
    Gamma0 : array_like, shape (..., n)
        Unit vector at ``t = 0``; the data must satisfy the two-tori condition
        ``sum_i F_i / (B_i - B_n) < 1`` (then ``Gamma_n`` never vanishes), unless ``allow_crossing``.
    I : array_like, shape (n,)
    B : array_like, shape (n,), ``B_i > B_n`` for ``i < n``.
    allow_crossing : bool
        Accept data violating (4.10): ``Gamma_n`` then passes through 0, ``tau`` oscillates between the
        zeros ``tau_-, tau_+`` of ``Gamma_n^2`` and the motion is periodic in t (module docstring).
        :meth:`state` and :meth:`tau` cover it; :meth:`time_of_tau` and :meth:`state_at_tau` (where
        ``Gamma_n``'s sign is not a function of tau) raise for such data.

    Attributes
    ----------
    integrals : ndarray, shape (..., n-1)
        ``c_i = F_i``.
    phases : ndarray, shape (..., n-1)
        ``phi_i`` at ``t = 0``.
    frequencies : ndarray, shape (n-1,)
        ``omega_i``.
    sign : ndarray, shape (...)
        ``sign(Gamma_n)`` at t = 0, constant on the torus (not for a crossing motion).
    margin : ndarray, shape (...)
        ``delta = 1 - sum_i c_i/(B_i - B_n)``; ``Gamma_n^2 >= delta`` (``delta <= 0``: ``crossing``).
    energy : ndarray, shape (...)
        ``(B_n + sum_i c_i)/2``.
    crossing : ndarray of bool, shape (...)
        Whether ``Gamma_n`` passes through 0 (only with ``allow_crossing``).
    period : ndarray, shape (...)
        The period in t of a crossing motion; ``nan`` on the tori (quasi-periodic motion).
    tau_range : ndarray, shape (..., 2)
        ``(tau_-, tau_+)`` of a crossing motion; ``(-inf, inf)`` on the tori.
    """

    def __init__(self, u0: Any, Gamma0: Any, I: Any, B: Any, *, allow_crossing: bool = False) -> None:
        I, B = _params(I, B, tori=True)
        n = I.shape[0]
        u0 = C.as_array(u0, "u0", tail=(n - 1,))
        Gamma0 = C.as_array(Gamma0, "Gamma0", tail=(n,))
        C.check_unit(Gamma0, "Gamma0")
        self.I, self.B, self.n = I, B, n
        self.batch_shape = C.broadcast_batch((u0, 1), (Gamma0, 1))
        u0 = np.broadcast_to(u0, self.batch_shape + (n - 1,)).reshape(-1, n - 1)
        Gamma0 = np.broadcast_to(Gamma0, self.batch_shape + (n,)).reshape(-1, n)
        Gamma0 = Gamma0 / np.linalg.norm(Gamma0, axis=-1, keepdims=True)
        self._a = np.sqrt(B[:-1] - B[-1])
        self._k = np.sqrt(I[:-1] + I[-1])
        self._w = self._a / self._k
        X, Y = self._a * Gamma0[:, :-1], self._k * u0
        self._c = X * X + Y * Y
        self._phi0 = np.arctan2(Y, X)
        self._alpha = self._c / (B[:-1] - B[-1])
        self._delta = 1.0 - np.sum(self._alpha, axis=-1)
        bad = self._delta <= 0.0
        if np.any(bad) and not allow_crossing:
            worst = float(np.max(1.0 - self._delta))
            raise ValueError(f"u0, Gamma0: sum_i F_i/(B_i - B_n) = {worst:.6g} >= 1 for some initial data; "
                             "Gamma_n can vanish on that invariant variety and the closed form (two "
                             "disjoint tori, condition (4.10)) does not apply (allow_crossing=True computes "
                             "the motion through Gamma_n = 0)")
        self._sigma = np.where(Gamma0[:, -1] > 0.0, 1.0, -1.0)
        self._u0, self._G0 = u0, Gamma0
        self._cross = bad
        nb = u0.shape[0]
        self._period = np.full(nb, np.nan)
        self._trange = np.tile([-np.inf, np.inf], (nb, 1))
        self._X = {}
        for b in np.flatnonzero(bad):
            self._setup_crossing(int(b))

    # ------------------------------------------------------------------------------------ properties
    def _out(self, a: np.ndarray) -> np.ndarray:
        return a.reshape(self.batch_shape + a.shape[1:])

    @property
    def integrals(self) -> np.ndarray:
        return self._out(self._c)

    @property
    def phases(self) -> np.ndarray:
        return self._out(self._phi0)

    @property
    def frequencies(self) -> np.ndarray:
        return self._w.copy()

    @property
    def sign(self) -> np.ndarray:
        return self._out(self._sigma)

    @property
    def margin(self) -> np.ndarray:
        return self._out(self._delta)

    @property
    def energy(self) -> np.ndarray:
        return self._out(0.5 * (self.B[-1] + np.sum(self._c, axis=-1)))

    @property
    def crossing(self) -> np.ndarray:
        return self._out(self._cross.copy())

    @property
    def period(self) -> np.ndarray:
        return self._out(self._period.copy())

    @property
    def tau_range(self) -> np.ndarray:
        return self._out(self._trange.copy())

    # ------------------------------------------------------------------------------ through Gamma_n = 0
    def _R(self, tau, b: int) -> np.ndarray:
        """``Gamma_n^2 = R(tau)`` for trajectory b."""
        ph = self._phi0[b] + self._w * np.asarray(tau, dtype=float)[..., None]
        return self._delta[b] + np.sum(self._alpha[b] * np.sin(ph) ** 2, axis=-1)

    def _R_near(self, d: np.ndarray, b: int, end: float) -> np.ndarray:
        """``R(end + d)`` for a zero ``end`` of R, from the offset d itself (full relative accuracy as d -> 0):
        ``sin^2 a - sin^2 c = sin(a - c) sin(a + c)`` with ``a - c = omega_i d``."""
        wd = self._w * np.asarray(d, dtype=float)[..., None]
        pe = self._phi0[b] + self._w * end
        return np.sum(self._alpha[b] * np.sin(wd) * np.sin(2.0 * pe + wd), axis=-1)

    def _tau_R(self, th: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
        """``tau = tau_- + Delta sin^2 theta`` and ``R(tau)``, R from the offset to the nearer zero."""
        lo, hi = self._trange[b]
        D = hi - lo
        s2, c2 = np.sin(th) ** 2, np.cos(th) ** 2
        near_lo = s2 <= 0.5
        d_lo, d_hi = D * s2, -D * c2
        tau = np.where(near_lo, lo + d_lo, hi + d_hi)
        R = np.where(near_lo, self._R_near(d_lo, b, lo), self._R_near(d_hi, b, hi))
        return tau, R

    def _dR(self, tau, b: int) -> np.ndarray:
        """``R'(tau) = sum_i alpha_i omega_i sin(2 phi_i(tau))``."""
        ph = self._phi0[b] + self._w * np.asarray(tau, dtype=float)[..., None]
        return np.sum(self._alpha[b] * self._w * np.sin(2.0 * ph), axis=-1)

    def _zero(self, b: int, direction: float) -> float:
        """The first zero of R from tau = 0 in ``direction``.

        R is sampled at 1/20 of the fastest period of its angles; a dip below zero between two positive
        samples is caught at the local minimum (a sign change of R' from - to + along ``direction``), so a
        pair of close zeros (data near ``delta = 0``) is not missed.
        """
        from scipy.optimize import brentq

        H = 0.05 / float(np.max(self._w))
        xtol, rtol = 1e-15, 4 * np.finfo(float).eps

        def root(a: float, c: float) -> float:
            return float(brentq(lambda x: float(self._R(x, b)), a, c, xtol=xtol, rtol=rtol, maxiter=200))

        lo = 0.0
        for _ in range(200):  # blocks of 256 samples: up to ~8000 periods of the fastest angle
            grid = lo + direction * H * np.arange(0, 257)
            R = self._R(grid, b)
            slope = direction * self._dR(grid, b)  # dR along the search direction
            for j in range(1, grid.size):
                if R[j] <= 0.0:
                    if R[j] == 0.0:
                        return float(grid[j])
                    if R[j - 1] <= 0.0:  # only at j = 1, starting on Gamma_n = 0 toward R < 0
                        raise ValueError("u0, Gamma0: Gamma_n = 0 at t = 0 and it would not change sign "
                                         "(a double zero of Gamma_n^2); the closed form does not cover it")
                    return root(float(grid[j - 1]), float(grid[j]))
                if slope[j - 1] < 0.0 <= slope[j]:  # a local minimum inside: is R negative there?
                    m = float(brentq(lambda x: float(self._dR(x, b)), float(grid[j - 1]), float(grid[j]),
                                     xtol=xtol, rtol=rtol, maxiter=200)) if slope[j] > 0.0 else float(grid[j])
                    if float(self._R(m, b)) <= 0.0:
                        return root(float(grid[j - 1]), m)
            lo = float(grid[-1])
        raise ValueError("u0, Gamma0: Gamma_n^2 = R(tau) shows no zero within 8000 periods although "
                         "sum_i F_i/(B_i - B_n) >= 1 (a near-miss of the quasi-periodic R); not covered")

    def _dt_dtheta(self, th: np.ndarray, b: int) -> np.ndarray:
        """``dt/d theta = 2 Delta sin cos / sqrt(R)`` at ``tau = tau_- + Delta sin^2 theta`` (smooth)."""
        lo, hi = self._trange[b]
        th = np.maximum(th, 1e-100)  # theta = 0 exactly would be 0/0 (the limit 2 sqrt(Delta/R'(tau_-)))
        _, R = self._tau_R(th, b)
        return 2.0 * (hi - lo) * np.sin(th) * np.cos(th) / np.sqrt(np.maximum(R, np.finfo(float).tiny))

    def _int_theta(self, a: np.ndarray, c: np.ndarray, b: int) -> np.ndarray:
        mid, half = 0.5 * (a + c), 0.5 * (c - a)
        nodes = mid[..., None] + half[..., None] * _GL_X
        return half * np.sum(self._dt_dtheta(nodes, b) * _GL_W, axis=-1)

    def _setup_crossing(self, b: int) -> None:
        Gn0 = self._G0[b, -1]
        if Gn0 != 0.0:
            lo, hi = self._zero(b, -1.0), self._zero(b, 1.0)
        else:  # starting on Gamma_n = 0: R'(0) = 2 Gamma_n'(0) says which side the motion is on
            dR = float(np.sum(self._alpha[b] * self._w * np.sin(2.0 * self._phi0[b])))
            if dR == 0.0:
                raise ValueError("u0, Gamma0: Gamma_n = 0 and Gamma_n' = 0: an equilibrium of the tau-motion; "
                                 "the closed form does not cover it")
            lo, hi = (0.0, self._zero(b, 1.0)) if dR > 0.0 else (self._zero(b, -1.0), 0.0)
        self._trange[b] = lo, hi
        npan = int(np.ceil((hi - lo) * np.max(self._w) / 0.25)) + 1
        edges = np.linspace(0.0, 0.5 * np.pi, npan + 1)
        # grade the end panels geometrically (30 halvings): where R' is small at a zero (data near
        # delta = 0) dt/d theta has a peak of width ~sqrt(R'/(R'' Delta)) at that end
        h0 = edges[1]
        grade = h0 * 0.5 ** np.arange(1, 31)
        edges = np.unique(np.concatenate([edges, grade, 0.5 * np.pi - grade]))
        pieces = self._int_theta(edges[:-1], edges[1:], b)
        cum = np.concatenate([[0.0], np.cumsum(pieces)])
        half = float(cum[-1])
        self._period[b] = 2.0 * half
        th0 = np.arcsin(np.sqrt(np.clip(-lo / (hi - lo), 0.0, 1.0)))
        t0 = self._t_theta(np.array([th0]), b, edges, cum)[0]
        if Gn0 > 0.0 or (Gn0 == 0.0 and lo == 0.0):
            p0 = t0
        else:
            p0 = 2.0 * half - t0
        self._X[b] = (edges, cum, p0)

    def _t_theta(self, th: np.ndarray, b: int, edges: np.ndarray, cum: np.ndarray) -> np.ndarray:
        """Time from ``tau_-`` (ascending) to ``theta``."""
        j = np.clip(np.searchsorted(edges, th, side="right") - 1, 0, edges.size - 2)
        return cum[j] + self._int_theta(edges[j], th, b)

    def _state_crossing(self, t: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
        """``(tau, Gamma_n)`` at the times t (1-D) of crossing trajectory b."""
        edges, cum, p0 = self._X[b]
        T = self._period[b]
        half = 0.5 * T
        p = np.mod(p0 + t, T)
        up = p <= half
        target = np.where(up, p, T - p)
        j = np.clip(np.searchsorted(cum, target, side="right") - 1, 0, edges.size - 2)
        a, c = edges[j], edges[j + 1]
        frac = (target - cum[j]) / np.where(cum[j + 1] > cum[j], cum[j + 1] - cum[j], 1.0)
        th = a + np.clip(frac, 0.0, 1.0) * (c - a)
        lo_b, hi_b = a.copy(), c.copy()
        for _ in range(60):
            f = cum[j] + self._int_theta(a, th, b) - target
            lo_b = np.where(f <= 0.0, th, lo_b)
            hi_b = np.where(f >= 0.0, th, hi_b)
            new = th - f / self._dt_dtheta(th, b)
            bad = ~((new >= lo_b) & (new <= hi_b))
            new = np.where(bad, 0.5 * (lo_b + hi_b), new)
            step = float(np.max(np.abs(new - th), initial=0.0))
            th = new
            if step <= 1e-15:
                break
        tau, R = self._tau_R(th, b)
        gn = np.where(up, 1.0, -1.0) * np.sqrt(np.maximum(R, 0.0))
        return tau, gn

    # ------------------------------------------------------------------------------------ internals
    def _g(self, tau: np.ndarray, k: np.ndarray) -> np.ndarray:
        """``1/|Gamma_n(tau)|`` for batch indices ``k`` (broadcast with ``tau``)."""
        ph = self._phi0[k] + self._w * tau[..., None]
        return 1.0 / np.sqrt(self._delta[k] + np.sum(self._alpha[k] * np.sin(ph) ** 2, axis=-1))

    def _int_g(self, a: np.ndarray, b: np.ndarray, k: np.ndarray) -> np.ndarray:
        """``int_a^b 1/|Gamma_n|`` by one Gauss–Legendre panel (``b - a`` at most one panel width)."""
        mid, half = 0.5 * (a + b), 0.5 * (b - a)
        nodes = mid[..., None] + half[..., None] * _GL_X
        vals = self._g(nodes, k[..., None])
        return half * np.sum(vals * _GL_W, axis=-1)

    def _panel(self, k: np.ndarray) -> np.ndarray:
        return 0.5 * np.minimum(1.0, np.sqrt(self._delta[k])) / np.max(self._w)

    def _abs_time(self, tau: np.ndarray, k: np.ndarray) -> np.ndarray:
        """``int_0^tau 1/|Gamma_n|`` (signed like ``tau``) by panels of width <= ``_panel``."""
        H = self._panel(k)
        npan = np.ceil(np.abs(tau) / H).astype(int)
        mmax = int(np.max(npan, initial=0))
        total = np.zeros_like(tau)
        step = np.where(npan > 0, tau / np.maximum(npan, 1), 0.0)
        for j in range(mmax):
            active = j < npan
            a = j * step
            total = total + np.where(active, self._int_g(a, a + step, k), 0.0)
        return total

    # ------------------------------------------------------------------------------------ evaluation
    def _flat(self, x: Any, name: str) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
        x = C.as_array(x, name)
        nb = self._u0.shape[0]
        xx = np.broadcast_to(x.reshape(-1)[:, None], (x.size, nb))
        k = np.broadcast_to(np.arange(nb)[None, :], xx.shape)
        return xx, k, x.shape + self.batch_shape

    def time_of_tau(self, tau: Any) -> np.ndarray:
        """``t(tau) = int_0^tau d tau' / Gamma_n(tau')``; ``tau`` any shape → ``tau.shape + batch_shape``."""
        self._refuse_crossing("time_of_tau")
        tt, k, shape = self._flat(tau, "tau")
        return (self._sigma[k] * self._abs_time(tt, k)).reshape(shape)

    def _refuse_crossing(self, what: str) -> None:
        if np.any(self._cross):
            raise ValueError(f"{what}: Gamma_n passes through 0 for some initial data (crossing); tau is not "
                             "monotone in t there and Gamma_n's sign is not a function of tau — use state(t)")

    def tau(self, t: Any) -> np.ndarray:
        """The new time ``tau(t)`` (inverse of :meth:`time_of_tau`), shape ``t.shape + batch_shape``."""
        tt, k, shape = self._flat(t, "t")
        return self._tau_gn(tt, k)[0].reshape(shape)

    def _tau_gn(self, t: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """tau(t) for every trajectory, and Gamma_n where a crossing motion fixes it (else None)."""
        if not np.any(self._cross):
            return self._tau(t, k), None
        tau = np.empty_like(t)
        gn = np.full_like(t, np.nan)
        tori = ~self._cross[k]
        if np.any(tori):
            tau[tori] = self._tau(t[tori], k[tori])
        for b in np.flatnonzero(self._cross):
            sel = k == b
            if np.any(sel):
                tau[sel], gn[sel] = self._state_crossing(t[sel], int(b))
        return tau, gn

    def _tau(self, t: np.ndarray, k: np.ndarray) -> np.ndarray:
        target = self._sigma[k] * t            # int_0^tau 1/|Gamma_n| = sigma t
        H = self._panel(k)
        # cumulative panel sums on the grid tau_j = j H sign(target), until they pass |target|
        sgn = np.where(target >= 0.0, 1.0, -1.0)
        goal = np.abs(target)
        lo = np.zeros_like(goal)         # |tau| at the start of the current panel
        acc = np.zeros_like(goal)        # integral up to lo
        for _ in range(int(np.max(np.ceil(goal / H), initial=0)) + 1):
            active = acc < goal
            if not np.any(active):
                break
            inc = np.abs(self._int_g(sgn * lo, sgn * (lo + H), k))
            move = active & (acc + inc < goal)
            acc = np.where(move, acc + inc, acc)
            lo = np.where(move, lo + H, lo)
            if not np.any(move):
                break
        # Newton inside [lo, lo + H]: acc + |int_lo^x g| = goal
        g0 = self._g(sgn * lo, k)
        x = lo + np.clip((goal - acc) / g0, 0.0, H)
        for _ in range(30):
            f = acc + np.abs(self._int_g(sgn * lo, sgn * x, k)) - goal
            dx = f / self._g(sgn * x, k)
            x = np.clip(x - dx, lo, lo + H)
            if float(np.max(np.abs(dx), initial=0.0)) <= 1e-15 * max(1.0, float(np.max(x, initial=0.0))):
                break
        return sgn * x

    def state_at_tau(self, tau: Any) -> tuple[np.ndarray, np.ndarray]:
        """The state at the new times ``tau``: ``phi_i = phi_i^0 + omega_i tau``.

        Returns ``u`` of shape ``tau.shape + batch_shape + (n-1,)`` and ``Gamma`` ``(..., n)``.
        """
        self._refuse_crossing("state_at_tau")
        tt, k, shape = self._flat(tau, "tau")
        u, G = self._state_tau(tt, k)
        return u.reshape(shape + (self.n - 1,)), G.reshape(shape + (self.n,))

    def _state_tau(self, tau: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ph = self._phi0[k] + self._w * tau[..., None]
        rc = np.sqrt(self._c[k])
        u = rc / self._k * np.sin(ph)
        Gp = rc / self._a * np.cos(ph)
        R = self._delta[k] + np.sum(self._alpha[k] * np.sin(ph) ** 2, axis=-1)
        gn = self._sigma[k] * np.sqrt(np.maximum(R, 0.0))  # (crossing motions: R ~ -eps at tau_+-)
        return u, np.concatenate([Gp, gn[..., None]], axis=-1)

    def state(self, t: Any) -> tuple[np.ndarray, np.ndarray]:
        """The state at the times ``t``.

        Returns
        -------
        u : ndarray, shape ``t.shape + batch_shape + (n-1,)``
        Gamma : ndarray, shape ``t.shape + batch_shape + (n,)``
        """
        tt, k, shape = self._flat(t, "t")
        tau, gn = self._tau_gn(tt, k)
        u, G = self._state_tau(tau, k)
        if gn is not None:
            cross = self._cross[k]
            G[..., -1] = np.where(cross, gn, G[..., -1])
        return u.reshape(shape + (self.n - 1,)), G.reshape(shape + (self.n,))
