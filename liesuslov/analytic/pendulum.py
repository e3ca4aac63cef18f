r"""The spherical pendulum on :math:`S^{n-1}`: the reduced n-dimensional Lagrange case, in closed form.

The Fedorov–Kozlov Lagrange case (``I = diag(I_1, ..., I_1, I_n)``, ``V = B_n Gamma_n``) reduces by
``SO(n-1)`` to a point ``q = g e_n`` on the sphere with

.. math::

    L = \tfrac12 m |\dot q|^2 - B \langle\gamma, q\rangle,\qquad
    m\ddot q = -B(\gamma - \langle\gamma, q\rangle q) - m|\dot q|^2 q,

``m = I_1 + I_n``, ``B = B_n``, ``gamma`` the fixed unit vertical (``Gamma_n = <gamma, q>``).

Solution
--------
Since ``q''`` lies in ``span{gamma, q}``, the motion stays in the 3-space ``span{gamma, q0, v0}``. In
an orthonormal frame ``(g, f2, f3)`` of it with ``g = sign(B) gamma`` (so that the potential is
``beta z`` with ``beta = |B|/m >= 0`` and ``z = <g, q>``), the height, the energy per unit mass
``e = |v|^2/2 + beta z`` and the angular momentum ``l = x y' - y x'`` about ``g`` give

.. math::

    \dot z^2 = f(z) = 2(e - \beta z)(1 - z^2) - l^2 = 2\beta (z - z_1)(z - z_2)(z - z_3),

with ``-1 <= z1 <= z0 <= z2 <= 1 <= z3``. Then, with ``m = (z2 - z1)/(z3 - z1)``,
``m1 = (z3 - z2)/(z3 - z1)`` and ``lambda = sqrt(beta (z3 - z1)/2)``,

.. math::

    z(t) = z_1 + (z_2 - z_1)\,\mathrm{sn}^2(u, m),\qquad u = s\lambda t + u_0,

``s = sign(z'(0))``; the height period is ``2K(m)/lambda``. The azimuth obeys ``phi' = l/(1 - z^2)``:

.. math::

    \varphi(t) - \varphi_0 = \frac{s\,l}{2\lambda}\Big[\frac{\Pi(n_+; \mathrm{am}\,u)}{1 - z_1}
        + \frac{\Pi(-n_-; \mathrm{am}\,u)}{1 + z_1}\Big]_{u_0}^{u},\qquad
    n_+ = \frac{z_2 - z_1}{1 - z_1},\; n_- = \frac{z_2 - z_1}{1 + z_1},

and advances by ``(l/lambda) [Pi(n+)/(1 - z1) + Pi(-n-)/(1 + z1)]`` per height period.

Accuracy
--------
Every small difference (``z2 - z1``, ``z3 - z2``, ``1 + z1``, ``1 - z2``) is a root of the cubic
re-expanded about ``z0``, about ``z = 1`` or about ``z = -1`` respectively, whose coefficients are
exact in the data (the constant terms are ``z'(0)^2`` and ``-l^2``); the elliptic functions take
``m1`` itself (:mod:`._elliptic`). Near the separatrix (``m1 -> 0``, motion started close to the
upright position) the period and the state keep full relative accuracy in the data.

Degenerate cases: ``l = 0`` (planar motion through the poles, including ``v0 = 0`` and
``q0 = +-gamma``) uses the planar pendulum angle ``theta`` (libration
``sin(theta/2) = k sn``, rotation ``theta/2 = am``, separatrix ``m1 = 0``); ``B = 0`` is motion on a
great circle.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _checks as C
from ._elliptic import amplitude_pi, complete_k, complete_pi_any, incomplete_f, jacobi, real_cubic_roots

__all__ = ["SphericalPendulumMotion"]

#: |q0 - (+-gamma)| below this is treated as exactly at the pole (the azimuth is then undefined).
POLE_TOL = 1e-12


def _unit_perp(g: np.ndarray) -> np.ndarray:
    """A unit vector orthogonal to the unit vector ``g`` (n,)."""
    k = int(np.argmin(np.abs(g)))
    e = np.zeros_like(g)
    e[k] = 1.0
    e = e - g[k] * g
    return e / np.linalg.norm(e)


class SphericalPendulumMotion:
    r"""Closed-form motion of the spherical pendulum on :math:`S^{n-1}` (batched over initial data).

    Parameters
    ----------
    q0 : array_like, shape (..., n)
        Initial position, a unit vector (``| |q0| - 1 | <= 1e-10``; it is then normalised).
    v0 : array_like, shape (..., n)
        Initial velocity, tangent: ``<q0, v0> = 0`` to ``1e-10 (1 + |v0|)`` (the radial rounding is removed).
    gamma : array_like, shape (n,)
        The fixed unit vertical; the potential is ``B <gamma, q>``.
    mass : float
        ``m = I_1 + I_n > 0``; the kinetic energy is ``m |v|^2 / 2``.
    B : float
        Potential coefficient (any sign; ``B = 0`` gives great circles).
    planar_tol : float
        Motions whose horizontal position and velocity (the parts of ``q0``, ``v0`` orthogonal to
        ``gamma``) are parallel to within this sine are computed as planar (an error of that relative
        size); so are those starting within ``1e-12`` of a pole.

    Attributes
    ----------
    n : int
    batch_shape : tuple
    energy : ndarray, shape (...)
        ``m |v0|^2 / 2 + B <gamma, q0>``.
    angular_momentum : ndarray, shape (...)
        ``m |P q0 ∧ P v0| >= 0``, ``P = Id - gamma gamma^T`` (the momentum of the rotation about gamma).
    cubic : ndarray, shape (..., 4)
        Coefficients, highest degree first, of ``C(z)`` with ``(dz/dt)^2 = C(z)``, ``z = <gamma, q>``:
        ``[2B/m, -2e, -2B/m, 2e - l^2]``, ``e = energy / m``, ``l = angular_momentum / m``.
    roots : ndarray, shape (..., 3)
        The roots of ``cubic``, ascending (for ``B = 0`` the cubic is a quadratic and the root at
        infinity is reported as ``+-inf``).
    height_range : ndarray, shape (..., 2)
        ``(min z, max z)`` over the motion: the two roots bracketing ``<gamma, q0>``.
    parameter, complementary_parameter : ndarray, shape (...)
        ``m`` and ``m1 = 1 - m`` of the Jacobi functions (``m1`` computed directly).
    height_period : ndarray, shape (...)
        Period of ``z(t)`` (``inf`` on a separatrix, ``2 pi / |v0|`` for ``B = 0``; the limit of the
        small oscillations ``pi / sqrt(|B|/m)`` at the stable equilibrium).
    precession : ndarray, shape (...)
        Azimuth swept about ``gamma`` (in the sense of the motion, ``>= 0``) during one height period.
        Planar motions: ``pi`` (libration) or ``2 pi`` (rotation, and great circles), the limits
        ``l -> 0``.
    planar : ndarray of bool, shape (...)
        Whether the motion was computed as planar.

    Examples
    --------
    >>> p = SphericalPendulumMotion([0.0, 0.6, 0.8], [0.3, 0.0, 0.0], gamma=[0.0, 0.0, 1.0], mass=1.0, B=9.81)
    >>> q, v = p.state([0.0, 1.0, 2.0])   # shapes (3, 3), (3, 3)
    """

    def __init__(self, q0: Any, v0: Any, gamma: Any, mass: float, B: float, *,
                 planar_tol: float = 1e-12) -> None:
        gamma = C.as_array(gamma, "gamma", ndim_min=1)
        if gamma.ndim != 1 or gamma.shape[0] < 2:
            raise ValueError(f"gamma must be a vector of shape (n,) with n >= 2, got {gamma.shape}")
        n = gamma.shape[0]
        C.check_unit(gamma, "gamma")
        q0 = C.as_array(q0, "q0", tail=(n,))
        v0 = C.as_array(v0, "v0", tail=(n,))
        C.check_unit(q0, "q0")
        radial = np.abs(np.sum(q0 * v0, axis=-1))
        if radial.size and np.any(radial > 1e-10 * (1.0 + np.linalg.norm(v0, axis=-1))):
            raise ValueError("v0 must be tangent to the sphere at q0 (<q0, v0> = 0); the largest "
                             f"|<q0, v0>| is {float(np.max(radial)):.3g}: remove the radial component")
        self.mass = C.as_positive(mass, "mass")
        self.B = C.as_scalar(B, "B")
        self.n = n
        self.batch_shape = C.broadcast_batch((q0, 1), (v0, 1))
        self.gamma = gamma / np.linalg.norm(gamma)
        q0 = np.broadcast_to(q0, self.batch_shape + (n,)).reshape(-1, n)
        v0 = np.broadcast_to(v0, self.batch_shape + (n,)).reshape(-1, n)
        q0 = q0 / np.linalg.norm(q0, axis=-1, keepdims=True)
        v0 = v0 - np.sum(q0 * v0, axis=-1, keepdims=True) * q0
        self.q0 = q0.reshape(self.batch_shape + (n,))
        self.v0 = v0.reshape(self.batch_shape + (n,))
        self._setup(q0, v0, float(planar_tol))

    # ------------------------------------------------------------------------------------------ setup
    def _setup(self, q0: np.ndarray, v0: np.ndarray, planar_tol: float) -> None:
        nb = q0.shape[0]
        self._sigma = 1.0 if self.B >= 0.0 else -1.0
        g = self._sigma * self.gamma
        self._g = g
        beta = abs(self.B) / self.mass
        self._beta = beta
        z0 = q0 @ g
        zd0 = v0 @ g
        hq = q0 - z0[:, None] * g
        hv = v0 - zd0[:, None] * g
        rho0 = np.linalg.norm(hq, axis=-1)
        at_pole = rho0 <= POLE_TOL
        speed = np.linalg.norm(v0, axis=-1)
        nhv = np.linalg.norm(hv, axis=-1)
        fallback = _unit_perp(g)
        f2 = np.where(~at_pole[:, None], hq / np.where(at_pole, 1.0, rho0)[:, None],
                      np.where((nhv > 0.0)[:, None], hv / np.where(nhv > 0.0, nhv, 1.0)[:, None], fallback))
        rho0 = np.where(at_pole, 0.0, rho0)
        hv2 = np.sum(hv * f2, axis=-1)
        hperp = hv - hv2[:, None] * f2
        nperp = np.linalg.norm(hperp, axis=-1)
        ell = rho0 * nperp
        planar = at_pole | (nperp <= planar_tol * nhv)     # horizontal q0, v0 parallel: sin < planar_tol
        f3 = np.where((nperp > 0.0)[:, None], hperp / np.where(nperp > 0.0, nperp, 1.0)[:, None], 0.0)
        self._z0, self._zd0, self._rho0, self._hv2 = z0, zd0, rho0, hv2
        self._f2, self._f3, self._ell = f2, f3, np.where(planar, 0.0, ell)
        self._speed = speed
        self._free = np.full(nb, beta == 0.0)
        self._planar = planar & ~self._free
        self._general = ~planar & ~self._free
        self._q0f, self._v0f = q0, v0
        shape = (nb,)
        self._roots = np.zeros(shape + (3,))
        self._m = np.zeros(shape)
        self._m1 = np.ones(shape)
        self._period = np.zeros(shape)
        self._prec = np.zeros(shape)
        self._range = np.zeros(shape + (2,))
        if np.any(self._free):
            self._setup_free()
        if np.any(self._planar):
            self._setup_planar(self._planar)
        if np.any(self._general):
            self._setup_general(self._general)
        # energy, angular momentum, cubic in the original height <gamma, q>
        e_orig = 0.5 * speed ** 2 + (self.B / self.mass) * (q0 @ self.gamma)
        bs = self.B / self.mass
        self._energy = self.mass * e_orig
        self._angmom = self.mass * self._ell
        self._cubic = np.stack([np.full(nb, 2.0 * bs), -2.0 * e_orig, np.full(nb, -2.0 * bs),
                                2.0 * e_orig - self._ell ** 2], axis=-1)
        if self._sigma < 0.0:
            self._roots = -self._roots[:, ::-1]
            self._range = -self._range[:, ::-1]

    def _setup_free(self) -> None:
        idx = self._free
        w = self._speed[idx]
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.sqrt(np.clip(1.0 - (self._ell[idx] / np.where(w > 0, w, 1.0)) ** 2, 0.0, 1.0))
            self._period[idx] = np.where(w > 0.0, 2.0 * np.pi / np.where(w > 0, w, 1.0), np.inf)
        z0 = self._z0[idx]
        r = np.where(w > 0.0, r, np.abs(z0))
        self._roots[idx] = np.stack([-r, r, np.full_like(r, np.inf)], axis=-1)
        self._range[idx] = np.stack([np.where(w > 0, -r, z0), np.where(w > 0, r, z0)], axis=-1)
        self._prec[idx] = np.where(w > 0.0, 2.0 * np.pi, np.nan)
        self._m[idx] = 0.0
        self._m1[idx] = 1.0

    def _setup_planar(self, idx: np.ndarray) -> None:
        beta = self._beta
        zd0, hv2 = self._zd0[idx], self._hv2[idx]
        q0 = self._q0f[idx]
        g = self._g
        sh = 0.5 * np.linalg.norm(q0 + g, axis=-1)    # sin(theta/2), theta from the stable pole -g
        ch = 0.5 * np.linalg.norm(q0 - g, axis=-1)    # cos(theta/2)
        th0 = 2.0 * np.arctan2(sh, ch)
        thd0 = np.sin(th0) * zd0 + np.cos(th0) * hv2
        a = np.abs(thd0) / (2.0 * np.sqrt(beta))
        m_lib = sh * sh + a * a
        m1_lib = (ch - a) * (ch + a)
        s = np.where(thd0 >= 0.0, 1.0, -1.0)
        lib = m1_lib >= 0.0
        k = np.sqrt(m_lib)
        # libration / separatrix: sin(theta/2) = k sn(s sqrt(beta) t + u0 | m_lib)
        ks = np.where(k > 0.0, k, 1.0)
        sphi = np.where(k > 0.0, sh / ks, 0.0)
        c2phi = np.where(k > 0.0, (a / ks) ** 2, 1.0)
        m1_l = np.where(lib, m1_lib, 0.5)
        u0_lib = incomplete_f(np.clip(sphi, -1, 1), np.clip(c2phi, 0, 1), m1_l)
        # rotation: theta/2 = s am(lambda_r t + u0 | 1/m_lib)
        mr = np.where(lib, 2.0, m_lib)
        kap1 = np.where(lib, 0.5, -m1_lib / mr)
        u0_rot = incomplete_f(s * sh, ch * ch, kap1)
        lam_r = np.sqrt(beta * mr)
        Klib = complete_k(m1_l)
        Krot = complete_k(kap1)
        period = np.where(lib, 2.0 * Klib / np.sqrt(beta), 2.0 * Krot / lam_r)
        self._pl = dict(lib=lib, s=s, k=k, m_lib=m_lib, m1_lib=m1_l, u0_lib=u0_lib, kap=1.0 / mr,
                        kap1=kap1, u0_rot=u0_rot, lam_r=lam_r)
        self._m[idx] = np.where(lib, m_lib, 1.0 / mr)
        self._m1[idx] = np.where(lib, m1_l, kap1)
        self._period[idx] = period
        self._prec[idx] = np.where(lib, np.pi, 2.0 * np.pi)
        e_over_beta = 2.0 * m_lib - 1.0
        roots = np.where(lib[:, None], np.stack([-np.ones_like(k), e_over_beta, np.ones_like(k)], -1),
                         np.stack([-np.ones_like(k), np.ones_like(k), e_over_beta], -1))
        self._roots[idx] = roots
        self._range[idx] = roots[:, :2]

    def _setup_general(self, idx: np.ndarray) -> None:
        beta = self._beta
        g = self._g
        q0 = self._q0f[idx]
        z0, zd0, rho0, ell = self._z0[idx], self._zd0[idx], self._rho0[idx], self._ell[idx]
        K0 = 0.5 * self._speed[idx] ** 2
        R = rho0 * rho0
        w0 = 0.5 * np.sum((q0 - g) ** 2, axis=-1)      # 1 - z0
        v0b = 0.5 * np.sum((q0 + g) ** 2, axis=-1)     # 1 + z0
        eps_top = K0 - beta * w0                       # e - beta
        eta = K0 + beta * v0b                          # e + beta
        l2 = ell * ell
        one = np.ones_like(z0)
        sr = real_cubic_roots(2.0 * beta * one, 2.0 * (2.0 * beta * z0 - K0),
                              -2.0 * (2.0 * K0 * z0 + beta * R), zd0 * zd0)
        wr = real_cubic_roots(-2.0 * beta * one, 2.0 * (2.0 * beta - eps_top), 4.0 * eps_top, -l2)
        vr = real_cubic_roots(2.0 * beta * one, -2.0 * (eta + 2.0 * beta), 4.0 * eta, -l2)
        s1 = np.minimum(sr[:, 0], 0.0)
        s2 = np.maximum(sr[:, 1], 0.0)
        w3 = np.minimum(wr[:, 0], 0.0)
        w2 = np.maximum(wr[:, 1], 0.0)
        v1 = np.maximum(vr[:, 0], 0.0)
        # each root from the expansion whose centre is nearest to it (z0, -1 or +1)
        near1 = -s1 <= v1
        near2 = s2 <= w2
        a1 = np.where(near1, -s1, np.maximum(v0b - v1, 0.0))     # z0 - z1
        a2 = np.where(near2, s2, np.maximum(w0 - w2, 0.0))       # z2 - z0
        opz1 = np.where(near1, np.maximum(v0b + s1, 0.0), v1)    # 1 + z1
        omz2 = np.where(near2, np.maximum(w0 - s2, 0.0), w2)     # 1 - z2
        d21 = a1 + a2
        d32 = omz2 - w3
        d31 = d21 + d32
        omz1 = omz2 + d21
        m = d21 / d31
        m1 = d32 / d31
        lam = np.sqrt(0.5 * beta * d31)
        K = complete_k(m1)
        pos = d21 > 0.0
        d21s = np.where(pos, d21, 1.0)
        sphi = np.where(pos, np.sqrt(np.clip(a1 / d21s, 0.0, 1.0)), 0.0)
        c2phi = np.where(pos, np.clip(a2 / d21s, 0.0, 1.0), 1.0)
        u0 = incomplete_f(sphi, c2phi, m1)
        s = np.where(zd0 >= 0.0, 1.0, -1.0)
        n_p = d21 / omz1
        omn_p = w2 / omz1
        n_m = -d21 / opz1
        omn_m = (opz1 + d21) / opz1
        Pp = complete_pi_any(n_p, omn_p, m, m1)
        Pm = complete_pi_any(n_m, omn_m, m, m1)
        sn0, cn0, _, am0 = jacobi(u0, m, m1)
        G0 = 0.5 * (amplitude_pi(n_p, omn_p, am0, sn0, cn0, m, m1, Pp) / omz1
                    + amplitude_pi(n_m, omn_m, am0, sn0, cn0, m, m1, Pm) / opz1)
        self._gen = dict(d21=d21, omz2=omz2, opz1=opz1, omz1=omz1, m=m, m1=m1, lam=lam, u0=u0,
                         s=s, n_p=n_p, omn_p=omn_p, n_m=n_m, omn_m=omn_m, Pp=Pp, Pm=Pm, G0=G0, ell=ell)
        self._m[idx] = m
        self._m1[idx] = m1
        self._period[idx] = 2.0 * K / lam
        self._prec[idx] = ell / lam * (Pp / omz1 + Pm / opz1)
        z1, z2, z3 = -1.0 + opz1, 1.0 - omz2, 1.0 - w3
        self._roots[idx] = np.stack([z1, z2, z3], axis=-1)
        self._range[idx] = np.stack([z1, z2], axis=-1)

    # ------------------------------------------------------------------------------------ properties
    def _out(self, a: np.ndarray) -> np.ndarray:
        return a.reshape(self.batch_shape + a.shape[1:])

    @property
    def energy(self) -> np.ndarray:
        return self._out(self._energy)

    @property
    def angular_momentum(self) -> np.ndarray:
        return self._out(self._angmom)

    @property
    def cubic(self) -> np.ndarray:
        return self._out(self._cubic)

    @property
    def roots(self) -> np.ndarray:
        return self._out(self._roots)

    @property
    def height_range(self) -> np.ndarray:
        return self._out(self._range)

    @property
    def parameter(self) -> np.ndarray:
        return self._out(self._m)

    @property
    def complementary_parameter(self) -> np.ndarray:
        return self._out(self._m1)

    @property
    def height_period(self) -> np.ndarray:
        return self._out(self._period)

    @property
    def precession(self) -> np.ndarray:
        return self._out(self._prec)

    @property
    def planar(self) -> np.ndarray:
        return self._out(self._planar | (self._free & (self._ell == 0.0)))

    def cubic_value(self, z: Any) -> np.ndarray:
        """``C(z)`` (= ``(dz/dt)^2`` along the motion), ``z`` broadcast against the batch shape (...)."""
        z = C.as_array(z, "z")
        c = self.cubic
        return ((c[..., 0] * z + c[..., 1]) * z + c[..., 2]) * z + c[..., 3]

    # ------------------------------------------------------------------------------------ evaluation
    def height(self, t: Any) -> np.ndarray:
        """``z(t) = <gamma, q(t)>``, shape ``t.shape + batch_shape``."""
        q, _ = self.state(t)
        return q @ self.gamma

    def state(self, t: Any) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity at the times ``t``.

        Parameters
        ----------
        t : array_like, any shape
            Times (any sign) measured from the initial data.

        Returns
        -------
        q, v : ndarray, shape ``t.shape + batch_shape + (n,)``
            ``q(t)`` on the unit sphere and ``v(t) = dq/dt`` tangent to it.
        """
        t = C.times(t)
        tf = t.reshape(-1)
        nb = self._z0.shape[0]
        q = np.empty((tf.size, nb, self.n))
        v = np.empty_like(q)
        if np.any(self._free):
            q[:, self._free], v[:, self._free] = self._state_free(tf, self._free)
        if np.any(self._planar):
            q[:, self._planar], v[:, self._planar] = self._state_planar(tf, self._planar)
        if np.any(self._general):
            q[:, self._general], v[:, self._general] = self._state_general(tf, self._general)
        shape = t.shape + self.batch_shape + (self.n,)
        return q.reshape(shape), v.reshape(shape)

    def _state_free(self, t: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q0, v0, w = self._q0f[idx], self._v0f[idx], self._speed[idx]
        wt = t[:, None] * w[None, :]
        ws = np.where(w > 0.0, w, 1.0)
        c, s = np.cos(wt)[..., None], np.sin(wt)[..., None]
        q = c * q0 + s * (v0 / ws[:, None])
        v = -s * (q0 * w[:, None]) + c * v0
        return q, v

    def _state_planar(self, t: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        P = self._pl
        beta = self._beta
        g, f2 = self._g, self._f2[idx]
        lib = P["lib"]
        s = P["s"]
        # libration and separatrix
        u = s * np.sqrt(beta) * t[:, None] + P["u0_lib"]
        sn, cn, dn, _ = jacobi(u, P["m_lib"], P["m1_lib"])
        k = P["k"]
        cos_l = dn * dn - P["m_lib"] * sn * sn
        sin_l = 2.0 * k * sn * dn
        thd_l = 2.0 * s * k * np.sqrt(beta) * cn
        # rotation
        ur = P["lam_r"] * t[:, None] + P["u0_rot"]
        snr, cnr, dnr, _ = jacobi(ur, P["kap"], P["kap1"])
        cos_r = cnr * cnr - snr * snr
        sin_r = 2.0 * s * snr * cnr
        thd_r = 2.0 * s * P["lam_r"] * dnr
        cth = np.where(lib, cos_l, cos_r)[..., None]
        sth = np.where(lib, sin_l, sin_r)[..., None]
        thd = np.where(lib, thd_l, thd_r)[..., None]
        q = -cth * g + sth * f2
        v = thd * (sth * g + cth * f2)
        return q, v

    def _state_general(self, t: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        P = self._gen
        g, f2, f3 = self._g, self._f2[idx], self._f3[idx]
        s, lam = P["s"], P["lam"]
        u = s * lam * t[:, None] + P["u0"]
        sn, cn, dn, am = jacobi(u, P["m"], P["m1"])
        d21 = P["d21"]
        omz = P["omz2"] + d21 * cn * cn
        opz = P["opz1"] + d21 * sn * sn
        z = 0.5 * (opz - omz)
        rho = np.sqrt(omz * opz)
        zd = 2.0 * s * lam * d21 * sn * cn * dn
        G = 0.5 * (amplitude_pi(P["n_p"], P["omn_p"], am, sn, cn, P["m"], P["m1"], P["Pp"]) / P["omz1"]
                   + amplitude_pi(P["n_m"], P["omn_m"], am, sn, cn, P["m"], P["m1"], P["Pm"]) / P["opz1"])
        ell = P["ell"]
        phi = s * ell / lam * (G - P["G0"])
        c, sp = np.cos(phi)[..., None], np.sin(phi)[..., None]
        radial = c * f2 + sp * f3
        tang = -sp * f2 + c * f3
        rhod = -z * zd / rho
        q = z[..., None] * g + rho[..., None] * radial
        v = zd[..., None] * g + rhod[..., None] * radial + (ell / rho)[..., None] * tang
        return q, v
