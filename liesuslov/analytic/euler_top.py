r"""The free rigid body (Euler top) in closed form: Jacobi elliptic functions, the period, Montgomery's phase.

Vector form (``docs/concepts.md``): body angular velocity ``w``, principal moments ``J = (J1, J2, J3)`` (distinct,
positive), body momentum ``M = J w`` and Euler's equations ``M' = M x w`` (our ``dM/dt = [M, Omega]``).
Sort the moments ``I1 < I2 < I3`` (an odd permutation of the axes is compensated by ``w -> -w``, which
reverses time in a quadratic field), and let ``2E = sum I_i w_i^2``, ``m^2 = |M|^2``.

Solution (Landau–Lifshitz §37)
------------------------------
If ``m^2 > 2 E I2`` (``M`` circulates around axis 3):

.. math::

    w_1 = s\,a_1\,\mathrm{cn}\,u,\quad w_2 = a_2\,\mathrm{sn}\,u,\quad w_3 = s\,a_3\,\mathrm{dn}\,u,\qquad
    u = \lambda t + u_0,

    a_1^2 = \frac{2EI_3 - m^2}{I_1(I_3 - I_1)},\ a_2^2 = \frac{2EI_3 - m^2}{I_2(I_3 - I_2)},\
    a_3^2 = \frac{m^2 - 2EI_1}{I_3(I_3 - I_1)},\
    \lambda^2 = \frac{(I_3 - I_2)(m^2 - 2EI_1)}{I_1 I_2 I_3},\
    k^2 = \frac{(I_2 - I_1)(2EI_3 - m^2)}{(I_3 - I_2)(m^2 - 2EI_1)},

``s = sign(w_3(0))`` (the symmetry ``(w1, w2, w3) -> (-w1, w2, -w3)``). If ``m^2 < 2 E I2`` exchange the
roles of axes 1 and 3: ``w_1 = s a_1 dn``, ``w_2 = a_2 sn``, ``w_3 = s a_3 cn`` with
``a_1^2 = (2EI_3 - m^2)/(I_1(I_3 - I_1))``, ``a_2^2 = (m^2 - 2EI_1)/(I_2(I_2 - I_1))``,
``a_3^2 = (m^2 - 2EI_1)/(I_3(I_3 - I_1))``, ``lambda^2 = (I_2 - I_1)(2EI_3 - m^2)/(I_1 I_2 I_3)``,
``k^2 = (I_3 - I_2)(m^2 - 2EI_1)/((I_2 - I_1)(2EI_3 - m^2))``, ``s = sign(w_1(0))``. In both cases the
reduced motion has the period

.. math::

    T = \frac{4 K(k)}{\lambda}

(``cn``, ``sn`` have period ``4K``; ``dn`` has ``2K``); ``T = inf`` on the separatrix ``m^2 = 2 E I_2``.

Montgomery's phase (1991)
-------------------------
After one period the attitude has turned about the momentum: ``g(T) = exp(Delta hat(m/|m|)) g(0)`` in
space, i.e. ``R = g(0)^{-1} g(T) = exp(Delta hat(M0/|M0|))`` in the body, with

.. math::

    \Delta \equiv \frac{2ET}{|m|} - \Lambda \pmod{2\pi},\qquad
    \Lambda = \oint \frac{p\cdot(u\times\dot u)}{1 + p\cdot u}\,dt,\quad u = M/|M|,

``Lambda`` the solid angle on the left of the closed curve ``u(t)`` (oriented by the outward normal),
``p`` the axis it circulates around. The sign follows from ``g^{-1} g' = Omega`` (``docs/reconstruction.md``
derives it). Landau's precession rate gives the same angle independently:
``Delta == int_0^T m (I1 w1^2 + I2 w2^2)/(I1^2 w1^2 + I2^2 w2^2) dt`` (circulation about axis 3; axes
1 and 3 exchanged otherwise) modulo ``2 pi``. Both integrands are smooth and periodic, so the
trapezoidal rule on a uniform grid over one period converges exponentially.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.special import ellipj, ellipk, ellipkinc

from . import _checks as C

__all__ = ["EulerTop"]


class EulerTop:
    r"""Closed-form motion of the free rigid body (batched over the initial angular velocity).

    Parameters
    ----------
    J : array_like, shape (3,)
        Principal moments ``(J1, J2, J3)`` acting on ``w`` (distinct, positive).
    w0 : array_like, shape (..., 3)
        Initial body angular velocity (the paper's vector ``w``; ``so(3)`` coordinates are
        ``(-w3, w2, -w1)``), not zero. Exactly along the middle axis it is the steady rotation (constant);
        off that axis by less than rounding resolves, a ``ValueError`` (the closed form has ``k^2 = 1`` and
        cannot say when the body leaves the unstable rotation).

    Attributes
    ----------
    energy : ndarray, shape (...)
        ``E = 1/2 sum J_i w_i^2``.
    momentum : ndarray, shape (...)
        ``|m| = |J w|``.
    parameter : ndarray, shape (...)
        ``k^2`` of the Jacobi functions (0 at a steady rotation about the largest or smallest axis,
        1 on the separatrix).
    rate : ndarray, shape (...)
        ``lambda``: ``u = lambda t + u0``.
    period : ndarray, shape (...)
        ``T = 4 K(k) / lambda`` (``inf`` on the separatrix).
    axis : ndarray, shape (..., 3)
        The unit principal axis (``+-e1`` or ``+-e3``) that ``M/|M|`` circulates around, on its side.

    Examples
    --------
    >>> top = EulerTop([1.0, 2.0, 3.0], [0.3, 0.2, 1.0])
    >>> w = top.state([0.0, top.period])      # shape (2, 3): equal rows
    """

    def __init__(self, J: Any, w0: Any) -> None:
        J = C.as_array(J, "J")
        if J.shape != (3,) or np.any(J <= 0.0):
            raise ValueError(f"J must be the three positive principal moments (J1, J2, J3), got {J.tolist()}")
        order = np.argsort(J, kind="stable")
        Is = J[order]
        if np.any(np.diff(Is) <= 1e-12 * Is[-1]):
            raise ValueError(f"J: the moments must be distinct for the elliptic solution, got {J.tolist()} "
                             "(an axisymmetric top precesses uniformly; use J1 != J2 != J3)")
        w0 = C.as_array(w0, "w0", tail=(3,))
        if np.any(np.linalg.norm(w0, axis=-1) == 0.0):
            raise ValueError("w0 must not be zero (the body at rest has no period)")
        self.J = J
        self.batch_shape = w0.shape[:-1]
        self._order = order
        # An odd permutation of the axes reverses the sign of the cross product: compensate by w -> -w.
        self._sign = float(np.linalg.det(np.eye(3)[order]))
        v = self._sign * w0.reshape(-1, 3)[:, order]
        I1, I2, I3 = Is
        E2 = np.sum(Is * v * v, axis=-1)
        m2 = np.sum((Is * v) ** 2, axis=-1)
        self.energy = (0.5 * E2).reshape(self.batch_shape)
        self.momentum = np.sqrt(m2).reshape(self.batch_shape)
        # Differences computed from the data directly keep their relative accuracy near the axes:
        # 2E I3 - m^2 = sum_i I_i (I3 - I_i) v_i^2, m^2 - 2E I1 = sum_i I_i (I_i - I1) v_i^2.
        p3 = I1 * (I3 - I1) * v[:, 0] ** 2 + I2 * (I3 - I2) * v[:, 1] ** 2
        p1 = I2 * (I2 - I1) * v[:, 1] ** 2 + I3 * (I3 - I1) * v[:, 2] ** 2
        around3 = m2 > E2 * I2
        with np.errstate(divide="ignore", invalid="ignore"):
            # around axis 3
            lam3 = np.sqrt((I3 - I2) * p1 / (I1 * I2 * I3))
            k3 = (I2 - I1) * p3 / ((I3 - I2) * p1)
            # around axis 1
            lam1 = np.sqrt((I2 - I1) * p3 / (I1 * I2 * I3))
            k1 = (I3 - I2) * p1 / ((I2 - I1) * p3)
        self._around3 = around3
        lam = np.where(around3, lam3, lam1)
        k2 = np.clip(np.where(around3, k3, k1), 0.0, 1.0)
        s = np.where(around3, np.sign(v[:, 2]), np.sign(v[:, 0]))
        s = np.where(s == 0.0, 1.0, s)
        a1 = np.sqrt(np.where(around3, p3 / (I1 * (I3 - I1)), p3 / (I1 * (I3 - I1))))
        a2 = np.sqrt(np.where(around3, p3 / (I2 * (I3 - I2)), p1 / (I2 * (I2 - I1))))
        a3 = np.sqrt(np.where(around3, p1 / (I3 * (I3 - I1)), p1 / (I3 * (I3 - I1))))
        # initial phase: sn u0 = w2 / a2 and cn u0 = s w_(cn axis) / a_(cn axis); multiply both by a2 a_cn > 0
        cn_v, cn_a = np.where(around3, v[:, 0], v[:, 2]), np.where(around3, a1, a3)
        phi0 = np.arctan2(v[:, 1] * cn_a, s * cn_v * a2)
        u0 = ellipkinc(phi0, k2)
        # u0 infinite: the state is the separatrix's end, the steady rotation about the middle axis (an unstable
        # equilibrium). Exactly on the axis the motion is that rotation; off it by less than rounding resolves
        # (k^2 = 1 in floating point), the closed form cannot say when it leaves: a ValueError, not NaN.
        on_axis = (v[:, 0] == 0.0) & (v[:, 2] == 0.0)
        unresolved = ~np.isfinite(u0) & ~on_axis
        if np.any(unresolved):
            bad = w0.reshape(-1, 3)[int(np.flatnonzero(unresolved)[0])].tolist()
            raise ValueError(f"w0 = {bad} is, to rounding, the steady rotation about the middle axis (an unstable "
                             "equilibrium): the closed form cannot resolve when the body leaves it; integrate it "
                             "numerically")
        self._steady = on_axis
        self._w0 = w0.reshape(-1, 3)
        u0 = np.where(on_axis, 0.0, u0)
        self._lam, self._k2, self._s, self._u0 = lam, k2, s, u0
        self._a = np.stack([a1, a2, a3], axis=-1)
        self.parameter = k2.reshape(self.batch_shape)
        self.rate = lam.reshape(self.batch_shape)
        with np.errstate(divide="ignore"):
            T = np.where(k2 >= 1.0, np.inf, 4.0 * ellipk(k2) / lam)
        self.period = T.reshape(self.batch_shape)
        ax = np.zeros((v.shape[0], 3))
        ax[:, 2] = np.where(around3, s, 0.0)
        ax[:, 0] = np.where(around3, 0.0, s)
        self.axis = self._unsort(self._sign * ax).reshape(self.batch_shape + (3,))

    # ------------------------------------------------------------------------------------------ helpers
    def _unsort(self, v: np.ndarray) -> np.ndarray:
        out = np.empty_like(v)
        out[..., self._order] = v
        return out

    def state(self, t: Any) -> np.ndarray:
        """The angular velocity ``w(t)``.

        Parameters
        ----------
        t : array_like, any shape

        Returns
        -------
        ndarray, shape ``t.shape + batch_shape + (3,)``
        """
        t = C.times(t)
        tt = t.reshape(-1)[:, None]
        sn, cn, dn, _ = ellipj(self._lam * tt + self._u0, self._k2)
        a1, a2, a3 = self._a[:, 0], self._a[:, 1], self._a[:, 2]
        s, r3 = self._s, self._around3
        v = np.stack([s * a1 * np.where(r3, cn, dn), a2 * sn, s * a3 * np.where(r3, dn, cn)], axis=-1)
        w = self._sign * self._unsort(v)
        w = np.where(self._steady[:, None], self._w0, w)  # the steady rotation about the middle axis: constant
        return w.reshape(t.shape + self.batch_shape + (3,))

    def momentum_vector(self, t: Any) -> np.ndarray:
        """The body momentum ``M(t) = J w(t)``, shape ``t.shape + batch_shape + (3,)``."""
        return self.J * self.state(t)

    def dynamic_phase(self) -> np.ndarray:
        """``2 E T / |m|``, shape (...)."""
        return 2.0 * self.energy * self.period / self.momentum

    def geometric_phase(self, samples: int = 512) -> np.ndarray:
        r"""``Lambda``: the solid angle on the left of the closed curve ``M/|M|`` over one period, in
        ``[0, 4 pi)``, shape (...).

        ``int_0^T p.(u x u')/(1 + p.u) dt`` with ``u' = u x w`` and ``p`` = :attr:`axis`, by the
        trapezoidal rule on ``samples`` points of the period (exponentially convergent), modulo ``4 pi``:
        the integral is the area enclosed about ``p`` with the sign of the sense of travel, which is the
        area on the left modulo ``4 pi``. NaN on the separatrix.
        """
        u, w, dt = self._period_samples(samples)
        p = self.axis
        du = np.cross(u, w)
        integrand = np.sum(p * np.cross(u, du), axis=-1) / (1.0 + np.sum(p * u, axis=-1))
        return np.mod(np.sum(integrand, axis=0) * dt, 4.0 * np.pi)

    def precession(self, samples: int = 512) -> np.ndarray:
        r"""Landau's precession of the body about ``m`` during one period (an independent route to the phase).

        ``int_0^T m (I_a w_a^2 + I_b w_b^2)/(I_a^2 w_a^2 + I_b^2 w_b^2) dt`` with ``a, b`` the two axes other
        than :attr:`axis`; the rotation of the attitude about ``m`` is this angle modulo ``2 pi``.
        """
        _, w, dt = self._period_samples(samples)
        p = np.abs(self.axis)
        J = self.J * (1.0 - p)  # zero out the circulation axis
        num = np.sum(J * w * w, axis=-1)
        den = np.sum((J * w) ** 2, axis=-1)
        return self.momentum * np.sum(num / den, axis=0) * dt

    def _period_samples(self, samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if not isinstance(samples, (int, np.integer)) or samples < 8:
            raise ValueError(f"samples must be an integer >= 8, got {samples!r}")
        T = self.period
        frac = np.arange(samples) / samples
        t = frac.reshape((samples,) + (1,) * len(self.batch_shape)) * np.where(np.isfinite(T), T, np.nan)
        # state() takes a common time array; evaluate per sample fraction through u = lambda t + u0
        lam = self._lam.reshape(self.batch_shape)
        u = lam * t
        sn, cn, dn, _ = ellipj(u.reshape(samples, -1) + self._u0, self._k2)
        a1, a2, a3 = self._a[:, 0], self._a[:, 1], self._a[:, 2]
        s, r3 = self._s, self._around3
        v = np.stack([s * a1 * np.where(r3, cn, dn), a2 * sn, s * a3 * np.where(r3, dn, cn)], axis=-1)
        w = (self._sign * self._unsort(v)).reshape((samples,) + self.batch_shape + (3,))
        M = self.J * w
        uvec = M / np.linalg.norm(M, axis=-1, keepdims=True)
        return uvec, w, T / samples
