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
        ``sum_i F_i / (B_i - B_n) < 1`` (then ``Gamma_n`` never vanishes).
    I : array_like, shape (n,)
    B : array_like, shape (n,), ``B_i > B_n`` for ``i < n``.

    Attributes
    ----------
    integrals : ndarray, shape (..., n-1)
        ``c_i = F_i``.
    phases : ndarray, shape (..., n-1)
        ``phi_i`` at ``t = 0``.
    frequencies : ndarray, shape (n-1,)
        ``omega_i``.
    sign : ndarray, shape (...)
        ``sign(Gamma_n)``, constant on the torus.
    margin : ndarray, shape (...)
        ``delta = 1 - sum_i c_i/(B_i - B_n) > 0``; ``Gamma_n^2 >= delta``.
    energy : ndarray, shape (...)
        ``(B_n + sum_i c_i)/2``.
    """

    def __init__(self, u0: Any, Gamma0: Any, I: Any, B: Any) -> None:
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
        if np.any(bad):
            worst = float(np.max(1.0 - self._delta))
            raise ValueError(f"u0, Gamma0: sum_i F_i/(B_i - B_n) = {worst:.6g} >= 1 for some initial data; "
                             "Gamma_n can vanish on that invariant variety and the closed form (two "
                             "disjoint tori, condition (4.10)) does not apply")
        self._sigma = np.where(Gamma0[:, -1] > 0.0, 1.0, -1.0)
        self._u0, self._G0 = u0, Gamma0

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
        tt, k, shape = self._flat(tau, "tau")
        return (self._sigma[k] * self._abs_time(tt, k)).reshape(shape)

    def tau(self, t: Any) -> np.ndarray:
        """The new time ``tau(t)`` (inverse of :meth:`time_of_tau`), shape ``t.shape + batch_shape``."""
        tt, k, shape = self._flat(t, "t")
        return self._tau(tt, k).reshape(shape)

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
        tt, k, shape = self._flat(tau, "tau")
        u, G = self._state_tau(tt, k)
        return u.reshape(shape + (self.n - 1,)), G.reshape(shape + (self.n,))

    def _state_tau(self, tau: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ph = self._phi0[k] + self._w * tau[..., None]
        rc = np.sqrt(self._c[k])
        u = rc / self._k * np.sin(ph)
        Gp = rc / self._a * np.cos(ph)
        gn = self._sigma[k] * np.sqrt(self._delta[k] + np.sum(self._alpha[k] * np.sin(ph) ** 2, axis=-1))
        return u, np.concatenate([Gp, gn[..., None]], axis=-1)

    def state(self, t: Any) -> tuple[np.ndarray, np.ndarray]:
        """The state at the times ``t``.

        Returns
        -------
        u : ndarray, shape ``t.shape + batch_shape + (n-1,)``
        Gamma : ndarray, shape ``t.shape + batch_shape + (n,)``
        """
        tt, k, shape = self._flat(t, "t")
        u, G = self._state_tau(self._tau(tt, k), k)
        return u.reshape(shape + (self.n - 1,)), G.reshape(shape + (self.n,))
