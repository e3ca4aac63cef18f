"""The model (the probed polynomial field) and the group part by kind (so3 rotation vectors, dense matrices,
the low-rank Fedorov–Kozlov basis, so4 pairs (p, q) in :mod:`.so4`): Omega, dphi⁻¹, the action on Gamma, the
update of g, the state error.

Each operation of the group part (``_omega_alg``, ``_alg_sq``, ``_alg_dinv``, ``_alg_act``, ``_alg_update``,
``_alg_state``) is a stub that only compiled code calls, with the *family* of the kinds as its first
argument, a numba literal (the loop is compiled once per family: :func:`.loop._solve_one` takes ``family``
as a literal, :data:`.common.FAMILIES`), and the kind itself as a run-time value. :func:`_by_kind`
registers, for each stub and family, a function with the stub's signature (inlined where the stub is
called) that branches on the kind and calls the kind's implementation — with every argument for the
matrix kinds, with only what they read for the closed forms: a family's loop therefore compiles its own
group code only — the closed-form loop (so3, so4) none of the matrix algorithms, the loop of a scene without
a group part (family 0) typed no-ops. Adding a kind is one
implementation per operation and one entry in each table at the end of this module.
"""

from __future__ import annotations

import math

from numba import types
from numba.extending import overload

from .common import _JIT_OPTIONS, _borrow, _jit, _jit_inline, _view
from .maps import _dexp3_coefficient, _mat_act, _mat_dinv, _mat_phi, _mm, _so3_coef
from .so4 import _so3_lin_c, _so4_dinv, _so4_omega, _so4_rotate, _so4_sq, _so4_state, _so4_update


# ====================================================================================== the model
@_jit_inline
def _field(x, Gam, has_gamma, fidx, fval, z, out, row):
    """out[row] = f(x, Gam): the probed polynomial (COO, see :class:`~.compiled.CompilePlan`); z scratch."""
    k = x.shape[0]
    for c in range(k):
        z[c] = x[c]
    if has_gamma:
        for c in range(Gam.shape[0]):
            z[k + c] = Gam[c]
    for c in range(out.shape[1]):
        out[row, c] = 0.0
    for t in range(fval.shape[0]):
        v = fval[t]
        i = fidx[t, 1]
        j = fidx[t, 2]
        if i >= 0:
            v = v * z[i]
        if j >= 0:
            v = v * z[j]
        out[row, fidx[t, 0]] += v


#: :func:`_field` as a function of its own, for the calls outside the stages (the start of a trajectory, the
#: first step): each inlined call site adds to the loop's compile time.
_field_call = _jit(_field.py_func)


# ====================================================================================== the stubs
# Layouts of an algebra element: so3 3 numbers (X21, X02, X10), dense m*m (row major), lowrank r*r (the
# coordinates in the step's basis Q), so4 6 numbers (p, q); see the package docstring.
def _omega_alg(family, kind, skew, x, widx, wval, Om, Q, nc, cvec, out):
    """out = Omega(x) in the kind's layout; returns the number of basis columns (low rank: adds column
    ``nc`` to Q, Gram–Schmidt twice; the other kinds return nc unchanged). Om (1, n): the low-rank kind's
    scratch row (the other kinds write out directly and leave it alone)."""


def _alg_sq(family, kind, Th, dom):
    """|Theta|_F^2 / 2 of the leading dom x dom block (the squared rotation angle on so(3)): the chart-domain
    test."""


def _alg_dinv(family, kind, chart, skew, Th, Om, h, out, row, Wf, bern, nc, r, bufs):
    """out[row] = h dphi^{-1}_{-Th}(Om) in the kind's layout (a row index, not a row view: a view costs two
    atomic reference-count updates per stage)."""


def _alg_act(family, kind, chart, skew, Th, sign, v, out, Wf, vbf, Q, nc, r, bufs):
    """out = phi(sign Th) v for a vector v (n,)."""


def _alg_update(family, kind, chart, skew, mode, G, Th, out, Wf, vbf, Q, nc, r, bufs, PQ, PQ2):
    """The group part moved by Th: ``g phi(Th)`` (mode g, G flat m*m) or ``phi(-Th) Gamma`` (mode gamma)."""


def _alg_state(family, kind, mode, G1, Ea, out, Q, nc, r, bufs, PQ, PQ2):
    """The chart increment Ea carried to the state: ``g1 E`` (mode g, m*m entries) or ``E Gamma1`` (mode
    gamma, n entries) — the error estimate of the group part, and (with Ea = Omega) its velocity."""


# A family's implementation of each operation: ``first`` when ``kind == first_kind``, ``other`` otherwise (a
# run-time branch between the family's two kinds). Written out per operation, not with *args: a tuple of
# arrays would be packed (and reference-counted) on every call. The arrays go in borrowed (common._borrow): a
# compiled function that calls others counts a reference to each of its array arguments, atomically, on entry
# and exit — unless the argument is borrowed.
def _omega_by(first_kind, first, other):
    def impl(family, kind, skew, x, widx, wval, Om, Q, nc, cvec, out):
        x, widx, wval, Om, Q, cvec, out = (_borrow(x), _borrow(widx), _borrow(wval), _borrow(Om), _borrow(Q),
                                           _borrow(cvec), _borrow(out))
        if kind == first_kind:
            return first(kind, skew, x, widx, wval, Om, Q, nc, cvec, out)
        return other(kind, skew, x, widx, wval, Om, Q, nc, cvec, out)
    return impl


def _sq_by(first_kind, first, other):
    def impl(family, kind, Th, dom):
        if kind == first_kind:
            return first(kind, Th, dom)
        return other(kind, Th, dom)
    return impl


def _dinv_by(first_kind, first, other):
    def impl(family, kind, chart, skew, Th, Om, h, out, row, Wf, bern, nc, r, bufs):
        Th, Om, out, Wf, bern, bufs = _borrow(Th), _borrow(Om), _borrow(out), _borrow(Wf), _borrow(bern), _borrow(bufs)
        if kind == first_kind:
            first(kind, chart, skew, Th, Om, h, out, row, Wf, bern, nc, r, bufs)
        else:
            other(kind, chart, skew, Th, Om, h, out, row, Wf, bern, nc, r, bufs)
    return impl


def _act_by(first_kind, first, other):
    def impl(family, kind, chart, skew, Th, sign, v, out, Wf, vbf, Q, nc, r, bufs):
        Th, v, out, Wf, vbf, Q, bufs = (_borrow(Th), _borrow(v), _borrow(out), _borrow(Wf), _borrow(vbf), _borrow(Q),
                                        _borrow(bufs))
        if kind == first_kind:
            first(kind, chart, skew, Th, sign, v, out, Wf, vbf, Q, nc, r, bufs)
        else:
            other(kind, chart, skew, Th, sign, v, out, Wf, vbf, Q, nc, r, bufs)
    return impl


def _update_by(first_kind, first, other):
    def impl(family, kind, chart, skew, mode, G, Th, out, Wf, vbf, Q, nc, r, bufs, PQ, PQ2):
        G, Th, out, Wf, vbf, Q, bufs, PQ, PQ2 = (_borrow(G), _borrow(Th), _borrow(out), _borrow(Wf), _borrow(vbf),
                                                 _borrow(Q), _borrow(bufs), _borrow(PQ), _borrow(PQ2))
        if kind == first_kind:
            first(kind, chart, skew, mode, G, Th, out, Wf, vbf, Q, nc, r, bufs, PQ, PQ2)
        else:
            other(kind, chart, skew, mode, G, Th, out, Wf, vbf, Q, nc, r, bufs, PQ, PQ2)
    return impl


def _state_by(first_kind, first, other):
    def impl(family, kind, mode, G1, Ea, out, Q, nc, r, bufs, PQ, PQ2):
        G1, Ea, out, Q, bufs, PQ, PQ2 = (_borrow(G1), _borrow(Ea), _borrow(out), _borrow(Q), _borrow(bufs),
                                         _borrow(PQ), _borrow(PQ2))
        if kind == first_kind:
            first(kind, mode, G1, Ea, out, Q, nc, r, bufs, PQ, PQ2)
        else:
            other(kind, mode, G1, Ea, out, Q, nc, r, bufs, PQ, PQ2)
    return impl


# The closed forms (family 1: so3 = kind 1, so4) take only what they read: every array passed to a call that
# LLVM does not inline is unpacked into its fields on the way (~10 ns a step per unused scratch array).
def _omega_closed(so3, so4):
    def impl(family, kind, skew, x, widx, wval, Om, Q, nc, cvec, out):
        if kind == 1:
            so3(skew, x, widx, wval, Om, out)
        else:
            so4(skew, x, widx, wval, Om, out)
        return nc
    return impl


def _dinv_closed(so3, so4):
    def impl(family, kind, chart, skew, Th, Om, h, out, row, Wf, bern, nc, r, bufs):
        if kind == 1:
            so3(chart, Th, Om, h, out, row)
        else:
            so4(chart, Th, Om, h, out, row, bern)
    return impl


def _act_closed(so3, so4):
    def impl(family, kind, chart, skew, Th, sign, v, out, Wf, vbf, Q, nc, r, bufs):
        Th, v, out = _borrow(Th), _borrow(v), _borrow(out)
        if kind == 1:
            so3(chart, Th, sign, v, out)
        else:
            so4(chart, Th, sign, v, out)
    return impl


def _update_closed(so3, so4):
    def impl(family, kind, chart, skew, mode, G, Th, out, Wf, vbf, Q, nc, r, bufs, PQ, PQ2):
        G, Th, out = _borrow(G), _borrow(Th), _borrow(out)
        if kind == 1:
            so3(chart, mode, G, Th, out)
        else:
            so4(chart, mode, G, Th, out)
    return impl


def _state_closed(so3, so4):
    def impl(family, kind, mode, G1, Ea, out, Q, nc, r, bufs, PQ, PQ2):
        G1, Ea, out = _borrow(G1), _borrow(Ea), _borrow(out)
        if kind == 1:
            so3(mode, G1, Ea, out)
        else:
            so4(mode, G1, Ea, out)
    return impl


# Family 0 (no group part: mode "none", the loop advances xi alone): the loop calls none of the operations
# at run time; these typed no-ops let its code compile without any group code.
def _omega_none(family, kind, skew, x, widx, wval, Om, Q, nc, cvec, out):
    return nc


def _sq_none(family, kind, Th, dom):
    return 0.0


def _dinv_none(family, kind, chart, skew, Th, Om, h, out, row, Wf, bern, nc, r, bufs):
    return None


def _act_none(family, kind, chart, skew, Th, sign, v, out, Wf, vbf, Q, nc, r, bufs):
    return None


def _update_none(family, kind, chart, skew, mode, G, Th, out, Wf, vbf, Q, nc, r, bufs, PQ, PQ2):
    return None


def _state_none(family, kind, mode, G1, Ea, out, Q, nc, r, bufs, PQ, PQ2):
    return None


def _by_kind(stub, table: dict) -> None:
    """Register ``stub``'s implementations: with a literal family f, ``table[f]``."""

    @overload(stub, prefer_literal=True, strict=False, inline="always", jit_options=_JIT_OPTIONS)
    def _typer(family, *args):
        if isinstance(family, types.IntegerLiteral) and family.literal_value in table:
            return table[family.literal_value]
        return None


# ====================================================================================== Omega(x)
@_jit
def _omega_matrix(skew, x, widx, wval, Om):
    """Om = Omega(x) as an (m, m) matrix from the probed linear map."""
    n = Om.shape[0]
    for i in range(n):
        for j in range(n):
            Om[i, j] = 0.0
    for t in range(wval.shape[0]):
        Om[widx[t, 1], widx[t, 2]] += wval[t] * x[widx[t, 0]]
    if skew:
        for i in range(n):
            for j in range(i + 1, n):
                Om[j, i] = -Om[i, j]


@_jit_inline
def _so3_omega(skew, x, widx, wval, Om, out):
    """out = (X21, X02, X10) of Omega(x), straight from the upper triangle of the probed map (rows (a, r, c),
    r < c): X01 = -X10, X02, X12 = -X21 (no matrix: Om is not used)."""
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0
    for t in range(wval.shape[0]):
        v = wval[t] * x[widx[t, 0]]
        if widx[t, 1] == 1:
            out[0] -= v
        elif widx[t, 2] == 2:
            out[1] += v
        else:
            out[2] -= v


@_jit
def _dense_omega(kind, skew, x, widx, wval, Om, Q, nc, cvec, out):
    n = int(math.sqrt(out.shape[0]) + 0.5)
    _omega_matrix(skew, x, widx, wval, _view(out, 0, (n, n)))  # out: the (n, n) matrix, row major
    return nc


@_jit
def _lowrank_omega(kind, skew, x, widx, wval, Om, Q, nc, cvec, out):
    n = Q.shape[0]
    r = Q.shape[1]
    u_n = n - 1
    for i in range(r):
        cvec[i] = 0.0
    w = Om[0]  # scratch row (n,)
    if nc == 1:
        acc = 0.0
        for p in range(u_n):
            w[p] = x[p]
            acc += x[p] * x[p]
        rho1 = math.sqrt(acc)
    else:
        for i in range(1, nc):
            acc = 0.0
            for p in range(u_n):
                acc += Q[p, i] * x[p]
            cvec[i] = acc
        acc = 0.0
        for p in range(u_n):
            v = x[p]
            for i in range(1, nc):
                v -= Q[p, i] * cvec[i]
            w[p] = v
            acc += v * v
        rho1 = math.sqrt(acc)
        for i in range(1, nc):  # second pass
            acc = 0.0
            for p in range(u_n):
                acc += Q[p, i] * w[p]
            cvec[i] += acc
            for p in range(u_n):
                w[p] -= Q[p, i] * acc
    acc = 0.0
    for p in range(u_n):
        acc += w[p] * w[p]
    rho = math.sqrt(acc)
    if rho > 0.5 * rho1:
        cvec[nc] = rho
        for p in range(u_n):
            Q[p, nc] = w[p] / rho
    for i in range(r * r):
        out[i] = 0.0
    for i in range(r):
        out[i * r] = cvec[i]
        out[i] = -cvec[i]
    out[0] = 0.0
    return nc + 1


# ====================================================================================== |Theta|^2 / 2
@_jit
def _so3_sq(kind, Th, dom):
    return Th[0] * Th[0] + Th[1] * Th[1] + Th[2] * Th[2]


@_jit
def _matrix_sq(kind, Th, dom):
    """Over the leading dom x dom block of the r x r matrix Th holds (flat): all of it but an affine algebra's
    translations (se(n): dom = r - 1)."""
    r = int(math.sqrt(Th.shape[0]) + 0.5)
    acc = 0.0
    for i in range(dom):
        for j in range(dom):
            acc += Th[i * r + j] * Th[i * r + j]
    return 0.5 * acc


# ====================================================================================== helpers of the matrix kinds
@_jit
def _block(Th, r, ra, buf):
    """The leading ra×ra block of the r×r matrix stored flat in Th, as a contiguous (ra, ra) matrix."""
    Mb = _view(buf, 0, (ra, ra))
    for i in range(ra):
        for j in range(ra):
            Mb[i, j] = Th[i * r + j]
    return Mb


@_jit
def _scratch(Wf, vbf, n):
    """W (12, n, n) and vb (n, 1): C-contiguous views of the flat scratch, sized for n×n matrices."""
    return _view(Wf, 0, (12, n, n)), _view(vbf, 0, (n, 1))


@_jit
def _basis_coordinates(Q, v, ra, y):
    """y = Q[:, :ra]^T v: a vector's coordinates in the step's basis."""
    n = Q.shape[0]
    for i in range(ra):
        acc = 0.0
        for p in range(n):
            acc += Q[p, i] * v[p]
        y[i] = acc


@_jit
def _from_basis(Q, z, ra, v, add_v, out):
    """out = (v if add_v else 0) + Q[:, :ra] z."""
    for p in range(Q.shape[0]):
        acc = v[p] if add_v else 0.0
        for i in range(ra):
            acc += Q[p, i] * z[i]
        out[p] = acc


@_jit
def _g_low_rank(Gm, Q, F, ra, PQ, PQ2, Om, add_g):
    """``Om = (g if add_g else 0) + g Q F Q^T`` for g (n, n), Q (n, >= ra), F (ra, ra): O(n^2 ra)."""
    n = Q.shape[0]
    P1 = PQ[:, :ra]
    P2 = PQ2[:, :ra]
    for i in range(n):
        for j in range(ra):
            P1[i, j] = 0.0
        for p in range(n):
            g = Gm[i, p]
            if g != 0.0:
                for j in range(ra):
                    P1[i, j] += g * Q[p, j]
        for j in range(ra):
            acc = 0.0
            for p in range(ra):
                acc += P1[i, p] * F[p, j]
            P2[i, j] = acc
        for j in range(n):
            acc = Gm[i, j] if add_g else 0.0
            for p in range(ra):
                acc += P2[i, p] * Q[j, p]
            Om[i, j] = acc


# ====================================================================================== h dphi^{-1}
@_jit_inline
def _so3_dinv(chart, Th, Om, h, out, row):
    t0, t1, t2_ = Th[0], Th[1], Th[2]
    a0, a1, a2 = Om[0], Om[1], Om[2]
    tt = t0 * t0 + t1 * t1 + t2_ * t2_
    if chart == 0:  # exact: (1 - c θ²) a + ½ θ × a + c (θ·a) θ
        c = _dexp3_coefficient(tt)
        cc, aa, bb = 1.0 - c * tt, 0.5, c
    else:  # exact: a + ½ θ × a + ¼ (θ·a) θ
        cc, aa, bb = 1.0, 0.5, 0.25
    d = bb * (t0 * a0 + t1 * a1 + t2_ * a2)
    out[row, 0] = h * (cc * a0 + aa * (t1 * a2 - t2_ * a1) + d * t0)
    out[row, 1] = h * (cc * a1 + aa * (t2_ * a0 - t0 * a2) + d * t1)
    out[row, 2] = h * (cc * a2 + aa * (t0 * a1 - t1 * a0) + d * t2_)


@_jit
def _dense_dinv(kind, chart, skew, Th, Om, h, out, row, Wf, bern, nc, r, bufs):
    n = int(math.sqrt(Th.shape[0]) + 0.5)
    W = _view(Wf, 0, (12, n, n))
    Rm = _view(out, row * out.shape[1], (n, n))  # the stage's row of out, as the n x n matrix it holds
    _mat_dinv(chart, skew, _view(Th, 0, (n, n)), _view(Om, 0, (n, n)), Rm, W, bern)
    for i in range(n):
        for j in range(n):
            Rm[i, j] *= h


@_jit
def _lowrank_dinv(kind, chart, skew, Th, Om, h, out, row, Wf, bern, nc, r, bufs):
    ra = nc
    W = _view(Wf, 0, (12, ra, ra))
    Tm = _block(Th, r, ra, _view(bufs, 0, bufs.shape[1]))
    Am = _block(Om, r, ra, _view(bufs, bufs.shape[1], bufs.shape[1]))
    Rm = _view(bufs, 2 * bufs.shape[1], (ra, ra))
    _mat_dinv(chart, skew, Tm, Am, Rm, W, bern)
    for i in range(r * r):
        out[row, i] = 0.0
    for i in range(ra):
        for j in range(ra):
            out[row, i * r + j] = h * Rm[i, j]


# ====================================================================================== phi(sign Th) v
# The so3 operations below are straight-line code on scalars (no matrix, no scratch, no loop in one branch
# only), on arrays borrowed from the family dispatch (numba counts no references to them). _so3_rotate runs in
# every stage and is inlined there at numba IR level; _so3_update runs once a step and stays a call (inlined,
# ~5% of an so(3) step for ~8 s more compile: kernel/__init__.py).
@_jit_inline
def _so3_rotate(chart, Th, sign, v, out):
    """out = phi(sign hat(Th)) v = c v + sign a Th × v + b (Th·v) Th."""
    w0, w1, w2 = Th[0], Th[1], Th[2]
    c, a, b = _so3_coef(chart, w0 * w0 + w1 * w1 + w2 * w2)
    out[0], out[1], out[2] = _so3_lin_c(c, sign * a, b, (w0, w1, w2), (v[0], v[1], v[2]))


@_jit
def _dense_act(kind, chart, skew, Th, sign, v, out, Wf, vbf, Q, nc, r, bufs):
    n = v.shape[0]
    W, vb = _scratch(Wf, vbf, n)
    _mat_act(chart, skew, _view(Th, 0, (n, n)), sign, v, out, W, vb)


@_jit
def _lowrank_act(kind, chart, skew, Th, sign, v, out, Wf, vbf, Q, nc, r, bufs):
    ra = nc
    W, vb = _scratch(Wf, vbf, ra)
    Mb = _block(Th, r, ra, _view(bufs, 0, bufs.shape[1]))
    y = _view(bufs, bufs.shape[1], ra)
    z = _view(bufs, 2 * bufs.shape[1], ra)
    _basis_coordinates(Q, v, ra, y)
    _mat_act(chart, skew, Mb, sign, y, z, W, vb)
    for i in range(ra):
        z[i] -= y[i]
    _from_basis(Q, z, ra, v, True, out)


# ====================================================================================== g phi(Th) or phi(-Th) Gamma
@_jit
def _so3_update(chart, mode, G, Th, out):
    """``phi(-Th) Gamma`` (mode gamma) or ``g phi(Th)`` (mode g) row by row: row i of g R is R^T g_i =
    phi(-Th) g_i, since R^T = phi(-Th) (no matrix R, no scratch)."""
    w0, w1, w2 = Th[0], Th[1], Th[2]
    c, a, b = _so3_coef(chart, w0 * w0 + w1 * w1 + w2 * w2)
    w = (w0, w1, w2)
    out[0], out[1], out[2] = _so3_lin_c(c, -a, b, w, (G[0], G[1], G[2]))
    if mode != 1:
        out[3], out[4], out[5] = _so3_lin_c(c, -a, b, w, (G[3], G[4], G[5]))
        out[6], out[7], out[8] = _so3_lin_c(c, -a, b, w, (G[6], G[7], G[8]))


@_jit
def _dense_update(kind, chart, skew, mode, G, Th, out, Wf, vbf, Q, nc, r, bufs, PQ, PQ2):
    if mode == 1:
        _dense_act(kind, chart, skew, Th, -1.0, G, out, Wf, vbf, Q, nc, r, bufs)
        return
    n = int(math.sqrt(G.shape[0]) + 0.5)
    W = _view(Wf, 0, (12, n, n))
    R = W[10]
    _mat_phi(chart, skew, _view(Th, 0, (n, n)), R, W)
    _mm(_view(G, 0, (n, n)), R, _view(out, 0, (n, n)))


@_jit
def _lowrank_update(kind, chart, skew, mode, G, Th, out, Wf, vbf, Q, nc, r, bufs, PQ, PQ2):
    if mode == 1:
        _lowrank_act(kind, chart, skew, Th, -1.0, G, out, Wf, vbf, Q, nc, r, bufs)
        return
    # g + (g Q) (phi(M) - I) Q^T
    n = Q.shape[0]
    ra = nc
    W = _view(Wf, 0, (12, ra, ra))
    Mb = _block(Th, r, ra, _view(bufs, 0, bufs.shape[1]))
    F = _view(bufs, bufs.shape[1], (ra, ra))
    _mat_phi(chart, skew, Mb, F, W)
    for i in range(ra):
        F[i, i] -= 1.0
    _g_low_rank(_view(G, 0, (n, n)), Q, F, ra, PQ, PQ2, _view(out, 0, (n, n)), True)


# ====================================================================================== the state's error
@_jit
def _so3_state(mode, G1, Ea, out):
    """``hat(e) Gamma1 = e × Gamma1`` (mode gamma) or ``g1 hat(e)``, whose row i is ``g1_i × e`` (mode g)."""
    e = (Ea[0], Ea[1], Ea[2])
    if mode == 1:  # (the cross product as groups' c v + a w × v + b (w·v) w with c = b = 0, a = 1)
        out[0], out[1], out[2] = _so3_lin_c(0.0, 1.0, 0.0, e, (G1[0], G1[1], G1[2]))
    else:
        out[0], out[1], out[2] = _so3_lin_c(0.0, 1.0, 0.0, (G1[0], G1[1], G1[2]), e)
        out[3], out[4], out[5] = _so3_lin_c(0.0, 1.0, 0.0, (G1[3], G1[4], G1[5]), e)
        out[6], out[7], out[8] = _so3_lin_c(0.0, 1.0, 0.0, (G1[6], G1[7], G1[8]), e)


@_jit
def _dense_state(kind, mode, G1, Ea, out, Q, nc, r, bufs, PQ, PQ2):
    if mode == 1:
        n = G1.shape[0]
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += Ea[i * n + j] * G1[j]
            out[i] = acc
        return
    n = int(math.sqrt(G1.shape[0]) + 0.5)
    _mm(_view(G1, 0, (n, n)), _view(Ea, 0, (n, n)), _view(out, 0, (n, n)))


@_jit
def _lowrank_state(kind, mode, G1, Ea, out, Q, nc, r, bufs, PQ, PQ2):
    n = Q.shape[0]
    ra = nc
    Eb = _block(Ea, r, ra, _view(bufs, 0, bufs.shape[1]))
    if mode == 1:
        y = _view(bufs, bufs.shape[1], ra)
        z = _view(bufs, 2 * bufs.shape[1], ra)
        _basis_coordinates(Q, G1, ra, y)
        for i in range(ra):
            acc = 0.0
            for j in range(ra):
                acc += Eb[i, j] * y[j]
            z[i] = acc
        _from_basis(Q, z, ra, G1, False, out)
        return
    _g_low_rank(_view(G1, 0, (n, n)), Q, Eb, ra, PQ, PQ2, _view(out, 0, (n, n)), False)


# ============================================================================ the tables (codes: common.KINDS)
# family 0: no group part (mode "none"); family 1 (closed forms): so3, so4; family 2 (matrices): dense, lowrank
_by_kind(_omega_alg, {0: _omega_none, 1: _omega_closed(_so3_omega, _so4_omega),
                      2: _omega_by(2, _dense_omega, _lowrank_omega)})
_by_kind(_alg_sq, {0: _sq_none, 1: _sq_by(1, _so3_sq, _so4_sq), 2: _sq_by(2, _matrix_sq, _matrix_sq)})
_by_kind(_alg_dinv, {0: _dinv_none, 1: _dinv_closed(_so3_dinv, _so4_dinv), 2: _dinv_by(2, _dense_dinv, _lowrank_dinv)})
_by_kind(_alg_act, {0: _act_none, 1: _act_closed(_so3_rotate, _so4_rotate), 2: _act_by(2, _dense_act, _lowrank_act)})
_by_kind(_alg_update, {0: _update_none, 1: _update_closed(_so3_update, _so4_update),
                       2: _update_by(2, _dense_update, _lowrank_update)})
_by_kind(_alg_state, {0: _state_none, 1: _state_closed(_so3_state, _so4_state),
                      2: _state_by(2, _dense_state, _lowrank_state)})
