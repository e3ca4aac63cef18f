"""The floor: plain compiled loops of the method the library runs, to report the library's cost as a ratio.

Each kernel is one scalar time loop in numba (``@njit(cache=True)``) doing exactly the arithmetic of
``ls.integrate(..., method="rkmk4", chart="exp", reconstruct=True)`` on one scene — no allocation per
step, no controller, no output — so that ``library time / floor time`` measures what the library adds
around the method (the time loop, dispatch, output), not the method.

The method (classical RK4 in the Munthe-Kaas form, exponential chart, right trivialisation
``g^{-1} g' = Omega``): stage i has ``Xi_i = xi + h sum_j a_ij L_j``, ``Theta_i = h sum_j a_ij K_j``,
``L_i = f(Xi_i, Gamma_i)`` with ``Gamma_i = exp(-Theta_i) Gamma`` and
``K_i = dexp^{-1}_{-Theta_i}(Omega(Xi_i)) = Omega + 1/2 [Theta_i, Omega] + c [Theta_i, [Theta_i, Omega]]``;
then ``xi1 = xi + h sum_i b_i L_i`` and ``g1 = g exp(h sum_i b_i K_i)``.

* :func:`free3_steps`, :func:`free3_batch` — the free rigid body in SO(3), Euler's equations
  ``J w' = (J w) x w`` for a diagonal J; rotation vectors, Rodrigues' formula and the closed-form so(3)
  ``dexp^{-1}`` (``c = (1 - (t/2) cot(t/2)) / t^2``, ``t = |Theta|``).
* :func:`kt4_steps` — the Klebsh–Tisserand body in SO(4) with the Fedorov–Kozlov constraints,
  ``xi_i' = c_i Gamma_i Gamma_4``, ``Omega = u e_4^T - e_4 u^T`` with ``u = (xi, 0)``,
  ``Gamma = g^T gamma``. so(4) = so(3) ⊕ so(3) by quaternions: ``X x = p x - x q`` (``x`` in H = R^4,
  ``p``, ``q`` pure), whose bracket is the cross product on each factor in ``P = 2p``, ``Q = 2q``; so
  ``exp(X) x = e^p x e^-q`` (two unit quaternions) and ``dexp^{-1}`` acts factor by factor as on so(3).
  ``exact`` picks the closed-form ``c`` or the library's truncated series ``c = 1/12`` (the terms up to
  ``ad^2``, enough for order 4).

Importing this module imports numba; :mod:`.targets` imports it only when numba is installed.
"""

from __future__ import annotations

import math

from numba import njit

__all__ = ["free3_steps", "free3_batch", "kt4_steps"]


@njit(cache=True)
def _c_exact(t2):
    """(1 - (t/2) cot(t/2)) / t^2 for t^2 = |Theta|^2: the so(3) dexp^-1 coefficient of ad^2."""
    if t2 < 1e-6:  # the series: the closed form cancels catastrophically near 0
        return 1.0 / 12.0 + t2 * (1.0 / 720.0 + t2 / 30240.0)
    t = math.sqrt(t2)
    return (1.0 - 0.5 * t / math.tan(0.5 * t)) / t2


@njit(cache=True)
def _dexpinv(tx, ty, tz, wx, wy, wz, exact):
    """dexp^{-1}_{-Theta}(w) on so(3) = (R^3, x): w + 1/2 Theta x w + c Theta x (Theta x w)."""
    c = _c_exact(tx * tx + ty * ty + tz * tz) if exact else 1.0 / 12.0
    ax = ty * wz - tz * wy
    ay = tz * wx - tx * wz
    az = tx * wy - ty * wx
    bx = ty * az - tz * ay
    by = tz * ax - tx * az
    bz = tx * ay - ty * ax
    return wx + 0.5 * ax + c * bx, wy + 0.5 * ay + c * by, wz + 0.5 * az + c * bz


@njit(cache=True)
def _free3_field(a, wx, wy, wz):
    """Euler's equations: w' = (a1 w2 w3, a2 w3 w1, a3 w1 w2)."""
    return a[0] * wy * wz, a[1] * wz * wx, a[2] * wx * wy


@njit(cache=True)
def free3_steps(w, g, a, h, nsteps):
    """Advance ``w`` (3,) and ``g`` (3, 3) in place by ``nsteps`` RKMK4 steps of the free rigid body.

    ``a = ((J2 - J3)/J1, (J3 - J1)/J2, (J1 - J2)/J3)``: Euler's equations ``w1' = a1 w2 w3`` (cyclic).
    """
    w1, w2, w3 = w[0], w[1], w[2]
    g00, g01, g02 = g[0, 0], g[0, 1], g[0, 2]
    g10, g11, g12 = g[1, 0], g[1, 1], g[1, 2]
    g20, g21, g22 = g[2, 0], g[2, 1], g[2, 2]
    hh = 0.5 * h
    for _ in range(nsteps):
        # stage 1: Theta = 0, K = Omega
        l1x, l1y, l1z = _free3_field(a, w1, w2, w3)
        k1x, k1y, k1z = w1, w2, w3
        # stage 2
        xx, xy, xz = w1 + hh * l1x, w2 + hh * l1y, w3 + hh * l1z
        l2x, l2y, l2z = _free3_field(a, xx, xy, xz)
        k2x, k2y, k2z = _dexpinv(hh * k1x, hh * k1y, hh * k1z, xx, xy, xz, True)
        # stage 3
        xx, xy, xz = w1 + hh * l2x, w2 + hh * l2y, w3 + hh * l2z
        l3x, l3y, l3z = _free3_field(a, xx, xy, xz)
        k3x, k3y, k3z = _dexpinv(hh * k2x, hh * k2y, hh * k2z, xx, xy, xz, True)
        # stage 4
        xx, xy, xz = w1 + h * l3x, w2 + h * l3y, w3 + h * l3z
        l4x, l4y, l4z = _free3_field(a, xx, xy, xz)
        k4x, k4y, k4z = _dexpinv(h * k3x, h * k3y, h * k3z, xx, xy, xz, True)
        h6 = h / 6.0
        w1 += h6 * (l1x + 2.0 * l2x + 2.0 * l3x + l4x)
        w2 += h6 * (l1y + 2.0 * l2y + 2.0 * l3y + l4y)
        w3 += h6 * (l1z + 2.0 * l2z + 2.0 * l3z + l4z)
        tx = h6 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
        ty = h6 * (k1y + 2.0 * k2y + 2.0 * k3y + k4y)
        tz = h6 * (k1z + 2.0 * k2z + 2.0 * k3z + k4z)
        # Rodrigues: R = I + s hat(T) + c hat(T)^2
        t2 = tx * tx + ty * ty + tz * tz
        if t2 < 1e-12:
            s = 1.0 - t2 / 6.0
            c = 0.5 - t2 / 24.0
        else:
            t = math.sqrt(t2)
            s = math.sin(t) / t
            c = (1.0 - math.cos(t)) / t2
        r00 = 1.0 - c * (ty * ty + tz * tz)
        r11 = 1.0 - c * (tx * tx + tz * tz)
        r22 = 1.0 - c * (tx * tx + ty * ty)
        r01 = c * tx * ty - s * tz
        r10 = c * tx * ty + s * tz
        r02 = c * tx * tz + s * ty
        r20 = c * tx * tz - s * ty
        r12 = c * ty * tz - s * tx
        r21 = c * ty * tz + s * tx
        g00, g01, g02 = (g00 * r00 + g01 * r10 + g02 * r20, g00 * r01 + g01 * r11 + g02 * r21,
                         g00 * r02 + g01 * r12 + g02 * r22)
        g10, g11, g12 = (g10 * r00 + g11 * r10 + g12 * r20, g10 * r01 + g11 * r11 + g12 * r21,
                         g10 * r02 + g11 * r12 + g12 * r22)
        g20, g21, g22 = (g20 * r00 + g21 * r10 + g22 * r20, g20 * r01 + g21 * r11 + g22 * r21,
                         g20 * r02 + g21 * r12 + g22 * r22)
    w[0], w[1], w[2] = w1, w2, w3
    g[0, 0], g[0, 1], g[0, 2] = g00, g01, g02
    g[1, 0], g[1, 1], g[1, 2] = g10, g11, g12
    g[2, 0], g[2, 1], g[2, 2] = g20, g21, g22


@njit(cache=True)
def free3_batch(W, G, a, h, nsteps):
    """:func:`free3_steps` on each trajectory of ``W`` (B, 3), ``G`` (B, 3, 3) in turn: one thread."""
    for b in range(W.shape[0]):
        free3_steps(W[b], G[b], a, h, nsteps)


@njit(cache=True)
def _qmul(a0, a1, a2, a3, b0, b1, b2, b3):
    """The quaternion product a b."""
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3, a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1, a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


@njit(cache=True)
def _qexp_half(x, y, z):
    """The unit quaternion exp(v / 2) of the pure quaternion v = (x, y, z)."""
    t2 = x * x + y * y + z * z
    if t2 < 1e-12:
        return 1.0 - t2 / 8.0, 0.5 * x, 0.5 * y, 0.5 * z  # sin(t/2)/t = 1/2 - t^2/48: below rounding here
    t = math.sqrt(t2)
    s = math.sin(0.5 * t) / t
    return math.cos(0.5 * t), s * x, s * y, s * z


@njit(cache=True)
def _kt4_stage(c, xi0, xi1, xi2, P0, P1, P2, Q0, Q1, Q2, G0, G1, G2, G3, exact):
    """Field L and chart velocity K = dexp^{-1}_{-Theta}(Omega(Xi)) of one stage at Theta = (P, Q).

    Gamma_i = exp(-Theta) Gamma = e^{-p} Gamma e^{q}.
    """
    a0, a1, a2, a3 = _qexp_half(-P0, -P1, -P2)
    b0, b1, b2, b3 = _qexp_half(Q0, Q1, Q2)
    x0, x1, x2, x3 = _qmul(a0, a1, a2, a3, G0, G1, G2, G3)
    x0, x1, x2, x3 = _qmul(x0, x1, x2, x3, b0, b1, b2, b3)
    # Omega(Xi) in (P, Q): P = (-xi2, xi1, -xi0), Q = (-xi2, xi1, xi0)
    kp = _dexpinv(P0, P1, P2, -xi2, xi1, -xi0, exact)
    kq = _dexpinv(Q0, Q1, Q2, -xi2, xi1, xi0, exact)
    return c[0] * x0 * x3, c[1] * x1 * x3, c[2] * x2 * x3, kp, kq


@njit(cache=True)
def kt4_steps(xi, g, gamma, c, h, nsteps, exact):
    """Advance ``xi`` (3,) and ``g`` (4, 4) in place by ``nsteps`` RKMK4 steps of the Klebsh–Tisserand body.

    ``gamma = g0 Gamma0`` is the vertical in space; ``c_i = (B_i - B_4) / (I_i + I_4)``; ``exact``: the
    closed-form so(3) ``dexp^{-1}`` on each factor (else the series to ``ad^2``).
    """
    hh = 0.5 * h
    h6 = h / 6.0
    for _ in range(nsteps):
        # Gamma = g^T gamma at the start of the step
        G0 = g[0, 0] * gamma[0] + g[1, 0] * gamma[1] + g[2, 0] * gamma[2] + g[3, 0] * gamma[3]
        G1 = g[0, 1] * gamma[0] + g[1, 1] * gamma[1] + g[2, 1] * gamma[2] + g[3, 1] * gamma[3]
        G2 = g[0, 2] * gamma[0] + g[1, 2] * gamma[1] + g[2, 2] * gamma[2] + g[3, 2] * gamma[3]
        G3 = g[0, 3] * gamma[0] + g[1, 3] * gamma[1] + g[2, 3] * gamma[2] + g[3, 3] * gamma[3]
        u0, u1, u2 = xi[0], xi[1], xi[2]
        l1 = (c[0] * G0 * G3, c[1] * G1 * G3, c[2] * G2 * G3)
        kp1, kq1 = (-u2, u1, -u0), (-u2, u1, u0)
        l2x, l2y, l2z, kp2, kq2 = _kt4_stage(c, u0 + hh * l1[0], u1 + hh * l1[1], u2 + hh * l1[2], hh * kp1[0],
                                             hh * kp1[1], hh * kp1[2], hh * kq1[0], hh * kq1[1], hh * kq1[2],
                                             G0, G1, G2, G3, exact)
        l3x, l3y, l3z, kp3, kq3 = _kt4_stage(c, u0 + hh * l2x, u1 + hh * l2y, u2 + hh * l2z, hh * kp2[0],
                                             hh * kp2[1], hh * kp2[2], hh * kq2[0], hh * kq2[1], hh * kq2[2],
                                             G0, G1, G2, G3, exact)
        l4x, l4y, l4z, kp4, kq4 = _kt4_stage(c, u0 + h * l3x, u1 + h * l3y, u2 + h * l3z, h * kp3[0],
                                             h * kp3[1], h * kp3[2], h * kq3[0], h * kq3[1], h * kq3[2],
                                             G0, G1, G2, G3, exact)
        xi[0] = u0 + h6 * (l1[0] + 2.0 * l2x + 2.0 * l3x + l4x)
        xi[1] = u1 + h6 * (l1[1] + 2.0 * l2y + 2.0 * l3y + l4y)
        xi[2] = u2 + h6 * (l1[2] + 2.0 * l2z + 2.0 * l3z + l4z)
        P0 = h6 * (kp1[0] + 2.0 * kp2[0] + 2.0 * kp3[0] + kp4[0])
        P1 = h6 * (kp1[1] + 2.0 * kp2[1] + 2.0 * kp3[1] + kp4[1])
        P2 = h6 * (kp1[2] + 2.0 * kp2[2] + 2.0 * kp3[2] + kp4[2])
        Q0 = h6 * (kq1[0] + 2.0 * kq2[0] + 2.0 * kq3[0] + kq4[0])
        Q1 = h6 * (kq1[1] + 2.0 * kq2[1] + 2.0 * kq3[1] + kq4[1])
        Q2 = h6 * (kq1[2] + 2.0 * kq2[2] + 2.0 * kq3[2] + kq4[2])
        # g <- g exp(Theta): row r of g E is (E^T r)^T, and E^T = exp(-Theta) is x -> e^{-p} x e^{q}
        a0, a1, a2, a3 = _qexp_half(-P0, -P1, -P2)
        b0, b1, b2, b3 = _qexp_half(Q0, Q1, Q2)
        for r in range(4):
            y0, y1, y2, y3 = _qmul(a0, a1, a2, a3, g[r, 0], g[r, 1], g[r, 2], g[r, 3])
            g[r, 0], g[r, 1], g[r, 2], g[r, 3] = _qmul(y0, y1, y2, y3, b0, b1, b2, b3)
