"""The whole solve compiled (numba), one trajectory at a time: :func:`solve` takes a :class:`~.problem.Problem`.

Per trajectory, inside one jitted function (no Python per step, no allocation per step): the RKMK stages of
the method's :class:`~.plan.StagePlan`, the step-size controller and the error norm of :mod:`.control`
(those very functions, compiled by numba), the continuous extension for ``t_eval`` and events, event
location by a bracketing root finder (Illinois), re-projection, failures with their time and code. A batch
runs in contiguous chunks on threads (the jitted loop releases the GIL; no parfor, so one function to
compile); a trajectory's numbers do not depend on its batch mates or the chunking (no reduction across
trajectories, the same code path for B = 1 and B > 1).

Cost (measured on the 2-core machine under load, 2026-11-24): the first compiled call on an empty cache
compiles one specialisation (~66 s CPU under load; the one int64 and one float64 parameter array carry
every scene, so no other scene compiles again); later processes load it from the cache (< 1 s). RKMK4 with
reconstruction, h = 0.005: so(3) ~1.4 µs per step (~5x a plain loop hard-coded for that method: the
kernel's loops run over run-time sizes — k, stages, layouts — that the plain loop has as constants), a
batch of 10^4 ~0.7 µs per trajectory-step on both cores; so(4) (dense kind) ~4.8 µs per step;
Fedorov–Kozlov SO(256) (low-rank kind) ~0.55 ms per step.

What is compiled
----------------
* the field: :func:`~.compiled.compile_plan` probes ``model.xi_dot`` as a verified polynomial of degree <= 2
  in ``(xi, Gamma)`` (sparse COO lists) and ``Omega(xi)`` as a linear map;
* the group part in one of the kinds of :func:`kind_for`:

  - ``"so3"``: rotation vectors, closed forms (Rodrigues, the exact so(3) dexp⁻¹ and Cayley maps);
  - ``"dense"``: m×m matrices — so(n) (skew brackets, Padé scaling and squaring with the skew norm bound
    and a Newton–Schulz polish, Cayley by LU) or a general matrix algebra (se(2), se(3): full brackets,
    Padé with the 1-norm, Cayley by LU); dexp⁻¹ is the series ``Σ_{k < p-1} (B_k/k!) ad^k`` with the
    sign of the right side (:func:`liesuslov.groups.dexpinv_terms` terms);
  - ``"lowrank"``: Fedorov–Kozlov models (``Omega = u e_n^T - e_n u^T``): stage values ``Q M Q^T`` in a
    per-step orthonormal basis Q (n × r, r <= S + 1) built stage by stage by Gram–Schmidt (twice), as
    :class:`~.charts._LowRankKernel`: O(n r + r³) per stage, O(n² r) per step.

Layouts of an algebra element (a stage's ``h K_j``): so3 3 numbers ``(X21, X02, X10)``, dense m² (row
major), lowrank r² (the r×r coordinates M in the step's basis).

Shared closed forms: ``groups._cayley_coefficients`` and ``groups._dexp3_series`` are jitted as they stand;
``groups._rodrigues`` and ``groups._dexp3_coefficient`` branch on ``isinstance`` (numpy arrays or floats)
and cannot be compiled: :func:`_rodrigues` and :func:`_dexp3_coefficient` below are their scalar branches.

Importing this module imports numba; ``import liesuslov`` does not import it.
"""

from __future__ import annotations

import math
import os

import numba  # (ImportError without numba: the front door then runs numpy)
import numpy as np
from numba import njit

from .. import groups
from . import control
from .compiled import (  # noqa: F401  (re-exported: the front door reads them from here)
    CompilePlan,
    NotCompilable,
    compile_plan,
    numba_available,
)
from .problem import FAILURES, RENORM_EVERY, Problem, RawResult  # noqa: F401

__all__ = ["solve", "check", "kind_for", "NotCompilable", "KINDS", "LOWRANK_MIN_N"]

KINDS = {None: 0, "so3": 1, "dense": 2, "lowrank": 3}
MODES = {"none": 0, "gamma": 1, "g": 2}
CHARTS = {"exp": 0, "cayley": 1, None: 0}
#: Fedorov–Kozlov models from this n on run the low-rank kind (below, dense m×m work is as cheap).
LOWRANK_MIN_N = 8
#: First capacity of the per-(trajectory, event) crossing storage (the wrapper re-runs with more if needed).
EVENT_CAP = 16


def _jit(fn):
    if njit is None:
        return fn
    return njit(cache=True, nogil=True, error_model="numpy")(fn)


def _share(fn):
    """A scalar formula of :mod:`control` or :mod:`liesuslov.groups`, compiled as it stands."""
    if njit is None:
        return fn
    return njit(cache=True, nogil=True, error_model="numpy")(fn)


_scale = _share(control.scale)
_combine = _share(control.combine)
_accept_factor = _share(control.accept_factor)
_reject_factor = _share(control.reject_factor)
_initial_step = _share(control.initial_step)
_probe_step = _share(control.probe_step)
_cayley_coefficients = _share(groups._cayley_coefficients)
_dexp3_series = _share(groups._dexp3_series)


# ====================================================================================== choosing the kind
def kind_for(model, mode: str, chart: str | None) -> str | None:
    """The group representation the kernel uses for ``model`` in ``mode`` (None for mode "none").

    "so3" on so(3); "lowrank" for Fedorov–Kozlov models with n >= :data:`LOWRANK_MIN_N`; "dense" otherwise
    (so(n), and general matrix algebras such as se(2), se(3)). so(4) runs as "dense".
    """
    if mode == "none":
        return None
    name = getattr(getattr(model, "algebra", None), "name", "")
    n = getattr(model, "n", None)
    if name == "so(3)":
        return "so3"
    if name.startswith("so(") and getattr(model, "fedorov_kozlov", False) and n is not None and n >= LOWRANK_MIN_N:
        return "lowrank"
    return "dense"


# ====================================================================================== the wrapper
def check(problem: Problem) -> None:
    """Raise :class:`NotCompilable` with the reason when ``problem`` cannot run on the compiled kernel."""
    _prepare(problem)


def _prepare(problem: Problem):
    if njit is None:
        raise NotCompilable("numba is not installed (pip install 'liesuslov[fast]')")
    if problem.events and problem.event_coef is None:
        raise NotCompilable("an event is a user callable (not a LinearEvent): events are located on numpy")
    mode = problem.mode
    kind = problem.kind if mode != "none" else None
    if kind == "so4":
        kind = "dense"
    if kind not in KINDS:
        raise NotCompilable(f"the compiled kernel knows the kinds {sorted(k for k in KINDS if k)}, got {kind!r}")
    if mode != "none" and problem.chart not in ("exp", "cayley"):
        raise NotCompilable(f"the compiled kernel knows the charts exp and cayley, got {problem.chart!r}")
    if kind in ("so3", "lowrank") and not problem.skew:
        raise NotCompilable(f"the {kind!r} kind needs so(n)")
    if kind == "so3" and problem.m != 3:
        raise NotCompilable(f"the 'so3' kind needs 3×3 matrices, got m = {problem.m}")
    cplan = compile_plan(problem.model, mode, problem.chart, skew=problem.skew, omega=kind != "lowrank")
    if kind == "lowrank":
        _check_fedorov_kozlov(problem.model)
    return kind, cplan


def _check_fedorov_kozlov(model) -> None:
    n, k = int(model.n), int(model.k)
    if not getattr(model, "fedorov_kozlov", False) or k != n - 1:
        raise NotCompilable("the 'lowrank' kind needs a Fedorov–Kozlov model (Omega = u e_n^T - e_n u^T)")
    x = np.random.default_rng(3).standard_normal((2, k))
    Om = np.asarray(model.omega_matrix(x), dtype=float)
    ref = np.zeros((2, n, n))
    ref[:, :k, k] = x
    ref[:, k, :k] = -x
    if Om.shape != ref.shape or not np.array_equal(Om, ref):
        raise NotCompilable("model.omega_matrix is not u e_n^T - e_n u^T: the 'lowrank' kind cannot run it")


# Layout of the packed integer parameters
(_I_K, _I_M, _I_Q, _I_MODE, _I_CHART, _I_KIND, _I_SKEW, _I_HASG, _I_S, _I_SS, _I_NE, _I_P, _I_FSAL, _I_NEWIN,
 _I_ADAPT, _I_MAXST, _I_REPROJ, _I_RENORM, _I_NB, _I_NF, _I_NW, _I_NEV, _I_ORDER, _I_RECORD, _I_R, _I_A,
 _I_NT) = range(27)
_NHEAD = 27
_F_T0, _F_T1, _F_H, _F_RTOL, _F_ATOL, _F_EXPO = range(6)
_FHEAD = 6


def _pack(problem: Problem, kind: str | None, cplan: CompilePlan, record: bool):
    plan = problem.plan
    mode = MODES[problem.mode]
    k, m, q = int(problem.k), int(problem.m), int(problem.q)
    S, s = plan.S, plan.s
    r = S + 1 if kind == "lowrank" else 0
    a = {None: 0, "so3": 3, "dense": m * m, "lowrank": r * r}[kind]
    terms = groups.bernoulli_coefficients(groups.dexpinv_terms(plan.order))[1:]
    bern = np.array(terms, dtype=float).reshape(-1, 2)
    E = 0 if problem.event_coef is None else int(problem.event_coef.shape[1])
    nt = 0 if problem.t_eval is None else int(len(problem.t_eval))
    head = np.zeros(_NHEAD, dtype=np.int64)
    head[:] = (k, m, q, mode, CHARTS[problem.chart if mode else None], KINDS[kind], int(problem.skew),
               int(bool(cplan.has_gamma) and mode != 0), s, S, plan.err.shape[0], plan.dense.shape[1],
               int(plan.fsal), int(plan.new_in_step), int(problem.adaptive), int(problem.max_steps),
               int(problem.reproject), max(RENORM_EVERY, m), bern.shape[0], cplan.field_value.size,
               cplan.omega_value.size, E, int(plan.order), int(record), r, a, nt)
    term = np.zeros(E, np.int64) if E == 0 else np.asarray(problem.event_terminal, np.int64).reshape(E)
    dirn = np.zeros(E, np.int64) if E == 0 else np.asarray(problem.event_direction, np.int64).reshape(E)
    iprm = np.concatenate([head, cplan.field_index.ravel(), cplan.omega_index.ravel(), term, dirn]).astype(np.int64)
    fhead = np.array([problem.t0, problem.t1, abs(float(problem.h)), problem.rtol, problem.atol,
                      plan.error_exponent], dtype=float)
    fprm = np.concatenate([fhead, plan.A.ravel(), plan.b.ravel(), plan.err.ravel(), plan.dense.ravel(),
                           bern.ravel(), cplan.field_value, cplan.omega_value]).astype(float)
    return np.ascontiguousarray(iprm), np.ascontiguousarray(fprm)


def solve(problem: Problem) -> RawResult:
    """Integrate ``problem`` on the compiled kernel (see the module docstring); ``RawResult.backend == "numba"``."""
    kind, cplan = _prepare(problem)
    B, k, q = int(problem.B), int(problem.k), int(problem.q)
    record = problem.t_eval is None
    if record and B != 1:
        raise ValueError("t_eval=None (record every step) needs a single trajectory")
    iprm, fprm = _pack(problem, kind, cplan, record)
    xi0 = np.ascontiguousarray(problem.xi0, dtype=float).reshape(B, k)
    G0 = np.ascontiguousarray(problem.G0, dtype=float).reshape(B, q)
    gamma = np.ascontiguousarray(problem.gamma, dtype=float).reshape(B, -1)
    t_eval = np.zeros(0) if record else np.ascontiguousarray(problem.t_eval, dtype=float)
    E = int(iprm[_I_NEV])
    if E:
        ev_coef = np.ascontiguousarray(problem.event_coef, dtype=float).reshape(B, E, k + q)
        ev_off = np.ascontiguousarray(problem.event_offset, dtype=float).reshape(B, E)
    else:
        ev_coef, ev_off = np.zeros((B, 0, k + q)), np.zeros((B, 0))
    cap = EVENT_CAP if E else 0
    while True:
        M = 0 if record else t_eval.shape[0]
        xi_out = np.full((M, B, k), np.nan)
        G_out = np.full((M, B, q), np.nan)
        status = np.zeros(B, np.int64)
        t_stop = np.zeros(B)
        failure = np.zeros(B, np.int64)
        nfev = np.zeros(B, np.int64)
        steps = np.zeros(B, np.int64)
        rejected = np.zeros(B, np.int64)
        ev_count = np.zeros((B, E), np.int64)
        ev_t = np.zeros((B, E, cap))
        ev_xi = np.zeros((B, E, cap, k))
        ev_G = np.zeros((B, E, cap, q))
        args = (iprm, fprm, xi0, G0, gamma, t_eval, ev_coef, ev_off, cap, xi_out, G_out, status, t_stop,
                failure, nfev, steps, rejected, ev_count, ev_t, ev_xi, ev_G)
        if record:
            t_rec, xi_rec, G_rec = _solve_one(0, 1, *args)
        else:
            _solve_batch(*args)
        top = int(ev_count.max(initial=0))
        if top <= cap:
            break
        cap = top  # deterministic: the same run again with room for every crossing
    if record:
        t_out, xi_out, G_out = t_rec, xi_rec[:, None, :], G_rec[:, None, :]
    else:
        t_out = t_eval.copy()
    ev_lists = ([], [], [], [])
    for e in range(E):
        cnt = ev_count[:, e]
        idx = np.repeat(np.arange(B, dtype=np.int64), cnt)
        sel = np.concatenate([np.arange(c) for c in cnt]) if B else np.zeros(0, np.int64)
        sel = sel.astype(np.int64)
        ev_lists[0].append(ev_t[idx, e, sel])
        ev_lists[1].append(idx)
        ev_lists[2].append(ev_xi[idx, e, sel].reshape(idx.size, k))
        ev_lists[3].append(ev_G[idx, e, sel].reshape(idx.size, q))
    return RawResult(t=t_out, xi=xi_out, G=G_out, status=status, t_stop=t_stop, failure=failure, nfev=nfev,
                     steps=steps, rejected=rejected, event_t=ev_lists[0], event_index=ev_lists[1],
                     event_xi=ev_lists[2], event_G=ev_lists[3], backend="numba")


# ====================================================================================== small linear algebra
def _pade_table() -> tuple[np.ndarray, np.ndarray]:
    """Bounds theta_m (Higham 2005, Table 2.3, m = 3, 5, 7, 9, 13) and the [m/m] Padé numerator coefficients."""
    thetas = np.array([t for _, t in groups._PADE_THETA])
    coef = np.zeros((5, 14))
    for r, (m, _) in enumerate(groups._PADE_THETA):
        coef[r, :m + 1] = groups._pade_coefficients(m)
    return thetas, coef


_PADE_THETA, _PADE_COEF = _pade_table()
# Beyond this |X|_2 bound the Cayley solve gets a polar step; beyond _CAYLEY_MAX it returns NaN (see compiled.py)
_CAYLEY_POLAR = 2.0
_CAYLEY_MAX = 6.7e7
_PI2 = math.pi * math.pi


@_jit
def _mm(A, B, C):
    """C = A @ B (C distinct from A and B)."""
    n = A.shape[0]
    p_ = A.shape[1]
    w = B.shape[1]
    for i in range(n):
        for j in range(w):
            C[i, j] = 0.0
        for p in range(p_):
            a = A[i, p]
            if a != 0.0:
                for j in range(w):
                    C[i, j] += a * B[p, j]


@_jit
def _set_eye(out, d):
    n = out.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] = 0.0
        out[i, i] = d


@_jit
def _axpy(out, a, A):
    n = out.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] += a * A[i, j]


@_jit
def _solve(A, X):
    """Solve A Y = X in place by LU with partial pivoting: A (n, n) destroyed, X (n, r) becomes Y."""
    n = A.shape[0]
    r = X.shape[1]
    for c in range(n):
        p = c
        big = abs(A[c, c])
        for i in range(c + 1, n):
            v = abs(A[i, c])
            if v > big:
                big = v
                p = i
        if p != c:
            for j in range(n):
                t = A[c, j]
                A[c, j] = A[p, j]
                A[p, j] = t
            for j in range(r):
                t = X[c, j]
                X[c, j] = X[p, j]
                X[p, j] = t
        d = A[c, c]
        for i in range(c + 1, n):
            f = A[i, c] / d
            if f != 0.0:
                for j in range(c + 1, n):
                    A[i, j] -= f * A[c, j]
                for j in range(r):
                    X[i, j] -= f * X[c, j]
    for i in range(n - 1, -1, -1):
        for j in range(r):
            acc = X[i, j]
            for p in range(i + 1, n):
                acc -= A[i, p] * X[p, j]
            X[i, j] = acc / A[i, i]


@_jit
def _polar_step(R, T, P):
    """R <- R (3 I - R^T R) / 2: one Newton–Schulz step toward the nearest orthogonal matrix (T, P scratch)."""
    n = R.shape[0]
    for i in range(n):
        for j in range(n):
            acc = 0.0
            for p in range(n):
                acc += R[p, i] * R[p, j]
            T[i, j] = -0.5 * acc
        T[i, i] += 1.5
    _mm(R, T, P)
    for i in range(n):
        for j in range(n):
            R[i, j] = P[i, j]


@_jit
def _bracket(skew, A, B, C):
    """C = [A, B] = A B - B A (skew A, B: upper triangle of A B - (A B)^T, exactly skew)."""
    n = A.shape[0]
    if skew:
        for i in range(n):
            C[i, i] = 0.0
            for j in range(i + 1, n):
                acc = 0.0
                for p in range(n):
                    acc += A[i, p] * B[p, j] - A[j, p] * B[p, i]
                C[i, j] = acc
                C[j, i] = -acc
        return
    for i in range(n):
        for j in range(n):
            acc = 0.0
            for p in range(n):
                acc += A[i, p] * B[p, j] - B[i, p] * A[p, j]
            C[i, j] = acc


# ---------------------------------------------------------------------- so(3) closed forms (scalar branches)
@_jit
def _rodrigues(t2):
    """(cos θ, sin θ/θ, (1 - cos θ)/θ²) from θ², by the half angle: the scalar branch of ``groups._rodrigues``."""
    x2 = 0.25 * t2
    x = math.sqrt(x2)
    if x < groups._SINC_TAYLOR:
        s = 1.0 - x2 * (1.0 / 6.0 - x2 / 120.0)
    else:
        s = math.sin(x) / x
    b = 0.5 * s * s
    return 1.0 - b * t2, s * math.cos(x), b


@_jit
def _dexp3_coefficient(t2):
    """(1 - (θ/2) cot(θ/2)) / θ²: the scalar branch of ``groups._dexp3_coefficient``."""
    if t2 < groups._DEXP3_TAYLOR ** 2:
        return _dexp3_series(t2)
    x = 0.5 * math.sqrt(t2)
    return (1.0 - x * math.cos(x) / math.sin(x)) / t2


@_jit
def _so3_coef(chart, t2):
    """(c, a, b) with phi(hat w) = c I + a hat(w) + b w w^T."""
    if chart == 0:
        return _rodrigues(t2)
    return _cayley_coefficients(t2)


# ---------------------------------------------------------------------- matrix charts (dense and low-rank)
@_jit
def _pade(X, r, W):
    """Odd and even parts U -> W[5], V -> W[6] of the Padé numerator of degree (3, 5, 7, 9, 13)[r]."""
    b = _PADE_COEF[r]
    X2, X4, X6, X8, T, U, V = W[0], W[1], W[2], W[3], W[4], W[5], W[6]
    _mm(X, X, X2)
    if r == 0:
        _set_eye(T, b[1])
        _axpy(T, b[3], X2)
        _set_eye(V, b[0])
        _axpy(V, b[2], X2)
    elif r < 4:
        _mm(X2, X2, X4)
        if r >= 2:
            _mm(X4, X2, X6)
        if r == 3:
            _mm(X6, X2, X8)
        _set_eye(T, b[1])
        _axpy(T, b[3], X2)
        _axpy(T, b[5], X4)
        _set_eye(V, b[0])
        _axpy(V, b[2], X2)
        _axpy(V, b[4], X4)
        if r >= 2:
            _axpy(T, b[7], X6)
            _axpy(V, b[6], X6)
        if r == 3:
            _axpy(T, b[9], X8)
            _axpy(V, b[8], X8)
    else:  # degree 13, Higham's form with 6 products
        _mm(X2, X2, X4)
        _mm(X4, X2, X6)
        _set_eye(T, 0.0)
        _axpy(T, b[13], X6)
        _axpy(T, b[11], X4)
        _axpy(T, b[9], X2)
        _mm(X6, T, X8)
        _set_eye(T, b[1])
        _axpy(T, 1.0, X8)
        _axpy(T, b[7], X6)
        _axpy(T, b[5], X4)
        _axpy(T, b[3], X2)
        _mm(X, T, U)
        _set_eye(T, 0.0)
        _axpy(T, b[12], X6)
        _axpy(T, b[10], X4)
        _axpy(T, b[8], X2)
        _mm(X6, T, V)
        _axpy(V, b[6], X6)
        _axpy(V, b[4], X4)
        _axpy(V, b[2], X2)
        for i in range(X.shape[0]):
            V[i, i] += b[0]
        return
    _mm(X, T, U)


@_jit
def _expm(skew, X, out, W):
    """out = exp(X): scaling and squaring with Padé (Higham 2005); skew X: the 2-norm bound |X|_F/√2 and a
    Newton–Schulz polish after the squarings (orthogonal to rounding); general X: the 1-norm. W[0..8]."""
    n = X.shape[0]
    if skew:
        acc = 0.0
        for i in range(n):
            for j in range(n):
                acc += X[i, j] * X[i, j]
        nrm = math.sqrt(0.5 * acc)
    else:
        nrm = 0.0
        for j in range(n):
            acc = 0.0
            for i in range(n):
                acc += abs(X[i, j])
            if acc > nrm or acc != acc:
                nrm = acc
    r = 4
    for q in range(4):
        if nrm <= _PADE_THETA[q]:
            r = q
            break
    s = 0
    if r == 4 and nrm == nrm and nrm < np.inf:
        e = math.frexp(nrm / _PADE_THETA[4])[1]
        s = e if e > 0 else 0
    Xs = W[7]
    sc = 2.0 ** (-s)
    for i in range(n):
        for j in range(n):
            Xs[i, j] = X[i, j] * sc
    _pade(Xs, r, W)
    A, U, V = W[4], W[5], W[6]
    for i in range(n):
        for j in range(n):
            A[i, j] = V[i, j] - U[i, j]
            out[i, j] = V[i, j] + U[i, j]
    _solve(A, out)
    T = W[8]
    for q in range(s):
        _mm(out, out, T)
        for i in range(n):
            for j in range(n):
                out[i, j] = T[i, j]
        if skew and (q % 8 == 7 or q == s - 1):
            _polar_step(out, W[0], W[1])


@_jit
def _mat_phi(chart, skew, X, out, W):
    """out = phi(X) for an (n, n) matrix: exp or Cayley ``(I - X/2)^{-1} (I + X/2)``; W[0..9] scratch."""
    n = X.shape[0]
    if chart == 0:
        _expm(skew, X, out, W)
        return
    Mt = W[9]
    acc = 0.0
    for i in range(n):
        for j in range(n):
            Mt[i, j] = -0.5 * X[i, j]
            out[i, j] = 0.5 * X[i, j]
            acc += X[i, j] * X[i, j]
        Mt[i, i] += 1.0
        out[i, i] += 1.0
    nrm = math.sqrt(0.5 * acc)
    if skew and nrm > _CAYLEY_MAX:
        for i in range(n):
            for j in range(n):
                out[i, j] = np.nan
        return
    _solve(Mt, out)
    if skew and nrm > _CAYLEY_POLAR:
        _polar_step(out, W[0], W[1])


@_jit
def _mat_act(chart, skew, X, sign, v, out, W, vb):
    """out = phi(sign X) v for an (n, n) matrix X and v (n,); W[0..11], vb (n, 1) scratch.

    Skew X with small ``|X|_2``: the Taylor series of the action (exp) or one solve with a vector (Cayley);
    otherwise the matrix phi(sign X), then the product.
    """
    n = X.shape[0]
    T = W[9]
    acc = 0.0
    for i in range(n):
        for j in range(n):
            acc += X[i, j] * X[i, j]
    nu = math.sqrt(0.5 * acc)  # bounds |X|_2 for skew X
    if skew and chart == 0 and nu <= 1.0:
        t = W[11][0]
        u = W[11][1]
        for i in range(n):
            out[i] = v[i]
            t[i] = v[i]
        bound = 1.0
        for j in range(1, 25):
            c = sign / j
            for i in range(n):
                acc = 0.0
                for p in range(n):
                    acc += X[i, p] * t[p]
                u[i] = c * acc
            for i in range(n):
                t[i] = u[i]
                out[i] += u[i]
            bound = bound * nu / j
            if not bound > 1.4e-17:
                break
        return
    if skew and chart == 1 and nu <= _CAYLEY_POLAR:  # (I - sX/2) y = v + sX v / 2
        hh = 0.5 * sign
        for i in range(n):
            acc = 0.0
            for j in range(n):
                T[i, j] = -hh * X[i, j]
                acc += X[i, j] * v[j]
            T[i, i] += 1.0
            vb[i, 0] = v[i] + hh * acc
        _solve(T, vb)
        for i in range(n):
            out[i] = vb[i, 0]
        return
    Sg = W[8]
    for i in range(n):
        for j in range(n):
            Sg[i, j] = sign * X[i, j]
    R = W[10]
    _mat_phi(chart, skew, Sg, R, W)
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += R[i, j] * v[j]
        out[i] = acc


@_jit
def _mat_dinv(chart, skew, Th, A, out, W, bern):
    """out = dphi^{-1}_{-Th}(A), right-trivialised: the truncated Bernoulli series (exp), or the exact
    ``(I + Th/2) A (I - Th/2)`` (Cayley); W[0..2] scratch."""
    n = Th.shape[0]
    if chart == 0:
        ad, P = W[0], W[1]
        for i in range(n):
            for j in range(n):
                ad[i, j] = A[i, j]
                out[i, j] = A[i, j]
        k_ad = 0
        for t in range(bern.shape[0]):
            kk = int(bern[t, 0])
            c = bern[t, 1]
            while k_ad < kk:
                _bracket(skew, Th, ad, P)
                for i in range(n):
                    for j in range(n):
                        ad[i, j] = P[i, j]
                k_ad += 1
            _axpy(out, -c if kk == 1 else c, ad)
        return
    M, P = W[0], W[1]
    _mm(Th, A, P)
    for i in range(n):
        for j in range(n):
            M[i, j] = A[i, j] + 0.5 * P[i, j]
    _mm(M, Th, P)
    if skew:
        for i in range(n):
            out[i, i] = 0.0
            for j in range(i + 1, n):
                v = 0.5 * ((M[i, j] - 0.5 * P[i, j]) - (M[j, i] - 0.5 * P[j, i]))
                out[i, j] = v
                out[j, i] = -v
    else:
        for i in range(n):
            for j in range(n):
                out[i, j] = M[i, j] - 0.5 * P[i, j]


# ====================================================================================== the model
@_jit
def _field(x, Gam, has_gamma, fidx, fval, z, out):
    """out = f(x, Gam): the probed polynomial (COO, see :class:`~.compiled.CompilePlan`); z scratch."""
    k = x.shape[0]
    for c in range(k):
        z[c] = x[c]
    if has_gamma:
        for c in range(Gam.shape[0]):
            z[k + c] = Gam[c]
    for c in range(out.shape[0]):
        out[c] = 0.0
    for t in range(fval.shape[0]):
        v = fval[t]
        i = fidx[t, 1]
        j = fidx[t, 2]
        if i >= 0:
            v = v * z[i]
        if j >= 0:
            v = v * z[j]
        out[fidx[t, 0]] += v


# ====================================================================================== the group part by kind
# kind 1 so3 (3 numbers), 2 dense (m*m), 3 lowrank (r*r in the basis Q); see the module docstring.
@_jit
def _omega_alg(kind, skew, x, widx, wval, Om, Q, nc, cvec, out):
    """out = Omega(x) in the kind's layout. Low-rank: adds column ``nc`` to the basis Q (Gram–Schmidt,
    twice) and returns the number of columns; the other kinds return nc unchanged."""
    if kind == 3:
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
    if kind == 1:
        out[0] = Om[2, 1]
        out[1] = Om[0, 2]
        out[2] = Om[1, 0]
    else:
        for i in range(n):
            for j in range(n):
                out[i * n + j] = Om[i, j]
    return nc


@_jit
def _block(Th, r, ra, buf):
    """The leading ra×ra block of the r×r matrix stored flat in Th, as a contiguous (ra, ra) matrix."""
    Mb = buf[:ra * ra].reshape((ra, ra))
    for i in range(ra):
        for j in range(ra):
            Mb[i, j] = Th[i * r + j]
    return Mb


@_jit
def _scratch(Wf, vbf, n):
    """W (12, n, n) and vb (n, 1): C-contiguous views of the flat scratch, sized for n×n matrices."""
    return Wf[:12 * n * n].reshape((12, n, n)), vbf[:n].reshape((n, 1))


@_jit
def _alg_sq(kind, Th):
    """|Theta|_F^2 / 2 (the squared rotation angle on so(3)): the chart-domain test of exp."""
    acc = 0.0
    for i in range(Th.shape[0]):
        acc += Th[i] * Th[i]
    return acc if kind == 1 else 0.5 * acc


@_jit
def _alg_dinv(kind, chart, skew, Th, Om, h, out, Wf, bern, nc, r, bufs):
    """out = h dphi^{-1}_{-Th}(Om) in the kind's layout."""
    if kind == 1:
        t0, t1, t2_ = Th[0], Th[1], Th[2]
        a0, a1, a2 = Om[0], Om[1], Om[2]
        tt = t0 * t0 + t1 * t1 + t2_ * t2_
        if chart == 0:  # exact: (1 - c θ²) a + ½ θ × a + c (θ·a) θ
            c = _dexp3_coefficient(tt)
            cc, aa, bb = 1.0 - c * tt, 0.5, c
        else:  # exact: a + ½ θ × a + ¼ (θ·a) θ
            cc, aa, bb = 1.0, 0.5, 0.25
        d = bb * (t0 * a0 + t1 * a1 + t2_ * a2)
        out[0] = h * (cc * a0 + aa * (t1 * a2 - t2_ * a1) + d * t0)
        out[1] = h * (cc * a1 + aa * (t2_ * a0 - t0 * a2) + d * t1)
        out[2] = h * (cc * a2 + aa * (t0 * a1 - t1 * a0) + d * t2_)
        return
    if kind == 2:
        n = int(math.sqrt(Th.shape[0]) + 0.5)
        W, _ = _scratch(Wf, bufs[1], n)
        Tm = Th.reshape((n, n))
        Am = Om.reshape((n, n))
        Rm = bufs[2][:n * n].reshape((n, n))
        _mat_dinv(chart, skew, Tm, Am, Rm, W, bern)
        for i in range(n * n):
            out[i] = h * bufs[2][i]
        return
    ra = nc
    W, _ = _scratch(Wf, bufs[2], ra)
    Tm = _block(Th, r, ra, bufs[0])
    Am = _block(Om, r, ra, bufs[1])
    Rm = bufs[2][:ra * ra].reshape((ra, ra))
    _mat_dinv(chart, skew, Tm, Am, Rm, W, bern)
    for i in range(r * r):
        out[i] = 0.0
    for i in range(ra):
        for j in range(ra):
            out[i * r + j] = h * Rm[i, j]


@_jit
def _alg_act(kind, chart, skew, Th, sign, v, out, Wf, vbf, Q, nc, r, bufs):
    """out = phi(sign Th) v for a vector v (n,)."""
    if kind == 1:
        w0, w1, w2 = Th[0], Th[1], Th[2]
        c, a, b = _so3_coef(chart, w0 * w0 + w1 * w1 + w2 * w2)
        a = sign * a
        v0, v1, v2 = v[0], v[1], v[2]
        d = b * (w0 * v0 + w1 * v1 + w2 * v2)
        out[0] = c * v0 + a * (w1 * v2 - w2 * v1) + d * w0
        out[1] = c * v1 + a * (w2 * v0 - w0 * v2) + d * w1
        out[2] = c * v2 + a * (w0 * v1 - w1 * v0) + d * w2
        return
    if kind == 2:
        n = v.shape[0]
        W, vb = _scratch(Wf, vbf, n)
        _mat_act(chart, skew, Th.reshape((n, n)), sign, v, out, W, vb)
        return
    n = v.shape[0]
    ra = nc
    W, vb = _scratch(Wf, vbf, ra)
    Mb = _block(Th, r, ra, bufs[0])
    y = bufs[1][:ra]
    z = bufs[2][:ra]
    for i in range(ra):
        acc = 0.0
        for p in range(n):
            acc += Q[p, i] * v[p]
        y[i] = acc
    _mat_act(chart, skew, Mb, sign, y, z, W, vb)
    for i in range(ra):
        z[i] -= y[i]
    for p in range(n):
        acc = v[p]
        for i in range(ra):
            acc += Q[p, i] * z[i]
        out[p] = acc


@_jit
def _alg_update(kind, chart, skew, mode, G, Th, out, Wf, vbf, Q, nc, r, bufs, PQ, PQ2):
    """The group part moved by Th: ``g phi(Th)`` (mode g, G flat m*m) or ``phi(-Th) Gamma`` (mode gamma)."""
    if mode == 1:
        _alg_act(kind, chart, skew, Th, -1.0, G, out, Wf, vbf, Q, nc, r, bufs)
        return
    if kind == 1:  # g R with R = c I + a hat(w) + b w w^T, by scalars (no reshape, no scratch)
        w0, w1, w2 = Th[0], Th[1], Th[2]
        c, a, b = _so3_coef(chart, w0 * w0 + w1 * w1 + w2 * w2)
        bw0, bw1, bw2 = b * w0, b * w1, b * w2
        r00, r01, r02 = c + bw0 * w0, bw0 * w1 - a * w2, bw0 * w2 + a * w1
        r10, r11, r12 = bw0 * w1 + a * w2, c + bw1 * w1, bw1 * w2 - a * w0
        r20, r21, r22 = bw0 * w2 - a * w1, bw1 * w2 + a * w0, c + bw2 * w2
        for i in range(3):
            g0, g1, g2 = G[3 * i], G[3 * i + 1], G[3 * i + 2]
            out[3 * i] = g0 * r00 + g1 * r10 + g2 * r20
            out[3 * i + 1] = g0 * r01 + g1 * r11 + g2 * r21
            out[3 * i + 2] = g0 * r02 + g1 * r12 + g2 * r22
        return
    if kind == 2:
        n = int(math.sqrt(G.shape[0]) + 0.5)
        W, _ = _scratch(Wf, vbf, n)
        R = W[10]
        _mat_phi(chart, skew, Th.reshape((n, n)), R, W)
        _mm(G.reshape((n, n)), R, out.reshape((n, n)))
        return
    # low rank: g + (g Q) (phi(M) - I) Q^T
    n = Q.shape[0]
    ra = nc
    W, _ = _scratch(Wf, vbf, ra)
    Mb = _block(Th, r, ra, bufs[0])
    F = bufs[1][:ra * ra].reshape((ra, ra))
    _mat_phi(chart, skew, Mb, F, W)
    for i in range(ra):
        F[i, i] -= 1.0
    _g_low_rank(G.reshape((n, n)), Q, F, ra, PQ, PQ2, out.reshape((n, n)), True)


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


@_jit
def _alg_state(kind, mode, G1, Ea, out, Q, nc, r, bufs, PQ, PQ2):
    """The chart increment Ea carried to the state: ``g1 E`` (mode g, m*m entries) or ``E Gamma1`` (mode
    gamma, n entries) — the error estimate of the group part, and (with Ea = Omega) its velocity."""
    if kind == 1:
        e0, e1, e2 = Ea[0], Ea[1], Ea[2]
        if mode == 1:
            v0, v1, v2 = G1[0], G1[1], G1[2]
            out[0] = e1 * v2 - e2 * v1
            out[1] = e2 * v0 - e0 * v2
            out[2] = e0 * v1 - e1 * v0
            return
        for i in range(3):  # row i of g1 times hat(e)
            g0, g1, g2 = G1[3 * i], G1[3 * i + 1], G1[3 * i + 2]
            out[3 * i] = g1 * e2 - g2 * e1
            out[3 * i + 1] = g2 * e0 - g0 * e2
            out[3 * i + 2] = g0 * e1 - g1 * e0
        return
    if kind == 2:
        if mode == 1:
            n = G1.shape[0]
            for i in range(n):
                acc = 0.0
                for j in range(n):
                    acc += Ea[i * n + j] * G1[j]
                out[i] = acc
            return
        n = int(math.sqrt(G1.shape[0]) + 0.5)
        _mm(G1.reshape((n, n)), Ea.reshape((n, n)), out.reshape((n, n)))
        return
    n = Q.shape[0]
    ra = nc
    Eb = _block(Ea, r, ra, bufs[0])
    if mode == 1:
        y = bufs[1][:ra]
        z = bufs[2][:ra]
        for i in range(ra):
            acc = 0.0
            for p in range(n):
                acc += Q[p, i] * G1[p]
            y[i] = acc
        for i in range(ra):
            acc = 0.0
            for j in range(ra):
                acc += Eb[i, j] * y[j]
            z[i] = acc
        for p in range(n):
            acc = 0.0
            for i in range(ra):
                acc += Q[p, i] * z[i]
            out[p] = acc
        return
    _g_low_rank(G1.reshape((n, n)), Q, Eb, ra, PQ, PQ2, out.reshape((n, n)), False)


# ====================================================================================== one trajectory
@_jit
def _ulp(t, direction):
    return abs(np.nextafter(t, direction * np.inf) - t)


@_jit
def _finite(x):
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
def _solve_one(lo, hi, iprm, fprm, xi0, G0, gamma, t_eval, ev_coef, ev_off, cap, xi_out, G_out, status, t_stop,
               failure, nfev_o, steps_o, rejected_o, ev_count, ev_t, ev_xi, ev_G):
    """Integrate trajectories ``lo .. hi-1`` one after the other (see the module docstring); returns the
    recorded steps of the last one (record mode, a single trajectory)."""
    k = iprm[_I_K]
    m = iprm[_I_M]
    q = iprm[_I_Q]
    mode = iprm[_I_MODE]
    chart = iprm[_I_CHART]
    kind = iprm[_I_KIND]
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
    NT = iprm[_I_NT]
    o = _NHEAD
    fidx = iprm[o:o + 3 * nf].reshape((nf, 3))
    o += 3 * nf
    widx = iprm[o:o + 3 * nw].reshape((nw, 3))
    o += 3 * nw
    ev_term = iprm[o:o + E]
    ev_dir = iprm[o + E:o + 2 * E]
    t0 = fprm[_F_T0]
    t1 = fprm[_F_T1]
    hfix = fprm[_F_H]
    rtol = fprm[_F_RTOL]
    atol = fprm[_F_ATOL]
    expo = fprm[_F_EXPO]
    o = _FHEAD
    A = fprm[o:o + S * S].reshape((S, S))
    o += S * S
    bw = fprm[o:o + S]
    o += S
    err = fprm[o:o + ne * S].reshape((ne, S))
    o += ne * S
    dense = fprm[o:o + S * P].reshape((S, P))
    o += S * P
    bern = fprm[o:o + 2 * nb].reshape((nb, 2))
    o += 2 * nb
    fval = fprm[o:o + nf]
    o += nf
    wval = fprm[o:o + nw]
    direction = 1.0 if t1 > t0 else -1.0
    group = mode != 0
    N = k + q
    s_eval = s + (1 if new_in else 0)

    rec_n = 0
    t_rec = np.zeros(0)
    xi_rec = np.zeros((0, xi0.shape[1]))
    G_rec = np.zeros((0, G0.shape[1]))
    for bi in range(lo, hi):
        # ---------------------------------------------------------------- scratch, once per trajectory
        n = m if has_g else 0
        mm = 3 if kind == 1 else (m if kind == 2 else r)
        F = np.zeros((S, k))
        hL = np.zeros((S, k))
        hK = np.zeros((S, a))
        xi = xi0[bi].copy()
        G = G0[bi].copy()
        gam = gamma[bi]
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
        Om = np.zeros((m if kind != 3 else 1, m))
        W = np.zeros(12 * mm * mm)  # flat: viewed as (12, n, n) for the size at hand (_scratch)
        vb = np.zeros(mm)
        bufs = np.zeros((3, max(mm * mm, 1)))
        Q = np.zeros((m if kind == 3 else 0, r))
        if kind == 3:
            Q[m - 1, 0] = 1.0
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
        sc_y = np.zeros(N)
        f_y = np.zeros(N)
        rec_n = 0
        rec_cap = 64 if record else 0
        t_rec = np.zeros(rec_cap)
        xi_rec = np.zeros((rec_cap, k))
        G_rec = np.zeros((rec_cap, q))
        for e in range(E):
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
        if has_g:
            _body_vertical(mode, G, gam, Gam0)
        _field(xi, Gam0, has_g, fidx, fval, z, F[0])
        nfev += 1
        f0_ok = True
        if not (_finite(F[0]) and _finite(xi) and _finite(G)):
            fail = 1
        else:
            while ie < NT and t_eval[ie] == t0:
                for c in range(k):
                    xi_out[ie, bi, c] = xi[c]
                for c in range(q):
                    G_out[ie, bi, c] = G[c]
                ie += 1
            if record:
                t_rec[0] = t0
                xi_rec[0, :] = xi
                G_rec[0, :] = G
                rec_n = 1
        for e in range(E):
            acc = -ev_off[bi, e]
            for c in range(k):
                acc += ev_coef[bi, e, c] * xi[c]
            for c in range(q):
                acc += ev_coef[bi, e, k + c] * G[c]
            gold[e] = acc
        h = hfix * direction
        if fail == 0 and adaptive and hfix == 0.0:
            # Hairer's estimate on the embedded state y = (xi, G), f = (xi_dot, group velocity)
            nc = 1
            if kind == 3:
                for p in range(m - 1):
                    for j in range(1, r):
                        Q[p, j] = 0.0
            if group:
                nc = _omega_alg(kind, skew, xi, widx, wval, Om, Q, nc, cvec, Oa)
                _alg_state(kind, mode, G, Oa, Eg, Q, nc, r, bufs, PQ, PQ2)
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
            _field(xit, Gam, has_g, fidx, fval, z, F[1])
            nfev += 1
            if group:
                nc = 1
                if kind == 3:
                    for p in range(m - 1):
                        for j in range(1, r):
                            Q[p, j] = 0.0
                nc = _omega_alg(kind, skew, xit, widx, wval, Om, Q, nc, cvec, Oa)
                _alg_state(kind, mode, Gt, Oa, Eg, Q, nc, r, bufs, PQ, PQ2)
            d2 = 0.0
            for c in range(k):
                d2 += ((F[1, c] - f_y[c]) / sc_y[c]) ** 2
            for c in range(q):
                v = -Eg[c] if mode == 1 else Eg[c]
                d2 += ((v - f_y[k + c]) / sc_y[k + c]) ** 2
            d2 = math.sqrt(d2 / N) / h0
            h = _initial_step(d0, d1, d2, h0, order) * direction
            if not (h == h):
                fail = 1

        # ---------------------------------------------------------------- the time loop
        after_reject = False
        i_step = 0
        nc = 1
        if not adaptive and hfix <= 0.0:
            fail = 2
        n_fixed = 0
        if not adaptive and fail == 0:
            n_fixed = max(1, int(math.ceil(abs(t1 - t0) / hfix - 1e-9)))
        at_start = True
        t_fail = t0
        while fail == 0 and t1 != t0:
            if nsteps + nrej >= max_steps:
                fail = 3
                break
            if adaptive:
                if abs(h) < 10.0 * _ulp(t, direction):
                    fail = 2
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
                _field(xi, Gam0, has_g, fidx, fval, z, F[0])
                nfev += 1
                f0_ok = True
            for c in range(k):
                hL[0, c] = h * F[0, c]
            nc = 1
            if kind == 3:
                for p in range(m - 1):
                    for j in range(1, r):
                        Q[p, j] = 0.0
            if group:
                nc = _omega_alg(kind, skew, xi, widx, wval, Om, Q, nc, cvec, Oa)
                for c in range(a):
                    hK[0, c] = h * Oa[c]
            ok = True
            have_new = fsal or new_in  # stage s available after this trial
            extended = False
            rejected_now = False
            i = 1
            i_hi = s_eval
            # stages 1 .. s_eval-1 of the trial step and, on demand below, s .. S-1 of an accepted one
            while True:
                while i < i_hi:
                    for c in range(k):
                        acc = 0.0
                        for j in range(i):
                            acc += A[i, j] * hL[j, c]
                        Xi[c] = xi[c] + acc
                    if group:
                        for c in range(a):
                            acc = 0.0
                            for j in range(i):
                                acc += A[i, j] * hK[j, c]
                            Th[c] = acc
                        if chart == 0 and skew and not extended and _alg_sq(kind, Th) >= _PI2:
                            ok = False
                        if has_g:
                            _alg_act(kind, chart, skew, Th, -1.0, Gam0, Gam, W, vb, Q, nc, r, bufs)
                    _field(Xi, Gam, has_g, fidx, fval, z, F[i])
                    nfev += 1
                    for c in range(k):
                        hL[i, c] = h * F[i, c]
                    if group:
                        nc = _omega_alg(kind, skew, Xi, widx, wval, Om, Q, nc, cvec, Oa)
                        _alg_dinv(kind, chart, skew, Th, Oa, h, hK[i], W, bern, nc, r, bufs)
                    i += 1
                if extended:  # the continuous extension's stages were just evaluated
                    break
                # ------------------------------------------------ the trial step's end and its error
                for c in range(k):
                    acc = 0.0
                    for j in range(s):
                        acc += bw[j] * hL[j, c]
                    xi1[c] = xi[c] + acc
                if group:
                    for c in range(a):
                        acc = 0.0
                        for j in range(s):
                            acc += bw[j] * hK[j, c]
                        Th1[c] = acc
                    if chart == 0 and skew and _alg_sq(kind, Th1) >= _PI2:
                        ok = False
                    _alg_update(kind, chart, skew, mode, G, Th1, G1, W, vb, Q, nc, r, bufs, PQ, PQ2)
                finite = _finite(xi1) and _finite(G1)
                nrm = 0.0
                if adaptive:
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
                        if group:
                            for c in range(a):
                                acc = 0.0
                                for j in range(s_eval):
                                    acc += err[e, j] * hK[j, c]
                                Ea[c] = acc
                            _alg_state(kind, mode, G1, Ea, Eg, Q, nc, r, bufs, PQ, PQ2)
                            for c in range(q):
                                v = Eg[c] / _scale(G[c], G1[c], rtol, atol)
                                acc2 += v * v
                        if e == 0:
                            s5 = acc2
                        else:
                            s3 = acc2
                    nrm = _combine(s5, s3, N, ne == 2)
                    if not ok or not finite:
                        nrm = np.inf
                    if not (nrm <= 1.0):
                        rejected_now = True
                        break
                else:
                    if not finite:  # the field broke down (a NaN chart argument too)
                        fail = 1
                        t_fail = t + h
                        break
                    if not ok:
                        fail = 4
                        t_fail = t
                        break
                # ------------------------------------------------ accepted: does its interior matter?
                t_new = t1 if last else t + h
                for e in range(E):
                    acc = -ev_off[bi, e]
                    for c in range(k):
                        acc += ev_coef[bi, e, c] * xi1[c]
                    for c in range(q):
                        acc += ev_coef[bi, e, k + c] * G1[c]
                    gnew[e] = acc
                n_act = 0
                for e in range(E):
                    go = gold[e]
                    gn = gnew[e]
                    if go == 0.0 and at_start:  # starting on the surface is not a crossing
                        continue
                    up = go <= 0.0 and gn >= 0.0 and go != gn
                    down = go >= 0.0 and gn <= 0.0 and go != gn
                    d = ev_dir[e]
                    if (up and d >= 0) or (down and d <= 0):
                        act_e[n_act] = e
                        n_act += 1
                need = n_act > 0 or (ie < NT and direction * (t_eval[ie] - t_new) <= 0.0)
                if need:  # the continuous extension: stage s (a copy for FSAL methods) and the extra stages
                    extended = True
                    if not have_new:
                        i = s
                    elif fsal:
                        for c in range(k):
                            F[s, c] = F[s - 1, c]
                            hL[s, c] = hL[s - 1, c]
                        for c in range(a):
                            hK[s, c] = hK[s - 1, c]
                        i = s + 1
                    else:
                        i = s + 1
                    i_hi = S
                    have_new = True
                    continue
                break
            if fail != 0:
                break
            if rejected_now:
                nrej += 1
                h = h * _reject_factor(nrm, expo)
                after_reject = True
                continue
            # ---------------------------------------------------- events, in time order
            nsteps += 1
            stop_th = 2.0
            if n_act > 0:
                for ia in range(n_act):
                    e = act_e[ia]
                    # Illinois on theta in [0, 1]: f(0) = gold, f(1) = gnew
                    lo = 0.0
                    hi = 1.0
                    flo = gold[e]
                    fhi = gnew[e]
                    tlo = flo
                    thi = fhi
                    side = 0
                    root = -1.0
                    if flo == 0.0:
                        root = 0.0
                    elif fhi == 0.0:
                        root = 1.0
                    for _it in range(300):
                        if root >= 0.0:
                            break
                        cth = (lo * fhi - hi * flo) / (fhi - flo)
                        if not (lo < cth < hi):
                            cth = 0.5 * (lo + hi)
                        if cth <= lo or cth >= hi:
                            break
                        # the value at cth, on the continuous extension
                        _dense_at(cth, dense, wts, xi, hL, hK, xit, Tht)
                        fc = -ev_off[bi, e]
                        for c in range(k):
                            fc += ev_coef[bi, e, c] * xit[c]
                        if ev_needG[e]:
                            _alg_update(kind, chart, skew, mode, G, Tht, Gt, W, vb, Q, nc, r, bufs, PQ, PQ2)
                            for c in range(q):
                                fc += ev_coef[bi, e, k + c] * Gt[c]
                        if fc == 0.0:
                            root = cth
                            break
                        if (fc > 0.0) == (fhi > 0.0):
                            hi = cth
                            fhi = fc
                            thi = fc
                            if side == 1:
                                flo *= 0.5
                            side = 1
                        else:
                            lo = cth
                            flo = fc
                            tlo = fc
                            if side == -1:
                                fhi *= 0.5
                            side = -1
                        if abs(h) * (hi - lo) <= 4.0 * _ulp(t + cth * h, direction):
                            break
                    if root < 0.0:
                        root = lo if abs(tlo) < abs(thi) else hi
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
                for ia in range(n_act):
                    e = act_e[ia]
                    th_ = act_th[ia]
                    if st == 1 and th_ > stop_th:
                        break
                    te = t_new if th_ == 1.0 else t + th_ * h
                    if th_ == 1.0:
                        for c in range(k):
                            xit[c] = xi1[c]
                        for c in range(q):
                            Gt[c] = G1[c]
                    else:
                        _dense_at(th_, dense, wts, xi, hL, hK, xit, Tht)
                        if group:
                            _alg_update(kind, chart, skew, mode, G, Tht, Gt, W, vb, Q, nc, r, bufs, PQ, PQ2)
                    cnt = ev_count[bi, e]
                    if cnt < cap:
                        ev_t[bi, e, cnt] = te
                        for c in range(k):
                            ev_xi[bi, e, cnt, c] = xit[c]
                        for c in range(q):
                            ev_G[bi, e, cnt, c] = Gt[c]
                    ev_count[bi, e] = cnt + 1
                    if ev_term[e] != 0 and st == 0:
                        st = 1
                        tst = te
                        stop_th = th_
            # ---------------------------------------------------- outputs (t_eval, record)
            t_lim = tst if st == 1 else t_new
            while ie < NT and direction * (t_eval[ie] - t_lim) <= 0.0:
                te = t_eval[ie]
                if te == t_new:
                    for c in range(k):
                        xi_out[ie, bi, c] = xi1[c]
                    for c in range(q):
                        G_out[ie, bi, c] = G1[c]
                else:
                    _dense_at((te - t) / h, dense, wts, xi, hL, hK, xit, Tht)
                    for c in range(k):
                        xi_out[ie, bi, c] = xit[c]
                    if group:
                        _alg_update(kind, chart, skew, mode, G, Tht, Gt, W, vb, Q, nc, r, bufs, PQ, PQ2)
                        for c in range(q):
                            G_out[ie, bi, c] = Gt[c]
                ie += 1
            if st == 1:
                break
            # ---------------------------------------------------- advance
            t = t_new
            i_step += 1
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
            at_start = False
            if reproj and group and nsteps % renorm == 0:
                f0_ok = False  # the state moved: stage 0 is evaluated again
                if mode == 2:
                    Gm = G.reshape((m, m))
                    _polar_step(Gm, Wg[0], Wg[1])
                elif mode == 1:
                    acc = 0.0
                    for c in range(q):
                        acc += G[c] * G[c]
                    nr = math.sqrt(acc)
                    for c in range(q):
                        G[c] = G[c] / nr
            if record:
                if rec_n == rec_cap:
                    rec_cap *= 2
                    t2 = np.zeros(rec_cap)
                    x2 = np.zeros((rec_cap, k))
                    g2 = np.zeros((rec_cap, q))
                    t2[:rec_n] = t_rec[:rec_n]
                    x2[:rec_n] = xi_rec[:rec_n]
                    g2[:rec_n] = G_rec[:rec_n]
                    t_rec, xi_rec, G_rec = t2, x2, g2
                t_rec[rec_n] = t
                xi_rec[rec_n, :] = xi
                G_rec[rec_n, :] = G
                rec_n += 1
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
    return t_rec[:rec_n].copy(), xi_rec[:rec_n].copy(), G_rec[:rec_n].copy()


def _solve_batch(*args) -> None:
    """Every trajectory of the batch, in contiguous chunks over the cores: the jitted loop releases the GIL,
    so threads run the chunks in parallel (no parfor to compile; no reduction across trajectories, so a
    trajectory's numbers do not depend on the chunking)."""
    B = args[2].shape[0]
    workers = min(B, numba.config.NUMBA_NUM_THREADS, os.cpu_count() or 1)
    if workers <= 1:
        _solve_one(0, B, *args)
        return
    bounds = np.linspace(0, B, 4 * workers + 1).astype(np.int64)
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(workers) as pool:
        list(pool.map(lambda c: _solve_one(int(bounds[c]), int(bounds[c + 1]), *args), range(len(bounds) - 1)))
