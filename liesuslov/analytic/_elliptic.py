"""Elliptic functions and integrals that take the complementary parameter ``m1 = 1 - m`` as input.

Near a separatrix the parameter ``m`` is within ``1e-8`` of 1 and ``1 - m`` formed from ``m`` has lost
half its digits. Every function here therefore receives ``m1`` computed directly from the problem's
data (differences of roots) and never forms ``1 - m``:

* :func:`jacobi` — ``sn, cn, dn, am`` by the arithmetic–geometric mean started from ``b0 = sqrt(m1)``
  (the Cephes algorithm), with the argument reduced modulo ``2K``;
* :func:`complete_k` — ``K(m)`` by ``scipy.special.ellipkm1(m1)``;
* :func:`incomplete_f`, :func:`incomplete_pi`, :func:`complete_pi` — Legendre's integrals through
  Carlson's ``R_F`` and ``R_J`` with ``1 - m sin^2 phi`` written as ``cos^2 phi + m1 sin^2 phi``.

Also :func:`real_cubic_roots`, the three real roots of a cubic with the small ones to relative
accuracy (largest root by the trigonometric formula and Newton, backward deflation, stable
quadratic formula).
"""

from __future__ import annotations

import numpy as np
from scipy.special import ellipkm1, elliprc, elliprf, elliprj

_EPS = np.finfo(float).eps


def complete_k(m1: np.ndarray) -> np.ndarray:
    """``K(m)`` from the complementary parameter ``m1 = 1 - m`` in [0, 1]; ``inf`` at ``m1 = 0``."""
    return ellipkm1(np.asarray(m1, dtype=float))


def jacobi(u: np.ndarray, m: np.ndarray,
           m1: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Jacobi ``sn, cn, dn`` and the amplitude ``am`` (continuous in ``u``), broadcast over all inputs.

    ``m`` in [0, 1] and ``m1 = 1 - m`` given separately (see the module docstring).
    """
    u, m, m1 = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (u, m, m1)))
    sep = m1 <= 0.0
    m1s = np.where(sep, 0.5, m1)
    ms = np.where(sep, 0.5, m)
    K = complete_k(m1s)
    with np.errstate(invalid="ignore"):
        j = np.where(np.isfinite(u), np.round(u / (2.0 * K)), 0.0)
        ur = np.where(np.isfinite(u), u - 2.0 * K * j, 0.0)
    a = np.ones_like(ur)
    b = np.sqrt(m1s)
    c = np.sqrt(ms)
    a_list, c_list = [a], [c]
    for _ in range(40):
        if float(np.max(np.abs(c), initial=0.0)) <= _EPS:
            break
        a, b, c = 0.5 * (a + b), np.sqrt(a * b), 0.5 * (a - b)
        a_list.append(a)
        c_list.append(c)
    N = len(a_list) - 1
    phi = (2.0 ** N) * a_list[N] * ur
    for i in range(N, 0, -1):
        phi = 0.5 * (phi + np.arcsin(np.clip(c_list[i] * np.sin(phi) / a_list[i], -1.0, 1.0)))
    sn, cn = np.sin(phi), np.cos(phi)
    sgn = np.where(np.mod(j, 2.0) == 0.0, 1.0, -1.0)
    sn, cn = sgn * sn, sgn * cn
    dn = np.sqrt(cn * cn + m1s * sn * sn)
    am = phi + np.pi * j
    if np.any(sep):
        us = u[sep]
        sn[sep] = np.tanh(us)
        cn[sep] = 1.0 / np.cosh(us)
        dn[sep] = cn[sep]
        am[sep] = 2.0 * np.arctan(np.tanh(0.5 * us))
    return sn, cn, dn, am


def incomplete_f(s: np.ndarray, c2: np.ndarray, m1: np.ndarray) -> np.ndarray:
    """``F(phi | m)`` for ``phi`` in [-pi/2, pi/2] given ``s = sin phi`` and ``c2 = cos^2 phi``."""
    s, c2, m1 = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (s, c2, m1)))
    return s * elliprf(c2, c2 + m1 * s * s, 1.0)


def complete_pi(n: np.ndarray, m1: np.ndarray) -> np.ndarray:
    """``Pi(n | m) = int_0^{pi/2} dth / ((1 - n sin^2 th) sqrt(1 - m sin^2 th))`` for ``n < 1``.

    ``1 - n`` is formed here; pass ``n`` only where that is accurate (the caller passes ``1 - n``
    through :func:`complete_pi_1mn` otherwise).
    """
    n = np.asarray(n, dtype=float)
    return complete_pi_1mn(n, 1.0 - n, m1)


def complete_pi_1mn(n: np.ndarray, one_minus_n: np.ndarray, m1: np.ndarray) -> np.ndarray:
    """``Pi(n | m)`` with ``1 - n`` supplied by the caller (accurate when ``n`` is close to 1)."""
    n, omn, m1 = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (n, one_minus_n, m1)))
    return elliprf(0.0, m1, 1.0) + n / 3.0 * elliprj(0.0, m1, 1.0, omn)


def incomplete_pi_1mn(n: np.ndarray, one_minus_n: np.ndarray, s: np.ndarray, c2: np.ndarray,
                      m1: np.ndarray) -> np.ndarray:
    """``Pi(n; phi | m)`` for ``phi`` in [-pi/2, pi/2] from ``s = sin phi``, ``c2 = cos^2 phi``, ``1 - n``.

    ``1 - n sin^2 phi`` is evaluated as ``(1 - n) + n cos^2 phi``.
    """
    args = (n, one_minus_n, s, c2, m1)
    n, omn, s, c2, m1 = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in args))
    d2 = c2 + m1 * s * s
    p = omn + n * c2
    return s * elliprf(c2, d2, 1.0) + n / 3.0 * s ** 3 * elliprj(c2, d2, 1.0, p)


def incomplete_pi_neg(N: np.ndarray, s: np.ndarray, c2: np.ndarray, m: np.ndarray,
                      m1: np.ndarray) -> np.ndarray:
    """``Pi(-N; phi | m)`` for ``N >= 0``, ``phi`` in [-pi/2, pi/2], without cancellation for large ``N``.

    Legendre's form ``F + (n/3) s^3 R_J`` subtracts two O(1) numbers to get an O(N^-1/2) result when
    ``N`` is large. The characteristic pairing ``n n' = m`` (DLMF 19.7.9) with ``n = -N``,
    ``n' = -m/N`` gives a sum of two positive terms instead::

        Pi(-N; phi) = (m / 3N) s^3 R_J(c^2, D^2, 1, 1 + (m/N) s^2)
                      + s R_C(c^2 D^2, (1 + N s^2)(1 + (m/N) s^2))

    with ``s = sin phi``, ``c^2 = cos^2 phi``, ``D^2 = c^2 + m1 s^2``. ``N = 0`` gives ``F(phi | m)``.
    """
    N, s, c2, m, m1 = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (N, s, c2, m, m1)))
    d2 = c2 + m1 * s * s
    small = N <= 0.0
    Ns = np.where(small, 1.0, N)
    r = m / Ns
    val = r / 3.0 * s ** 3 * elliprj(c2, d2, 1.0, 1.0 + r * s * s) + s * elliprc(c2 * d2, (1.0 + Ns * s * s)
                                                                                 * (1.0 + r * s * s))
    return np.where(small, s * elliprf(c2, d2, 1.0), val)


def amplitude_pi(n: np.ndarray, one_minus_n: np.ndarray, am: np.ndarray, sn: np.ndarray, cn: np.ndarray,
                 m: np.ndarray, m1: np.ndarray, pi_complete: np.ndarray) -> np.ndarray:
    """``Pi(n; am | m)`` for any amplitude ``am`` (quasi-periodic continuation) from ``sn, cn``.

    ``n <= 0`` goes through :func:`incomplete_pi_neg`; ``0 < n < 1`` through Legendre's Carlson form
    with the caller's ``1 - n``.
    """
    j = np.round(am / np.pi)
    sgn = np.where(np.mod(j, 2.0) == 0.0, 1.0, -1.0)
    s = sgn * sn
    c2 = cn * cn
    n = np.asarray(n, dtype=float)
    inc = np.where(n <= 0.0, incomplete_pi_neg(-np.minimum(n, 0.0), s, c2, m, m1),
                   incomplete_pi_1mn(np.maximum(n, 0.0), one_minus_n, s, c2, m1))
    return 2.0 * j * pi_complete + inc


def complete_pi_any(n: np.ndarray, one_minus_n: np.ndarray, m: np.ndarray, m1: np.ndarray) -> np.ndarray:
    """``Pi(n | m)`` for ``n < 1``: negative ``n`` without cancellation, ``1 - n`` supplied by the caller."""
    n = np.asarray(n, dtype=float)
    neg = incomplete_pi_neg(-np.minimum(n, 0.0), 1.0, 0.0, m, m1)
    pos = complete_pi_1mn(np.maximum(n, 0.0), np.where(n > 0.0, one_minus_n, 1.0), m1)
    return np.where(n <= 0.0, neg, pos)


# ---------------------------------------------------------------------------------------- cubic roots
def real_cubic_roots(c3: np.ndarray, c2: np.ndarray, c1: np.ndarray, c0: np.ndarray) -> np.ndarray:
    """The three real roots, ascending, of ``c3 x^3 + c2 x^2 + c1 x + c0`` (``c3 != 0``), shape (..., 3).

    For cubics known to have three real roots (up to rounding). The most isolated root (an end
    root, always simple unless the root is triple) comes from the trigonometric formula polished
    by Newton steps; the other two from the deflated quadratic (backward deflation when the
    isolated root is the largest in modulus, forward otherwise) by the cancellation-free formula.
    Roots much smaller than the others keep their relative accuracy when the coefficients have
    it; a near-double pair is as accurate as its conditioning allows (``sqrt(eps)`` relative).
    """
    c3, c2, c1, c0 = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (c3, c2, c1, c0)))
    a, b, c = c2 / c3, c1 / c3, c0 / c3
    p = b - a * a / 3.0
    q = 2.0 * a ** 3 / 27.0 - a * b / 3.0 + c
    pn = np.minimum(p, 0.0)
    r = 2.0 * np.sqrt(-pn / 3.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        arg = np.where(pn < 0.0, 3.0 * q / (pn * r), 0.0)
    th = np.arccos(np.clip(arg, -1.0, 1.0)) / 3.0
    ks = np.arange(3.0) * (2.0 * np.pi / 3.0)
    cand = np.sort(r[..., None] * np.cos(th[..., None] - ks) - a[..., None] / 3.0, axis=-1)
    low_isolated = (cand[..., 1] - cand[..., 0]) >= (cand[..., 2] - cand[..., 1])
    x = np.where(low_isolated, cand[..., 0], cand[..., 2])
    others_max = np.where(low_isolated, np.maximum(np.abs(cand[..., 1]), np.abs(cand[..., 2])),
                          np.maximum(np.abs(cand[..., 0]), np.abs(cand[..., 1])))
    for _ in range(6):
        f = ((c3 * x + c2) * x + c1) * x + c0
        df = (3.0 * c3 * x + 2.0 * c2) * x + c1
        ok = df != 0.0
        x = x - np.where(ok, f / np.where(ok, df, 1.0), 0.0)
    backward = np.abs(x) >= others_max
    xs = np.where(x != 0.0, x, 1.0)
    # backward: (x - r)(c3 x^2 + e1 x + e0) from the low coefficients; forward: from the high ones
    e0_b = -c0 / xs
    e1_b = (e0_b - c1) / xs
    e1_f = c2 + x * c3
    e0_f = c1 + x * e1_f
    e1 = np.where(backward & (x != 0.0), e1_b, e1_f)
    e0 = np.where(backward & (x != 0.0), e0_b, e0_f)
    disc = np.maximum(e1 * e1 - 4.0 * c3 * e0, 0.0)
    qq = -0.5 * (e1 + np.where(e1 >= 0.0, 1.0, -1.0) * np.sqrt(disc))
    nz = qq != 0.0
    r1 = np.where(nz, qq / c3, 0.0)
    r2 = np.where(nz, e0 / np.where(nz, qq, 1.0), 0.0)
    return np.sort(np.stack([x, r1, r2], axis=-1), axis=-1)
