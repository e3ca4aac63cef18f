"""so(4) = so(3) ⊕ so(3) by components: the split, the exponential and Cayley closed forms on the pair (p, q)."""

from __future__ import annotations

import math

import numpy as np

from .common import _SINC_TAYLOR, _Coef
from .so3 import _rodrigues_fast, _so3_lin_c, _sq, _stack, _vec_c

# ---------------------------------------------------------------------------- so(4) = so(3) ⊕ so(3) by components
# The component forms cost ~100 numpy calls on a batch (each over the batch, ~40 µs in all), against ~20
# stacked 4×4 products for Padé and one LU solve for Cayley: below these batch sizes the matrix
# algorithms are faster (a single element runs the components on Python floats, ~3 µs).
_SO4_EXP_MIN_BATCH = 64
_SO4_CAYLEY_MIN_BATCH = 256

# so(4) splits into two commuting copies of so(3) (self-dual and anti-self-dual 2-forms): X = P + Q with
#   P = p1 S1 + p2 S2 + p3 S3,  S = (E01 + E23, E02 − E13, E03 + E12),
#   Q = q1 A1 + q2 A2 + q3 A3,  A = (E01 − E23, E02 + E13, E03 − E12)            (0-based E_ij),
#   p = ½ (X01 + X23, X02 − X13, X03 + X12),  q = ½ (X01 − X23, X02 + X13, X03 − X12).
# S_i S_j = −δ_ij I − ε_ijk S_k and A_i A_j = −δ_ij I + ε_ijk A_k, [S_i, A_j] = 0, so
#   PQ = QP,  P² = −|p|² I,  Q² = −|q|² I,  [P, P'] ↔ −2 p × p',  [Q, Q'] ↔ 2 q × q',
#   P P' P = |p|² P' − 2 (p·p') P (likewise for Q),  |X|²_F = 4 (|p|² + |q|²),
# and every analytic function of X is a I + b P + c Q + d PQ (PQ is symmetric, traceless). In
# particular exp X = exp P exp Q = (cos|p| I + sinc|p| P)(cos|q| I + sinc|q| Q): closed forms with
# the cost of two so(3) Rodrigues formulas, orthogonal to rounding (no Padé, no solve).
def _so4_pq_c(X: np.ndarray) -> tuple[tuple, tuple]:
    """Components of ``p``, ``q`` of (..., 4, 4) skew matrices (upper triangle read); floats for one."""
    if X.size == 16:
        x01, x02, x03, x12, x13, x23 = (X.item(1), X.item(2), X.item(3), X.item(6), X.item(7), X.item(11))
    else:
        x01, x02, x03 = X[..., 0, 1], X[..., 0, 2], X[..., 0, 3]
        x12, x13, x23 = X[..., 1, 2], X[..., 1, 3], X[..., 2, 3]
    return _so4_pq_entries(x01, x02, x03, x12, x13, x23)


def _so4_pq_entries(x01, x02, x03, x12, x13, x23) -> tuple[tuple, tuple]:
    """``p``, ``q`` from the upper triangle ``X01, X02, X03, X12, X13, X23`` of a skew 4×4 matrix (floats or
    arrays): ``p = ½ (X01 + X23, X02 − X13, X03 + X12)``, ``q = ½ (X01 − X23, X02 + X13, X03 − X12)``."""
    return ((0.5 * (x01 + x23), 0.5 * (x02 - x13), 0.5 * (x03 + x12)),
            (0.5 * (x01 - x23), 0.5 * (x02 + x13), 0.5 * (x03 - x12)))


def _so4_pv_c(p: tuple, v: tuple) -> tuple:
    """Components of ``P v`` (P the self-dual part with coordinates p)."""
    p0, p1, p2 = p
    v0, v1, v2, v3 = v
    return (p0 * v1 + p1 * v2 + p2 * v3, -p0 * v0 + p2 * v2 - p1 * v3,
            -p1 * v0 - p2 * v1 + p0 * v3, -p2 * v0 + p1 * v1 - p0 * v2)


def _so4_qv_c(q: tuple, v: tuple) -> tuple:
    """Components of ``Q v`` (Q the anti-self-dual part with coordinates q)."""
    q0, q1, q2 = q
    v0, v1, v2, v3 = v
    return (q0 * v1 + q1 * v2 + q2 * v3, -q0 * v0 - q2 * v2 + q1 * v3,
            -q1 * v0 + q2 * v1 - q0 * v3, -q2 * v0 - q1 * v1 + q0 * v2)


def _so4_exp_coefficients(p: tuple, q: tuple) -> tuple[_Coef, _Coef, _Coef, _Coef]:
    """``(cos|p|, sinc|p|, cos|q|, sinc|q|)``: ``exp P = cos|p| I + sinc|p| P``, likewise Q."""
    a2 = p[0] * p[0] + p[1] * p[1] + p[2] * p[2]
    b2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2]
    if isinstance(a2, float):  # one element: math on floats, the branches of _rodrigues
        return _cos_sinc(a2) + _cos_sinc(b2)
    cp, sp, _ = _rodrigues_fast(a2)
    cq, sq, _ = _rodrigues_fast(b2)
    return cp, sp, cq, sq


def _cos_sinc(t2: float) -> tuple[float, float]:
    """``(cos θ, sin θ/θ)`` from a float ``θ²``: the first two of :func:`_rodrigues`, without its checks."""
    x2 = 0.25 * t2
    x = math.sqrt(x2)
    s = 1.0 - x2 * (1.0 / 6.0 - x2 / 120.0) if x < _SINC_TAYLOR else math.sin(x) / x
    return 1.0 - 0.5 * s * s * t2, s * math.cos(x)


def _so4_exp_apply_c(e: tuple, p: tuple, q: tuple, v: tuple, sign: float = 1.0) -> tuple:
    """``exp(±X) v = exp(±P) exp(±Q) v`` from the coefficients ``e`` of :func:`_so4_exp_coefficients`."""
    cp, sp, cq, sq = e
    if sign < 0:
        sp, sq = -sp, -sq
    u0, u1, u2, u3 = _so4_qv_c(q, v)
    v0, v1, v2, v3 = v
    w = (cq * v0 + sq * u0, cq * v1 + sq * u1, cq * v2 + sq * u2, cq * v3 + sq * u3)
    u0, u1, u2, u3 = _so4_pv_c(p, w)
    return cp * w[0] + sp * u0, cp * w[1] + sp * u1, cp * w[2] + sp * u2, cp * w[3] + sp * u3


def _so4_cayley_coefficients(p: tuple, q: tuple) -> tuple[_Coef, _Coef, _Coef, _Coef]:
    """``(c0, c1, c2, c3)`` with ``cay X = c0 I + c1 P + c2 Q + c3 PQ``.

    With ``a² = |p|²``, ``b² = |q|²``: ``(I − X/2)⁻¹ = (I − P/2 + Q/2)(μ I + P) / D``, where
    ``μ = 1 − a²/4 + b²/4`` and ``D = μ² + a² > 0`` (from ``(A − Q/2)(A + Q/2) = μ I − P`` with
    ``A = I − P/2``), and ``cay X = 2 (I − X/2)⁻¹ − I``; no division by a or b.
    """
    a2, b2 = _sq(p), _sq(q)
    mu = 1.0 - 0.25 * a2 + 0.25 * b2
    r = 1.0 / (mu * mu + a2)
    return (2.0 * mu + a2) * r - 1.0, (2.0 - mu) * r, mu * r, r


def _so4_lin_apply_c(c: tuple, p: tuple, q: tuple, v: tuple, sign: float = 1.0) -> tuple:
    """``(c0 I ± c1 P ± c2 Q + c3 PQ) v`` (the lower sign: the same function of −X)."""
    c0, c1, c2, c3 = c
    if sign < 0:
        c1, c2 = -c1, -c2
    Qv = _so4_qv_c(q, v)
    a0, a1, a2, a3 = _so4_pv_c(p, Qv)
    b0, b1, b2, b3 = _so4_pv_c(p, v)
    return (c0 * v[0] + c1 * b0 + c2 * Qv[0] + c3 * a0, c0 * v[1] + c1 * b1 + c2 * Qv[1] + c3 * a1,
            c0 * v[2] + c1 * b2 + c2 * Qv[2] + c3 * a2, c0 * v[3] + c1 * b3 + c2 * Qv[3] + c3 * a3)


def _so4_mat_c(c: tuple, p: tuple, q: tuple) -> tuple:
    """The 16 entries (row-major) of ``c0 I + c1 P + c2 Q + c3 PQ``."""
    c0, c1, c2, c3 = c
    p0, p1, p2 = p
    q0, q1, q2 = q
    P01, P02, P03, P12, P13, P23 = c1 * p0, c1 * p1, c1 * p2, c1 * p2, -c1 * p1, c1 * p0
    Q01, Q02, Q03, Q12, Q13, Q23 = c2 * q0, c2 * q1, c2 * q2, -c2 * q2, c2 * q1, -c2 * q0
    # PQ: first row (−p·q, p × q); lower 3×3 block diag(−p0q0 + p1q1 + p2q2, …), off-diagonal −(p_i q_j + p_j q_i)
    x0, x1, x2 = c3 * (p1 * q2 - p2 * q1), c3 * (p2 * q0 - p0 * q2), c3 * (p0 * q1 - p1 * q0)
    pq0, pq1, pq2 = p0 * q0, p1 * q1, p2 * q2
    d00 = c0 - c3 * (pq0 + pq1 + pq2)
    d11, d22, d33 = c0 + c3 * (-pq0 + pq1 + pq2), c0 + c3 * (pq0 - pq1 + pq2), c0 + c3 * (pq0 + pq1 - pq2)
    o12, o13, o23 = -c3 * (p0 * q1 + p1 * q0), -c3 * (p0 * q2 + p2 * q0), -c3 * (p1 * q2 + p2 * q1)
    return (d00, P01 + Q01 + x0, P02 + Q02 + x1, P03 + Q03 + x2,
            -P01 - Q01 + x0, d11, P12 + Q12 + o12, P13 + Q13 + o13,
            -P02 - Q02 + x1, -P12 - Q12 + o12, d22, P23 + Q23 + o23,
            -P03 - Q03 + x2, -P13 - Q13 + o13, -P23 - Q23 + o23, d33)


def _so4_exp_mat_c(e: tuple, p: tuple, q: tuple) -> tuple:
    """The 16 entries of ``exp X = cp cq I + sp cq P + cp sq Q + sp sq PQ``."""
    cp, sp, cq, sq = e
    return _so4_mat_c((cp * cq, sp * cq, cp * sq, sp * sq), p, q)


def _so4_dexpinv_c(half: float, cp: _Coef, cq: _Coef, a2: _Coef, b2: _Coef, p: tuple, q: tuple, ap: tuple,
                   aq: tuple) -> tuple:
    """The 6 components of the truncated ``dexp⁻¹_{−X}(A)`` (right side) on the pairs ``X ↔ (p, q)``, ``A ↔ (ap, aq)``.

    ``ad_P`` acts on the self-dual factor as ``ϑ ×`` with ``ϑ = −2p`` (``ϑ = 2q`` on the other factor), so
    the series is the so(3) one of :func:`~.dexp._dexpinv_so3_series` on each factor:
    ``a + half ϑ × a + C(|ϑ|²) ϑ × (ϑ × a)``, with ``a2 = |p|²``, ``b2 = |q|²``, ``cp = C(4 a2)``,
    ``cq = C(4 b2)`` (:func:`~.dexp._dexpinv_so3_poly`).
    """
    return (_so3_lin_c(1.0 - 4.0 * cp * a2, -2.0 * half, 4.0 * cp, p, ap)
            + _so3_lin_c(1.0 - 4.0 * cq * b2, 2.0 * half, 4.0 * cq, q, aq))


def _so4_dcayinv_c(a2: _Coef, b2: _Coef, p: tuple, q: tuple, ap: tuple, aq: tuple) -> tuple:
    """The 6 components of the exact ``dcay⁻¹_{−X}(A) = (I + X/2) A (I − X/2)`` on the pairs (``a2 = |p|²``,
    ``b2 = |q|²``).

    ``(I + X/2) A (I − X/2) = A + ½[X, A] − ¼ XAX`` with ``[X, A] ↔ (−2 p × ap, 2 q × aq)`` and
    ``XAX ↔ ((a² − b²) ap − 2 σ p, (b² − a²) aq − 2 σ q)``, ``σ = p·ap + q·aq``.
    """
    s = 0.5 * (p[0] * ap[0] + p[1] * ap[1] + p[2] * ap[2] + q[0] * aq[0] + q[1] * aq[1] + q[2] * aq[2])
    d = 0.25 * (a2 - b2)
    up = _so3_lin_c(1.0 - d, -1.0, 0.0, p, ap)
    uq = _so3_lin_c(1.0 + d, 1.0, 0.0, q, aq)
    return (up[0] + s * p[0], up[1] + s * p[1], up[2] + s * p[2], uq[0] + s * q[0], uq[1] + s * q[1],
            uq[2] + s * q[2])


def so4_split(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The self-dual and anti-self-dual parts of so(4): ``X = P(p) + Q(q)`` with ``[P, Q] = 0``.

    ``p = ½ (X01 + X23, X02 − X13, X03 + X12)``, ``q = ½ (X01 − X23, X02 + X13, X03 − X12)``
    (0-based): the isomorphism so(4) ≅ so(3) ⊕ so(3), with ``[X, Y] ↔ (−2 p × p', 2 q × q')`` and
    ``|X|²_F = 4 (|p|² + |q|²)``. The rotation angles of ``exp X`` are ``|p| ± |q|``.

    Parameters
    ----------
    X : ndarray, shape (..., 4, 4)
        Skew-symmetric (only the upper triangle is read).

    Returns
    -------
    p, q : ndarray, shape (..., 3)
    """
    p, q = _so4_pq_c(X)
    return _stack(p, (3,), X.shape[:-2]), _stack(q, (3,), X.shape[:-2])


def so4_join(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Inverse of :func:`so4_split`: ``Σ p_k S_k + Σ q_k A_k``, (..., 3), (..., 3) -> (..., 4, 4)."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    return _stack(_so4_mat_c((0.0, 1.0, 1.0, 0.0), _vec_c(p), _vec_c(q)), (4, 4), p.shape[:-1], q.shape[:-1])
