"""One trajectory's whole solve (stages, controller, output, events, failures, re-projection), compiled;
the batch's chunks of trajectories are spread over threads by :func:`~.wrapper._solve_batch`."""

from __future__ import annotations

import math

import numba  # (ImportError without numba: the front door then runs numpy)
import numpy as np

from .common import (
    _F_ATOL,
    _F_DOMAIN,
    _F_EXPO,
    _F_H,
    _F_RTOL,
    _F_T0,
    _F_T1,
    _FHEAD,
    _I_A,
    _I_ADAPT,
    _I_CHART,
    _I_DOM,
    _I_FSAL,
    _I_HASG,
    _I_K,
    _I_KIND,
    _I_M,
    _I_MAXST,
    _I_MODE,
    _I_NB,
    _I_NE,
    _I_NEV,
    _I_NEWIN,
    _I_NF,
    _I_NW,
    _I_ORDER,
    _I_P,
    _I_Q,
    _I_R,
    _I_RECORD,
    _I_RENORM,
    _I_REPROJ,
    _I_S,
    _I_SKEW,
    _I_SS,
    _NHEAD,
    _accept_factor,
    _borrow,
    _bracket_closed,
    _closest_end,
    _combine,
    _crossed,
    _fixed_steps,
    _illinois_update,
    _initial_step,
    _jit,
    _jit_entry,
    _on_surface_at_start,
    _probe_step,
    _reject_factor,
    _scale,
    _secant_point,
    _step_floor,
    _underflow,
    _view,
)
from .group import _alg_act, _alg_dinv, _alg_sq, _alg_state, _alg_update, _field, _field_call, _omega_alg
from .maps import _polar_step


# ====================================================================================== one trajectory
@_jit
def _finite(x):
    """Every entry of x is finite (the start of a trajectory; each step folds its test into its own loops)."""
    for i in range(x.shape[0]):
        if not np.isfinite(x[i]):
            return False
    return True


@_jit
def _dense_at(th, dense, wts, xi, hL, hK, xit, Tht):
    """The continuous extension at theta: weights b(theta) (Horner, as ``plan.dense_weights``), then
    ``xit = xi + sum_j b_j hL_j`` and ``Tht = sum_j b_j hK_j``."""
    S = dense.shape[0]
    P = dense.shape[1]
    for j in range(S):
        accw = dense[j, P - 1] * th
        for qq in range(P - 2, -1, -1):
            accw = (accw + dense[j, qq]) * th
        wts[j] = accw
    for c in range(xit.shape[0]):
        acc = 0.0
        for j in range(S):
            acc += wts[j] * hL[j, c]
        xit[c] = xi[c] + acc
    for c in range(Tht.shape[0]):
        acc = 0.0
        for j in range(S):
            acc += wts[j] * hK[j, c]
        Tht[c] = acc


@_jit
def _body_vertical(mode, G, gam, out):
    """The vertical in the body frame: ``g^T gamma`` (mode g) or Gamma itself."""
    n = out.shape[0]
    if mode == 2:
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += G[j * n + i] * gam[j]
            out[i] = acc
    else:
        for i in range(n):
            out[i] = G[i]


@_jit
def _fresh_basis(Q):
    """A new step's low-rank basis: column 0 stays e_n, the others are rebuilt stage by stage (Q has no rows
    for the other kinds)."""
    for p in range(Q.shape[0] - 1):
        for j in range(1, Q.shape[1]):
            Q[p, j] = 0.0


@_jit
def _event_values(bi, ev_coef, ev_off, xi, G, out):
    """The linear event functions at the state (xi, G): ``coef . (xi, G) - offset``."""
    k = xi.shape[0]
    for e in range(out.shape[0]):
        acc = -ev_off[bi, e]
        for c in range(k):
            acc += ev_coef[bi, e, c] * xi[c]
        for c in range(G.shape[0]):
            acc += ev_coef[bi, e, k + c] * G[c]
        out[e] = acc


@_jit
def _event_start(bi, ev_coef, ev_off, xi, G, out):
    """At t0: a value within its rounding of 0 is 0 (:func:`~liesuslov.integrators.control.on_surface_at_start`)."""
    k = xi.shape[0]
    for e in range(out.shape[0]):
        mag = abs(ev_off[bi, e])
        for c in range(k):
            mag += abs(ev_coef[bi, e, c] * xi[c])
        for c in range(G.shape[0]):
            mag += abs(ev_coef[bi, e, k + c] * G[c])
        out[e] = _on_surface_at_start(out[e], mag, k + G.shape[0])


@_jit
def _crossings(gold, gnew, ev_dir, act_e):
    """The events the step crossed (:func:`~liesuslov.integrators.control.crossed`), in ``act_e``; their count."""
    n_act = 0
    for e in range(gold.shape[0]):
        if _crossed(gold[e], gnew[e], ev_dir[e]):
            act_e[n_act] = e
            n_act += 1
    return n_act


@_jit
def _state_at(family, kind, chart, skew, mode, th, dense, wts, xi, G, hL, hK, xit, Tht, Gt, W, vb, Q, nc, r, bufs,
              PQ, PQ2):
    """The state at theta of the step on the continuous extension: ``xit`` and ``Gt`` (g phi(Theta(theta))
    or phi(-Theta(theta)) Gamma)."""
    _dense_at(th, dense, wts, xi, hL, hK, xit, Tht)
    if mode != 0:
        _alg_update(family, kind, chart, skew, mode, G, Tht, Gt, W, vb, Q, nc, r, bufs, PQ, PQ2)


@_jit
def _error_norm(family, kind, mode, err, s_eval, rtol, atol, xi, xi1, G, G1, hL, hK, Ea, Eg, Q, nc, r, bufs, PQ, PQ2):
    """The trial step's error norm (:mod:`.control`): the embedded estimates ``sum_j err[e, j] (hL_j, hK_j)``
    carried to the state (``_alg_state``), scaled like scipy's, combined over the estimators."""
    k = xi.shape[0]
    q = G.shape[0]
    a = Ea.shape[0]
    ne = err.shape[0]
    s5 = 0.0
    s3 = 0.0
    for e in range(ne):
        acc2 = 0.0
        for c in range(k):
            acc = 0.0
            for j in range(s_eval):
                acc += err[e, j] * hL[j, c]
            v = acc / _scale(xi[c], xi1[c], rtol, atol)
            acc2 += v * v
        if mode != 0:
            for c in range(a):
                acc = 0.0
                for j in range(s_eval):
                    acc += err[e, j] * hK[j, c]
                Ea[c] = acc
            _alg_state(family, kind, mode, G1, Ea, Eg, Q, nc, r, bufs, PQ, PQ2)
            for c in range(q):
                v = Eg[c] / _scale(G[c], G1[c], rtol, atol)
                acc2 += v * v
        if e == 0:
            s5 = acc2
        else:
            s3 = acc2
    return _combine(s5, s3, k + q, ne == 2)


@_jit
def _group_velocity(family, kind, skew, mode, x, G, widx, wval, Om, Q, cvec, Oa, Eg, r, bufs, PQ, PQ2):
    """Eg = Omega(x) carried to the state G (``g Omega`` or ``Omega Gamma``, :func:`.group._alg_state`): the
    group part's velocity, up to the sign of mode gamma (one function, so the first step inlines the group code
    once, not twice)."""
    _fresh_basis(Q)
    nc = _omega_alg(family, kind, skew, x, widx, wval, Om, Q, np.int64(1), cvec, Oa)
    _alg_state(family, kind, mode, G, Oa, Eg, Q, nc, r, bufs, PQ, PQ2)


@_jit
def _first_step(family, kind, skew, mode, has_g, order, direction, rtol, atol, xi, G, gam, F, xit, Gt, Gam, z, fidx,
                fval, widx, wval, Om, Q, cvec, Oa, Eg, r, bufs, PQ, PQ2, sc_y, f_y):
    """Hairer's starting step (as scipy's) on the embedded state y = (xi, G), f = (xi_dot, group velocity);
    ``F[0]`` holds the field at the start, ``F[1]`` gets the probe's (one evaluation). NaN if it breaks down."""
    k = xi.shape[0]
    q = G.shape[0]
    N = k + q
    if mode != 0:
        _group_velocity(family, kind, skew, mode, xi, G, widx, wval, Om, Q, cvec, Oa, Eg, r, bufs, PQ, PQ2)
    for c in range(k):
        sc_y[c] = _scale(xi[c], xi[c], rtol, atol)
        f_y[c] = F[0, c]
    for c in range(q):
        sc_y[k + c] = _scale(G[c], G[c], rtol, atol)
        f_y[k + c] = -Eg[c] if mode == 1 else Eg[c]
    d0 = 0.0
    d1 = 0.0
    for c in range(k):
        d0 += (xi[c] / sc_y[c]) ** 2
    for c in range(q):
        d0 += (G[c] / sc_y[k + c]) ** 2
    for c in range(N):
        d1 += (f_y[c] / sc_y[c]) ** 2
    d0 = math.sqrt(d0 / N)
    d1 = math.sqrt(d1 / N)
    h0 = _probe_step(d0, d1)
    hp = h0 * direction
    for c in range(k):
        xit[c] = xi[c] + hp * f_y[c]
    for c in range(q):
        Gt[c] = G[c] + hp * f_y[k + c]
    if has_g:
        _body_vertical(mode, Gt, gam, Gam)
    _field_call(xit, Gam, has_g, fidx, fval, z, F, np.int64(1))
    if mode != 0:
        _group_velocity(family, kind, skew, mode, xit, Gt, widx, wval, Om, Q, cvec, Oa, Eg, r, bufs, PQ, PQ2)
    d2 = 0.0
    for c in range(k):
        d2 += ((F[1, c] - f_y[c]) / sc_y[c]) ** 2
    for c in range(q):
        v = -Eg[c] if mode == 1 else Eg[c]
        d2 += ((v - f_y[k + c]) / sc_y[k + c]) ** 2
    d2 = math.sqrt(d2 / N) / h0
    return _initial_step(d0, d1, d2, h0, order) * direction


@_jit
def _locate(family, kind, chart, skew, mode, bi, n_act, act_e, act_th, gold, gnew, ev_needG, ev_coef, ev_off, ev_term,
            cap, ev_count, ev_t, ev_xi, ev_G, t, h, t_new, direction, dense, wts, xi, G, xi1, G1, hL, hK, xit, Tht, Gt,
            W, vb, Q, nc, r, bufs, PQ, PQ2):
    """Locate the crossings of the step (Illinois on theta in [0, 1] on the continuous extension, to a few
    ulps of t) and record them in time order, up to the first terminal one.

    Returns ``(terminal, t_stop)``: whether a terminal event stopped the trajectory, and its time."""
    k = xi.shape[0]
    q = G.shape[0]
    for ia in range(n_act):
        e = act_e[ia]
        lo = 0.0
        hi = 1.0
        flo = gold[e]
        fhi = gnew[e]
        vlo = flo
        vhi = fhi
        side = 0
        root = 1.0 if fhi == 0.0 else -1.0  # (a step that starts at 0 is not a crossing)
        for _it in range(300):
            if root >= 0.0:
                break
            cth = _secant_point(lo, hi, flo, fhi)
            if cth <= lo or cth >= hi:
                break
            # the value at cth, on the continuous extension (the group part only when the event reads it)
            _dense_at(cth, dense, wts, xi, hL, hK, xit, Tht)
            fc = -ev_off[bi, e]
            for c in range(k):
                fc += ev_coef[bi, e, c] * xit[c]
            if ev_needG[e]:
                _alg_update(family, kind, chart, skew, mode, G, Tht, Gt, W, vb, Q, nc, r, bufs, PQ, PQ2)
                for c in range(q):
                    fc += ev_coef[bi, e, k + c] * Gt[c]
            if fc == 0.0:
                root = cth
                break
            lo, hi, flo, fhi, vlo, vhi, side = _illinois_update(lo, hi, flo, fhi, vlo, vhi, side, cth, fc)
            if _bracket_closed(t, h, lo, hi, cth, direction):
                break
        if root < 0.0:
            root = _closest_end(lo, hi, vlo, vhi)
        act_th[ia] = root
    # insertion sort by theta (ties: event order)
    for ia in range(1, n_act):
        j = ia
        while j > 0 and act_th[j - 1] > act_th[j]:
            tmp = act_th[j - 1]
            act_th[j - 1] = act_th[j]
            act_th[j] = tmp
            tmpe = act_e[j - 1]
            act_e[j - 1] = act_e[j]
            act_e[j] = tmpe
            j -= 1
    terminal = False
    t_stop = t_new
    stop_th = 2.0
    for ia in range(n_act):
        e = act_e[ia]
        th_ = act_th[ia]
        if terminal and th_ > stop_th:
            break
        te = t_new if th_ == 1.0 else t + th_ * h
        if th_ == 1.0:
            for c in range(k):
                xit[c] = xi1[c]
            for c in range(q):
                Gt[c] = G1[c]
        else:
            _state_at(family, kind, chart, skew, mode, th_, dense, wts, xi, G, hL, hK, xit, Tht, Gt, W, vb, Q, nc, r,
                      bufs, PQ, PQ2)
        cnt = ev_count[bi, e]
        if cnt < cap:
            ev_t[bi, e, cnt] = te
            for c in range(k):
                ev_xi[bi, e, cnt, c] = xit[c]
            for c in range(q):
                ev_G[bi, e, cnt, c] = Gt[c]
        ev_count[bi, e] = cnt + 1
        if cnt + 1 == ev_term[e] and not terminal:  # its N-th crossing (ev_term 0: never)
            terminal = True
            t_stop = te
            stop_th = th_
    return terminal, t_stop


@_jit
def _outputs(family, kind, chart, skew, mode, bi, ie, t_eval, t_lim, t, h, t_new, direction, dense, wts, xi, G, xi1, G1,
             hL, hK, xit, Tht, Gt, W, vb, Q, nc, r, bufs, PQ, PQ2, xi_out, G_out):
    """Write the output times up to ``t_lim`` inside the accepted step (the continuous extension; the step's
    end exactly); returns the next output index."""
    k = xi.shape[0]
    q = G.shape[0]
    NT = t_eval.shape[0]
    while ie < NT and direction * (t_eval[ie] - t_lim) <= 0.0:
        te = t_eval[ie]
        if te == t_new:
            for c in range(k):
                xi_out[ie, bi, c] = xi1[c]
            for c in range(q):
                G_out[ie, bi, c] = G1[c]
        else:
            _state_at(family, kind, chart, skew, mode, (te - t) / h, dense, wts, xi, G, hL, hK, xit, Tht, Gt, W, vb,
                      Q, nc, r, bufs, PQ, PQ2)
            for c in range(k):
                xi_out[ie, bi, c] = xit[c]
            if mode != 0:
                for c in range(q):
                    G_out[ie, bi, c] = Gt[c]
        ie += 1
    return ie


@_jit
def _record(t_rec, xi_rec, G_rec, n, t, xi, G):
    """Row ``n`` of the every-step record: ``t_rec[n] = t``, ``xi_rec[n] = xi``, ``G_rec[n] = G``, the storage
    doubled first when full; returns the (possibly new) three arrays. Element loops, not slice assignments:
    those compile numba's shape-mismatch message (string formatting, ~5 s of a cold compile)."""
    if n == t_rec.shape[0]:
        cap = 2 * n
        t2, x2, g2 = np.zeros(cap), np.zeros((cap, xi_rec.shape[1])), np.zeros((cap, G_rec.shape[1]))
        for i in range(n):
            t2[i] = t_rec[i]
            for c in range(x2.shape[1]):
                x2[i, c] = xi_rec[i, c]
            for c in range(g2.shape[1]):
                g2[i, c] = G_rec[i, c]
        t_rec, xi_rec, G_rec = t2, x2, g2
    t_rec[n] = t
    for c in range(xi.shape[0]):
        xi_rec[n, c] = xi[c]
    for c in range(G.shape[0]):
        G_rec[n, c] = G[c]
    return t_rec, xi_rec, G_rec


@_jit
def _reproject(mode, G, Wg):
    """Back onto the group: one Newton–Schulz step for g (mode g), |Gamma| = 1 (mode gamma)."""
    if mode == 2:
        m = Wg.shape[1]
        _polar_step(_view(G, 0, (m, m)), Wg[0], Wg[1])
    elif mode == 1:
        acc = 0.0
        for c in range(G.shape[0]):
            acc += G[c] * G[c]
        nr = math.sqrt(acc)
        for c in range(G.shape[0]):
            G[c] = G[c] / nr


@_jit
def _keepalive(owners):
    """Nothing: a use of ``owners`` at the end of :func:`_solve_one`, so that numba keeps them (the memory of the
    loop's borrowed views) alive until then."""


@_jit_entry
def _solve_one(family, lo, hi, iprm, fprm, xi0, G0, gamma, t_eval, ev_coef, ev_off, cap, xi_out, G_out, status, t_stop,
               failure, nfev_o, steps_o, rejected_o, ev_count, ev_t, ev_xi, ev_G):
    """Integrate trajectories ``lo .. hi-1`` one after the other (see the module docstring); returns the
    recorded steps of the last one (record mode, a single trajectory).

    ``family`` (:data:`~.common.FAMILIES`) is a compile-time literal: each family of kinds compiles its own
    loop, with only its own group code (:mod:`.group`); the kind within it is a run-time value."""
    numba.literally(family)
    kind = iprm[_I_KIND]
    k = iprm[_I_K]
    m = iprm[_I_M]
    q = iprm[_I_Q]
    mode = iprm[_I_MODE]
    chart = iprm[_I_CHART]
    skew = iprm[_I_SKEW] != 0
    has_g = iprm[_I_HASG] != 0
    s = iprm[_I_S]
    S = iprm[_I_SS]
    ne = iprm[_I_NE]
    P = iprm[_I_P]
    fsal = iprm[_I_FSAL] != 0
    new_in = iprm[_I_NEWIN] != 0
    adaptive = iprm[_I_ADAPT] != 0
    max_steps = iprm[_I_MAXST]
    reproj = iprm[_I_REPROJ] != 0 and (skew or mode == 1)
    renorm = iprm[_I_RENORM]
    nb = iprm[_I_NB]
    nf = iprm[_I_NF]
    nw = iprm[_I_NW]
    E = iprm[_I_NEV]
    order = iprm[_I_ORDER]
    record = iprm[_I_RECORD] != 0
    r = iprm[_I_R]
    a = iprm[_I_A]
    dom = iprm[_I_DOM]
    o = _NHEAD
    fidx = _view(iprm, o, (nf, 3))
    o += 3 * nf
    widx = _view(iprm, o, (nw, 3))
    o += 3 * nw
    ev_term = _view(iprm, o, E)
    ev_dir = _view(iprm, o + E, E)
    t0 = fprm[_F_T0]
    t1 = fprm[_F_T1]
    hfix = fprm[_F_H]
    rtol = fprm[_F_RTOL]
    atol = fprm[_F_ATOL]
    expo = fprm[_F_EXPO]
    o = _FHEAD
    A = _view(fprm, o, (S, S))
    o += S * S
    bw = _view(fprm, o, S)
    o += S
    err = _view(fprm, o, (ne, S))
    o += ne * S
    dense = _view(fprm, o, (S, P))
    o += S * P
    bern = _view(fprm, o, (nb, 2))
    o += 2 * nb
    fval = _view(fprm, o, nf)
    o += nf
    wval = _view(fprm, o, nw)
    direction = 1.0 if t1 > t0 else -1.0
    s_eval = s + (1 if new_in else 0)
    # np.int64(1), not 1: numba compiles a separate specialisation for a literal argument
    i0 = np.int64(0)
    i1 = np.int64(1)
    # the chart's domain, a bound on |Theta|_F^2 / 2 of the leading dom x dom block (charts.domain_bound2 / 2,
    # charts.domain_block)
    bound2 = fprm[_F_DOMAIN]
    # scratch (once per call; each trajectory overwrites what it reads)
    n = m if has_g else 0
    mm = 3 if kind == 1 else (m if kind == 2 else r)
    F = np.zeros((S, k))
    hL = np.zeros((S, k))
    hK = np.zeros((S, a))
    xi = np.zeros(k)
    G = np.zeros(q)
    xi1 = np.zeros(k)
    G1 = np.zeros(q)
    Th = np.zeros(a)
    Th1 = np.zeros(a)
    Oa = np.zeros(a)
    Ea = np.zeros(a)
    Eg = np.zeros(q)
    Xi = np.zeros(k)
    Gam0 = np.zeros(n)
    Gam = np.zeros(n)
    z = np.zeros(k + n)
    Om = np.zeros((1 if kind == 3 else 0, m))  # the low-rank kind's scratch row (see group._omega_alg)
    W = np.zeros(12 * mm * mm)  # flat: viewed as (12, n, n) for the size at hand (group._scratch)
    vb = np.zeros(mm)
    bufs = np.zeros((3, max(mm * mm, 1)))
    Q = np.zeros((m if kind == 3 else 0, r))
    cvec = np.zeros(r)
    PQ = np.zeros((m if kind == 3 else 0, r))
    PQ2 = np.zeros((m if kind == 3 else 0, r))
    Wg = np.zeros((2, m if (mode == 2 and reproj) else 0, m if (mode == 2 and reproj) else 0))
    wts = np.zeros(S)
    xit = np.zeros(k)
    Gt = np.zeros(q)
    Tht = np.zeros(a)
    gold = np.zeros(E)
    gnew = np.zeros(E)
    ev_needG = np.zeros(E, np.bool_)
    act_th = np.zeros(E)
    act_e = np.zeros(E, np.int64)
    sc_y = np.zeros(k + q)
    f_y = np.zeros(k + q)
    # The loop works on borrowed views (common._view) of its scratch and arguments: no reference counting
    # in the step. The scratch's owners live in `owners` to the end of the call (_keepalive): numba releases
    # a variable after its last use, which would free the memory under a borrowed view.
    owners = (F, hL, hK, xi, G, xi1, G1, Th, Th1, Oa, Ea, Eg, Xi, Gam0, Gam, z, Om, W, vb, bufs, Q, cvec, PQ,
              PQ2, Wg, wts, xit, Gt, Tht, gold, gnew, ev_needG, act_th, act_e, sc_y, f_y)
    F, hL, hK, xi, G, xi1, G1 = _borrow(F), _borrow(hL), _borrow(hK), _borrow(xi), _borrow(G), _borrow(xi1), _borrow(G1)
    Th, Th1, Oa, Ea, Eg, Xi = _borrow(Th), _borrow(Th1), _borrow(Oa), _borrow(Ea), _borrow(Eg), _borrow(Xi)
    Gam0, Gam, z, Om, W, vb = _borrow(Gam0), _borrow(Gam), _borrow(z), _borrow(Om), _borrow(W), _borrow(vb)
    bufs, Q, cvec, PQ, PQ2, Wg = _borrow(bufs), _borrow(Q), _borrow(cvec), _borrow(PQ), _borrow(PQ2), _borrow(Wg)
    wts, xit, Gt, Tht, gold, gnew = _borrow(wts), _borrow(xit), _borrow(Gt), _borrow(Tht), _borrow(gold), _borrow(gnew)
    ev_needG, act_th, act_e, sc_y, f_y = _borrow(ev_needG), _borrow(act_th), _borrow(act_e), _borrow(sc_y), _borrow(f_y)
    xi0, G0, gamma, t_eval, ev_coef = _borrow(xi0), _borrow(G0), _borrow(gamma), _borrow(t_eval), _borrow(ev_coef)
    ev_off, xi_out, G_out, status = _borrow(ev_off), _borrow(xi_out), _borrow(G_out), _borrow(status)
    t_stop, failure, nfev_o, steps_o = _borrow(t_stop), _borrow(failure), _borrow(nfev_o), _borrow(steps_o)
    rejected_o, ev_count, ev_t, ev_xi = _borrow(rejected_o), _borrow(ev_count), _borrow(ev_t), _borrow(ev_xi)
    ev_G = _borrow(ev_G)
    rec_n = 0
    t_rec = np.zeros(0)
    xi_rec = np.zeros((0, k))
    G_rec = np.zeros((0, q))
    for bi in range(lo, hi):
        if kind == 3:
            for p in range(m):
                for j in range(r):
                    Q[p, j] = 0.0
            Q[m - 1, 0] = 1.0
        for c in range(k):
            xi[c] = xi0[bi, c]
        for c in range(q):
            G[c] = G0[bi, c]
        gam = _view(gamma, bi * gamma.shape[1], gamma.shape[1])
        rec_n = 0
        if record:  # (a single trajectory; a batch keeps the empty ones: no allocation per trajectory)
            t_rec = np.zeros(64)
            xi_rec = np.zeros((64, k))
            G_rec = np.zeros((64, q))
        for e in range(E):
            ev_needG[e] = False
            for c in range(q):
                if ev_coef[bi, e, k + c] != 0.0:
                    ev_needG[e] = True

        nfev = 0
        nsteps = 0
        nrej = 0
        st = 0
        fail = 0
        tst = t0
        t = t0
        ie = 0
        NT = t_eval.shape[0]
        if has_g:
            _body_vertical(mode, G, gam, Gam0)
        _field_call(xi, Gam0, has_g, fidx, fval, z, F, i0)
        nfev += 1
        f0_ok = True
        # the initial state is reported even when the field fails there (NaN only after the failure time)
        while ie < NT and t_eval[ie] == t0:
            for c in range(k):
                xi_out[ie, bi, c] = xi[c]
            for c in range(q):
                G_out[ie, bi, c] = G[c]
            ie += 1
        if record:
            # rec_n (0 here), not a literal 0: numba would compile _record a second time for it
            t_rec, xi_rec, G_rec = _record(t_rec, xi_rec, G_rec, rec_n, t0, xi, G)
            rec_n = 1
        if not (_finite(F[0]) and _finite(xi) and _finite(G)):
            fail = 1
        _event_values(bi, ev_coef, ev_off, xi, G, gold)
        _event_start(bi, ev_coef, ev_off, xi, G, gold)
        h = hfix * direction
        if fail == 0 and adaptive and hfix == 0.0:
            h = _first_step(family, kind, skew, mode, has_g, order, direction, rtol, atol, xi, G, gam, F, xit, Gt, Gam,
                            z, fidx, fval, widx, wval, Om, Q, cvec, Oa, Eg, r, bufs, PQ, PQ2, sc_y, f_y)
            nfev += 1  # (a step of 0, when the norms overflowed: the step-size floor below fails the run here)

        # ---------------------------------------------------------------- the time loop
        after_reject = False
        nonfinite_trial = False  # the last trial step, inside the chart's domain, met a non-finite value
        nc = i1
        if not adaptive and not hfix >= _step_floor(t0, t1):  # below the resolution of t: the grid is not t0 + i h
            fail = 5
        n_fixed = 0
        if not adaptive and fail == 0:
            n_fixed = _fixed_steps(abs(t1 - t0), hfix, max_steps + 1)
        t_fail = t0
        while fail == 0 and t1 != t0:
            if nsteps + nrej >= max_steps:
                fail = 3
                break
            if adaptive:
                if _underflow(h, t, direction):
                    fail = 6 if nonfinite_trial else 2
                    break
                last = abs(h) >= abs(t1 - t)
                if last:
                    h = t1 - t
            else:
                last = nsteps + 1 >= n_fixed
                h = (t1 if last else t0 + direction * hfix * (nsteps + 1)) - t
            # stage 0 (kept across rejections: the field value; the chart part is rescaled)
            if has_g:
                _body_vertical(mode, G, gam, Gam0)
            if not f0_ok:
                _field(xi, Gam0, has_g, fidx, fval, z, F, 0)
                nfev += 1
                f0_ok = True
            for c in range(k):
                hL[0, c] = h * F[0, c]
            if kind == 3:
                _fresh_basis(Q)
            nc = i1
            if mode != 0:
                nc = _omega_alg(family, kind, skew, xi, widx, wval, Om, Q, nc, cvec, Oa)
                for c in range(a):
                    hK[0, c] = h * Oa[c]
            # Stages 1 .. s_eval-1 of the trial step and, for an accepted step whose interior is asked for, the
            # extension's s .. S-1: one loop in this function, not a call per step (a call passes ~30 arrays,
            # each reference-counted on the way in and out: ~0.5 µs a step on so(3), half the step).
            ok = True
            nrm = 0.0
            i = i1
            i_hi = s_eval
            extended = False
            rejected_now = False
            n_act = 0
            t_new = t
            while True:
                while i < i_hi:
                    for c in range(k):
                        acc = 0.0
                        for j in range(i):
                            acc += A[i, j] * hL[j, c]
                        Xi[c] = xi[c] + acc
                    if mode != 0:
                        for c in range(a):
                            acc = 0.0
                            for j in range(i):
                                acc += A[i, j] * hK[j, c]
                            Th[c] = acc
                        if not extended and _alg_sq(family, kind, Th, dom) >= bound2:  # (NaN: the field's failure)
                            ok = False
                        if has_g:
                            if extended and i == s:
                                # the field at the new point, reused as the next stage 0: it reads the end
                                # state's vertical (g1^T gamma), as that stage 0 would (bitwise), not the chart's
                                _body_vertical(mode, G1, gam, Gam)
                            else:
                                _alg_act(family, kind, chart, skew, Th, -1.0, Gam0, Gam, W, vb, Q, nc, r, bufs)
                    _field(Xi, Gam, has_g, fidx, fval, z, F, i)
                    nfev += 1
                    for c in range(k):
                        hL[i, c] = h * F[i, c]
                    if mode != 0:
                        nc = _omega_alg(family, kind, skew, Xi, widx, wval, Om, Q, nc, cvec, Oa)
                        _alg_dinv(family, kind, chart, skew, Th, Oa, h, hK, i, W, bern, nc, r, bufs)
                    i += 1
                if extended:
                    break
                # ------------------------------------------------ the trial step's end and its error
                # finite: 0 * v is 0 for a finite v, NaN otherwise (the test folded into the loops over the state)
                chk = 0.0
                for c in range(k):
                    acc = 0.0
                    for j in range(s):
                        acc += bw[j] * hL[j, c]
                    xi1[c] = xi[c] + acc
                    chk += 0.0 * xi1[c]
                if mode != 0:
                    for c in range(a):
                        acc = 0.0
                        for j in range(s):
                            acc += bw[j] * hK[j, c]
                        Th1[c] = acc
                    if _alg_sq(family, kind, Th1, dom) >= bound2:
                        ok = False
                    _alg_update(family, kind, chart, skew, mode, G, Th1, G1, W, vb, Q, nc, r, bufs, PQ, PQ2)
                    for c in range(q):
                        chk += 0.0 * G1[c]
                finite = chk == 0.0
                if adaptive:
                    nrm = _error_norm(family, kind, mode, err, s_eval, rtol, atol, xi, xi1, G, G1, hL, hK, Ea, Eg, Q,
                                      nc, r, bufs, PQ, PQ2)
                    nonfinite_trial = ok and not finite
                    if not (ok and finite):
                        nrm = np.inf
                    if not (nrm <= 1.0):
                        rejected_now = True
                        break
                else:
                    if not ok:  # first: a step beyond the chart's domain may also end non-finite
                        fail = 4
                        t_fail = t
                        break
                    if not finite:  # the field broke down
                        fail = 1
                        t_fail = t + h
                        break
                # ------------------------------------------------ accepted: does its interior matter?
                t_new = t1 if last else t + h
                if E > 0:
                    _event_values(bi, ev_coef, ev_off, xi1, G1, gnew)
                    n_act = _crossings(gold, gnew, ev_dir, act_e)
                if n_act > 0 or (ie < NT and direction * (t_eval[ie] - t_new) < 0.0):
                    # an output time inside the step (one at t_new is the step's end itself) or a crossing:
                    # the continuous extension, stage s (a copy for FSAL methods) and the extra stages
                    extended = True
                    i = s
                    if fsal:
                        for c in range(k):
                            F[s, c] = F[s - 1, c]
                            hL[s, c] = hL[s - 1, c]
                        for c in range(a):
                            hK[s, c] = hK[s - 1, c]
                        i = s + 1
                    elif new_in:
                        i = s + 1
                    i_hi = S
                    continue
                break
            if fail != 0:
                break
            if rejected_now:
                nrej += 1
                h = h * _reject_factor(nrm, expo)
                after_reject = True
                continue
            nsteps += 1
            have_new = extended or fsal or new_in  # stage s is available
            # ---------------------------------------------------- events, in time order
            if n_act > 0:
                terminal, t_ev = _locate(family, kind, chart, skew, mode, bi, n_act, act_e, act_th, gold, gnew,
                                         ev_needG, ev_coef, ev_off, ev_term, cap, ev_count, ev_t, ev_xi, ev_G, t, h,
                                         t_new, direction, dense, wts, xi, G, xi1, G1, hL, hK, xit, Tht, Gt, W, vb, Q,
                                         nc, r, bufs, PQ, PQ2)
                if terminal:
                    st = 1
                    tst = t_ev
            # ---------------------------------------------------- outputs (t_eval, record)
            t_lim = tst if st == 1 else t_new
            # called only when an output time falls in the step: the call passes ~35 arrays
            if ie < NT and direction * (t_eval[ie] - t_lim) <= 0.0:
                ie = _outputs(family, kind, chart, skew, mode, bi, ie, t_eval, t_lim, t, h, t_new,
                              direction, dense, wts, xi, G, xi1, G1, hL, hK, xit, Tht, Gt, W, vb, Q, nc, r, bufs, PQ,
                              PQ2, xi_out, G_out)
            if st == 1:
                break
            # ---------------------------------------------------- advance
            t = t_new
            for c in range(k):
                xi[c] = xi1[c]
            for c in range(q):
                G[c] = G1[c]
            for e in range(E):
                gold[e] = gnew[e]
            if have_new:
                for c in range(k):
                    F[0, c] = F[s - 1, c] if fsal else F[s, c]
                f0_ok = True
            else:
                f0_ok = False
            if record:  # the step's own end, as an output time there gets it (before any re-projection)
                t_rec, xi_rec, G_rec = _record(t_rec, xi_rec, G_rec, rec_n, t, xi, G)
                rec_n += 1
            if reproj and mode != 0 and nsteps % renorm == 0:
                f0_ok = False  # the state moved: stage 0 is evaluated again
                _reproject(mode, G, Wg)
            if adaptive:
                h = h * _accept_factor(nrm, expo, after_reject)
                after_reject = False
            if last:
                tst = t1
                break
        if fail != 0:
            st = -1
            tst = t_fail if fail == 1 else t
        status[bi] = st
        t_stop[bi] = tst
        failure[bi] = fail
        nfev_o[bi] = nfev
        steps_o[bi] = nsteps
        rejected_o[bi] = nrej
    _keepalive(owners)
    return t_rec[:rec_n].copy(), xi_rec[:rec_n].copy(), G_rec[:rec_n].copy()
