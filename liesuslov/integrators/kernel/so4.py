"""Kind 4 "so4": so(4) = so(3) ⊕ so(3) as the pair (p, q) — 6 numbers ``(p0, p1, p2, q0, q1, q2)`` — with the
closed forms of :mod:`liesuslov.groups.so4`, compiled as they stand (the layout and the maps of
:class:`~liesuslov.integrators.charts._So4Kernel`, so the numbers are the numpy solver's to rounding).

The groups functions are registered with :func:`numba.extending.register_jitable` below (here: ``groups``
does not import numba): jitted code calls the original function objects, and groups functions calling each
other compile through the same registration. Two do not compile — :func:`~liesuslov.groups.so4._so4_pq_c`
reads numpy arrays by ``X.size`` / ``X.item`` with a batch branch, and
:func:`~liesuslov.groups.dexp._dexpinv_so3_poly` walks a tuple with ``reversed`` (its coefficients come
from the cached, rational :func:`~liesuslov.groups.dexp._dexpinv_so3_series`): :func:`_so4_omega` (through
``_so4_pq_entries``) and the loop in :func:`_so4_dinv` are their scalar branches.

The operations (:func:`_so4_omega`, :func:`_so4_sq`, :func:`_so4_dinv`, :func:`_so4_rotate`, :func:`_so4_update`,
:func:`_so4_state`) implement the group part's operations of :mod:`.group` (``_omega_alg``, ``_alg_sq``,
``_alg_dinv``, ``_alg_act``, ``_alg_update``, ``_alg_state``) for kind 4, with only the arguments they read
(the closed-form family's dispatch in :mod:`.group` passes those): every value is a local scalar, and
``out`` is the only array written.
"""

from __future__ import annotations

from numba.extending import register_jitable

from ...groups import so3 as _g3
from ...groups import so4 as _g4
from .common import _jit, _jit_inline

# _so4_exp_coefficients compiles its float branch (numba prunes ``isinstance(a2, float)`` on a float64); the
# batch branch's _rodrigues_fast is registered so that the name types before the pruning — never run.
for _fn in (_g3._sq, _g3._so3_lin_c, _g3._rodrigues_fast, _g4._so4_pq_entries, _g4._so4_pv_c, _g4._so4_qv_c,
            _g4._cos_sinc, _g4._so4_exp_coefficients, _g4._so4_exp_apply_c, _g4._so4_cayley_coefficients,
            _g4._so4_lin_apply_c, _g4._so4_mat_c, _g4._so4_exp_mat_c, _g4._so4_dexpinv_c, _g4._so4_dcayinv_c):
    register_jitable(_fn)
del _fn

_so3_lin_c = _g3._so3_lin_c
_so4_cayley_coefficients = _g4._so4_cayley_coefficients
_so4_dcayinv_c = _g4._so4_dcayinv_c
_so4_dexpinv_c = _g4._so4_dexpinv_c
_so4_exp_apply_c = _g4._so4_exp_apply_c
_so4_exp_coefficients = _g4._so4_exp_coefficients
_so4_exp_mat_c = _g4._so4_exp_mat_c
_so4_lin_apply_c = _g4._so4_lin_apply_c
_so4_mat_c = _g4._so4_mat_c
_so4_pq_entries = _g4._so4_pq_entries


# ====================================================================================== the operations of kind 4
@_jit_inline
def _so4_omega(skew, x, widx, wval, Om, out):
    """out = (p, q) of Omega(x): the upper triangle of the probed map (rows ``(a, r, c)``, r < c) summed into
    the six entries ``(x01, x02, x03, x12, x13, x23)`` (in ``out`` itself: six scalars summed in branches
    inside the loop make numba's SSA pass warn once inlined), then the shared formula
    :func:`~liesuslov.groups.so4._so4_pq_entries`. Om is not used."""
    for i in range(6):
        out[i] = 0.0
    for t in range(wval.shape[0]):
        r, c = widx[t, 1], widx[t, 2]
        out[(r * (7 - r)) // 2 + c - r - 1] += wval[t] * x[widx[t, 0]]  # (r, c) -> its place in that order
    p, q = _so4_pq_entries(out[0], out[1], out[2], out[3], out[4], out[5])
    out[0] = p[0]
    out[1] = p[1]
    out[2] = p[2]
    out[3] = q[0]
    out[4] = q[1]
    out[5] = q[2]


@_jit
def _so4_sq(kind, Th, dom):
    """|Theta|_F^2 / 2 = 2 (|p|^2 + |q|^2): what the dense kind computes from the matrix."""
    acc = 0.0
    for i in range(6):
        acc += Th[i] * Th[i]
    return 2.0 * acc


@_jit_inline
def _so4_dinv(chart, Th, Om, h, out, row, bern):
    """out[row] = h dphi^{-1}_{-Th}(Om): exp the truncated series on each factor (the terms of ``bern``, rows
    ``(k, B_k/k!)`` for k >= 1), Cayley exact."""
    p = (Th[0], Th[1], Th[2])
    q = (Th[3], Th[4], Th[5])
    ap = (Om[0], Om[1], Om[2])
    aq = (Om[3], Om[4], Om[5])
    a2 = p[0] * p[0] + p[1] * p[1] + p[2] * p[2]
    b2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2]
    if chart == 0:
        # groups._dexpinv_so3_series and _dexpinv_so3_poly on floats: half = ½ if the k = 1 term is kept,
        # C(t) = Σ_j c_j t^{j-1}, c_j = (B_{2j}/(2j)!) (-1)^{j-1}, by Horner's rule from the top term
        half = 0.0
        tp = 4.0 * a2
        tq = 4.0 * b2
        cp = 0.0
        cq = 0.0
        for t in range(bern.shape[0] - 1, -1, -1):
            kk = int(bern[t, 0])
            if kk == 1:
                half = 0.5
            elif kk >= 2:
                c = bern[t, 1] * (1.0 if (kk // 2) % 2 == 1 else -1.0)
                cp = cp * tp + c
                cq = cq * tq + c
        vals = _so4_dexpinv_c(half, cp, cq, a2, b2, p, q, ap, aq)
    else:
        vals = _so4_dcayinv_c(a2, b2, p, q, ap, aq)
    out[row, 0] = h * vals[0]
    out[row, 1] = h * vals[1]
    out[row, 2] = h * vals[2]
    out[row, 3] = h * vals[3]
    out[row, 4] = h * vals[4]
    out[row, 5] = h * vals[5]


@_jit_inline
def _so4_rotate(chart, Th, sign, v, out):
    """out = phi(sign Th) v for a 4-vector v."""
    p = (Th[0], Th[1], Th[2])
    q = (Th[3], Th[4], Th[5])
    w = (v[0], v[1], v[2], v[3])
    if chart == 0:
        u = _so4_exp_apply_c(_so4_exp_coefficients(p, q), p, q, w, sign)
    else:
        u = _so4_lin_apply_c(_so4_cayley_coefficients(p, q), p, q, w, sign)
    out[0] = u[0]
    out[1] = u[1]
    out[2] = u[2]
    out[3] = u[3]


@_jit
def _mul_right(G, M, out):
    """out = G M, G stored flat row-major (16), M the 16 entries of a 4×4 matrix (a row-major tuple)."""
    m00, m01, m02, m03, m10, m11, m12, m13, m20, m21, m22, m23, m30, m31, m32, m33 = M
    for i in range(4):
        g0, g1, g2, g3 = G[4 * i], G[4 * i + 1], G[4 * i + 2], G[4 * i + 3]
        out[4 * i] = g0 * m00 + g1 * m10 + g2 * m20 + g3 * m30
        out[4 * i + 1] = g0 * m01 + g1 * m11 + g2 * m21 + g3 * m31
        out[4 * i + 2] = g0 * m02 + g1 * m12 + g2 * m22 + g3 * m32
        out[4 * i + 3] = g0 * m03 + g1 * m13 + g2 * m23 + g3 * m33


@_jit
def _so4_update(chart, mode, G, Th, out):
    """``g phi(Th)`` (mode g, g flat row-major) or ``phi(-Th) Gamma`` (mode gamma)."""
    if mode == 1:
        _so4_rotate(chart, Th, -1.0, G, out)
        return
    p = (Th[0], Th[1], Th[2])
    q = (Th[3], Th[4], Th[5])
    if chart == 0:
        M = _so4_exp_mat_c(_so4_exp_coefficients(p, q), p, q)
    else:
        M = _so4_mat_c(_so4_cayley_coefficients(p, q), p, q)
    _mul_right(G, M, out)


@_jit
def _so4_state(mode, G1, Ea, out):
    """``g1 E`` (mode g, 16 entries) or ``E Gamma1`` (mode gamma, 4), E the matrix of the pair Ea."""
    E = _so4_mat_c((0.0, 1.0, 1.0, 0.0), (Ea[0], Ea[1], Ea[2]), (Ea[3], Ea[4], Ea[5]))
    if mode != 1:
        _mul_right(G1, E, out)
        return
    e00, e01, e02, e03, e10, e11, e12, e13, e20, e21, e22, e23, e30, e31, e32, e33 = E
    v0, v1, v2, v3 = G1[0], G1[1], G1[2], G1[3]
    out[0] = e00 * v0 + e01 * v1 + e02 * v2 + e03 * v3
    out[1] = e10 * v0 + e11 * v1 + e12 * v2 + e13 * v3
    out[2] = e20 * v0 + e21 * v1 + e22 * v2 + e23 * v3
    out[3] = e30 * v0 + e31 * v1 + e32 * v2 + e33 * v3
