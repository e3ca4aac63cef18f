"""The Python side: which kind runs a model, whether a problem compiles, packing, and :func:`solve`."""

from __future__ import annotations

import functools
import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
from numba import njit

from ... import groups
from ..charts import domain_block, domain_bound2
from ..compiled import (
    CompilePlan,
    NotCompilable,
    _model_cache,
    compile_plan,
)
from ..problem import RENORM_EVERY, Problem, RawResult
from .common import (
    _FHEAD,
    _I_NEV,
    _NHEAD,
    CHARTS,
    EVENT_CAP,
    FAMILIES,
    KINDS,
    LOWRANK_MIN_N,
    MODES,
)
from .loop import _solve_one


# ====================================================================================== choosing the kind
def kind_for(model, mode: str, chart: str | None) -> str | None:
    """The group representation the kernel uses for ``model`` in ``mode`` (None for mode "none").

    "so3" on so(3); "so4" on so(4) (the pair (p, q) of so(3) ⊕ so(3), closed forms: :mod:`.so4`); "lowrank"
    for Fedorov–Kozlov models with n >= :data:`LOWRANK_MIN_N`; "dense" otherwise (so(n), and general matrix
    algebras such as se(2), se(3)).
    """
    if mode == "none":
        return None
    name = getattr(getattr(model, "algebra", None), "name", "")
    n = getattr(model, "n", None)
    if name == "so(3)":
        return "so3"
    if name == "so(4)":
        return "so4"
    if name.startswith("so(") and getattr(model, "fedorov_kozlov", False) and n is not None and n >= LOWRANK_MIN_N:
        return "lowrank"
    return "dense"


# ====================================================================================== the wrapper
def check(problem: Problem) -> None:
    """Raise :class:`NotCompilable` with the reason when ``problem`` cannot run on the compiled kernel."""
    _prepare(problem, _model_cache(problem.model))


def _prepare(problem: Problem, cache: dict):
    """``(kind, CompilePlan)`` of ``problem``, or :class:`NotCompilable` with the reason; the model's part is
    judged once per (model, mode, chart, kind) and kept in the model's cache (a front-door call is ~0.1 ms)."""
    if njit is None:
        raise NotCompilable("numba is not installed (pip install 'liesuslov[fast]')")
    if problem.events and problem.event_coef is None:
        raise NotCompilable("an event is a user callable (not a LinearEvent): events are located on numpy")
    mode = problem.mode
    kind = problem.kind if mode != "none" else None
    key = ("prepared", mode, problem.chart, kind, bool(problem.skew), int(problem.m))
    out = cache.get(key)
    if out is None:
        try:
            out = _judge(problem.model, mode, problem.chart, kind, problem.skew, problem.m)
        except NotCompilable as exc:
            out = NotCompilable(str(exc))  # not exc: its traceback would keep the model, the cache's weak key
        cache[key] = out
    if isinstance(out, NotCompilable):
        raise NotCompilable(str(out))
    return out


def _judge(model, mode: str, chart: str | None, kind: str | None, skew: bool, m: int):
    """``(kind, CompilePlan)`` when the kernel runs ``model`` in this mode, chart and kind; NotCompilable else."""
    if kind not in KINDS:
        raise NotCompilable(f"the compiled kernel knows the kinds {sorted(k for k in KINDS if k)}, got {kind!r}")
    if mode != "none" and chart not in ("exp", "cayley"):
        raise NotCompilable(f"the compiled kernel knows the charts exp and cayley, got {chart!r}")
    if kind in ("so3", "so4", "lowrank") and not skew:
        raise NotCompilable(f"the {kind!r} kind needs so(n)")
    if kind in ("so3", "so4") and m != int(kind[2]):
        raise NotCompilable(f"the {kind!r} kind needs {kind[2]}×{kind[2]} matrices, got m = {m}")
    cplan = compile_plan(model, mode, chart, skew=skew, omega=kind != "lowrank")
    if kind == "lowrank":
        _check_fedorov_kozlov(model)
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




@functools.cache
def _bernoulli_pairs(order: int) -> np.ndarray:
    """The dexp⁻¹ series coefficients a method of ``order`` needs, as (term, 2) rows (read-only, shared)."""
    terms = groups.bernoulli_coefficients(groups.dexpinv_terms(order))[1:]
    pairs = np.array(terms, dtype=float).reshape(-1, 2)
    pairs.setflags(write=False)
    return pairs


def _constants(problem: Problem, cplan: CompilePlan, cache: dict) -> tuple[np.ndarray, np.ndarray, int]:
    """(integer, float constants, dexp⁻¹ terms) of the method and the model, packed once per pair: the
    coefficient lists of the field and Omega, the tableau's rows, the dexp⁻¹ series (read-only); the float
    constants after :data:`~.common._FHEAD` zeros, the place of the float head."""
    plan = problem.plan
    # one tableau gives plans with other error weights (rkmk5 / rkmk45): the name and the scale; cplan lives in
    # the same cache, so its id is not reused meanwhile
    key = ("packed", plan.name, plan.error_scale, id(cplan))
    if key not in cache:
        bern = _bernoulli_pairs(int(plan.order))
        ints = np.concatenate([cplan.field_index.ravel(), cplan.omega_index.ravel()]).astype(np.int64)
        floats = np.concatenate([np.zeros(_FHEAD), plan.A.ravel(), plan.b.ravel(), plan.err.ravel(), plan.dense.ravel(),
                                 bern.ravel(), cplan.field_value, cplan.omega_value]).astype(float)
        ints.setflags(write=False)
        floats.setflags(write=False)
        cache[key] = (ints, floats, bern.shape[0])
    return cache[key]


def _pack(problem: Problem, kind: str | None, cplan: CompilePlan, record: bool, cache: dict):
    """``(iprm, fprm)``: the integer head and constants (kept per model and setting when there is no event:
    the kernel only reads them) and the float head (times, step, tolerances) with the float constants."""
    plan = problem.plan
    ints, floats, nb = _constants(problem, cplan, cache)
    E = 0 if problem.event_coef is None else int(problem.event_coef.shape[1])
    if E:
        cache = {}
    key = ("iprm", plan.name, plan.error_scale, id(cplan), problem.mode, problem.chart, kind, bool(problem.skew),
           bool(problem.adaptive), int(problem.max_steps), bool(problem.reproject), bool(record))
    iprm = cache.get(key)
    if iprm is None:
        mode = MODES[problem.mode]
        k, m, q = int(problem.k), int(problem.m), int(problem.q)
        S, s = plan.S, plan.s
        r = S + 1 if kind == "lowrank" else 0
        a = {None: 0, "so3": 3, "so4": 6, "dense": m * m, "lowrank": r * r}[kind]
        # the block the chart's domain bounds (the matrix kinds; the closed forms take all of theirs)
        dom = domain_block(problem.model.algebra, m, bool(problem.skew)) if kind == "dense" else r
        head = (k, m, q, mode, CHARTS[problem.chart if mode else None], KINDS[kind], int(problem.skew),
                int(bool(cplan.has_gamma) and mode != 0), s, S, plan.err.shape[0], plan.dense.shape[1],
                int(plan.fsal), int(plan.new_in_step), int(problem.adaptive), int(problem.max_steps),
                int(problem.reproject), max(RENORM_EVERY, m), nb, cplan.field_value.size,
                cplan.omega_value.size, E, int(plan.order), int(record), r, a, dom)
        iprm = np.empty(_NHEAD + ints.size + 2 * E, np.int64)
        iprm[:_NHEAD] = head
        iprm[_NHEAD:_NHEAD + ints.size] = ints
        if E:
            iprm[_NHEAD + ints.size:] = np.concatenate([np.asarray(problem.event_terminal).reshape(E),
                                                         np.asarray(problem.event_direction).reshape(E)])
        cache[key] = iprm
    fprm = floats.copy()
    # the chart's domain as the kernel tests it, on |Theta|_F^2 / 2 (no group part: never tested)
    domain = 0.5 * domain_bound2(problem.chart) if problem.mode != "none" else np.inf
    fprm[:_FHEAD] = (problem.t0, problem.t1, abs(float(problem.h)), problem.rtol, problem.atol,
                     plan.error_exponent, domain)
    return iprm, fprm


_LOOPS: dict = {}
#: Held while a family's loop is compiled or loaded: numba's loading from its cache (``load_overload``, the
#: target context's ``refresh``) is not thread-safe — first calls in several threads at once failed at random
#: ("generator already executing", "key already in dictionary", an audit).
_COMPILE_LOCK = threading.Lock()


def _compiled(family: int, args: tuple):
    """The compiled :func:`~.loop._solve_one` of ``family`` (:data:`~.common.FAMILIES`), as ``f(lo, hi, *args)``.

    Compiled (or loaded from numba's on-disk cache) on first use with the family as a literal, then called
    through its entry point: a plain call with an int would make the dispatcher type the loop again on every
    call to find the literal specialisation (~10 ms). The argument types do not vary: :func:`solve` makes
    every array C-contiguous float64 or int64 of a fixed number of dimensions.
    """
    entry = _LOOPS.get(family)
    if entry is None:
        with _COMPILE_LOCK:
            entry = _LOOPS.get(family)  # (another thread may have made it while this one waited)
            if entry is None:
                sig = ((numba.types.literal(family), numba.types.int64, numba.types.int64)
                       + tuple(numba.typeof(a) for a in args))
                if sig not in _solve_one.overloads:
                    _compile_apart(family, sig)
                _solve_one.compile(sig)
                compiled = _solve_one.overloads[sig].entry_point
                entry = _LOOPS[family] = lambda lo, hi, *rest: compiled(family, lo, hi, *rest)
    return entry


def _compile_apart(family: int, sig: tuple) -> None:
    """Compile ``family``'s loop into numba's on-disk cache in a child process (:func:`.warm.compile_kinds`),
    unless the cache has it or this process is such a child; the caller then loads it from the cache.

    Why: the loop loaded from the cache can run faster than the same loop compiled in this process (an so(3)
    RKMK4 step 0.58 -> 0.34 µs; the dense family's Kharlamova step alike either way; numba issue #10617
    reports the effect), and the compiler's Python objects stay in the child. A child that fails (no writable cache, no
    subprocess) leaves the compilation to this process, as before.
    """
    # (imported here: `python -m liesuslov.integrators.kernel.warm` must not find warm imported by the package)
    from .warm import COMPILE_HERE_ENV, FAMILY_KIND, compile_kinds

    if os.environ.get(COMPILE_HERE_ENV) == "1":
        return
    if _solve_one._cache.load_overload(sig, _solve_one.targetctx) is not None:
        return
    try:
        compile_kinds([FAMILY_KIND[family]], processes=1)
    except (RuntimeError, OSError):
        pass


@functools.lru_cache(maxsize=64)
def _empty(shape: tuple, dtype=float) -> np.ndarray:
    """A zero-size array of ``shape``, shared: it holds nothing to write (its allocation is ~0.5 µs of a
    front-door call on a shared machine, and a call has up to ten)."""
    return np.empty(shape, dtype)


@functools.lru_cache(maxsize=64)
def _no_events(B: int, k: int, q: int) -> tuple:
    """The six event arrays of a run without events (zero-size, shared): coefficients, offsets, counts, times,
    states xi and G."""
    return (_empty((B, 0, k + q)), _empty((B, 0)), _empty((B, 0), np.int64), _empty((B, 0, 0)),
            _empty((B, 0, 0, k)), _empty((B, 0, 0, q)))


def _nans(shape: tuple) -> np.ndarray:
    """An output array of NaN (the shared empty one when ``shape`` has no entry)."""
    if 0 in shape:
        return _empty(shape)
    out = np.empty(shape)
    out.fill(np.nan)  # (np.full is a Python function: ~1 µs more a call)
    return out


@functools.cache
def _cpu_count() -> int:
    """The machine's cores (``os.cpu_count`` reads /sys on every call: ~15 µs)."""
    return os.cpu_count() or 1


def _threads() -> int:
    """Threads a batch may use: the cores, at most numba's thread count (``NUMBA_NUM_THREADS``)."""
    return max(1, min(numba.config.NUMBA_NUM_THREADS, _cpu_count()))


#: The batch's threads: made on first use and kept (starting two threads costs ~0.5 ms a call, as much as a
#: small batch's whole solve). A forked child inherits the pool object but not its threads, and perhaps the
#: lock held by another thread: it starts afresh (_forget_pool).
_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()


def _forget_pool() -> None:
    """In a forked child: no pool yet, and locks nobody holds."""
    global _POOL, _POOL_LOCK, _COMPILE_LOCK
    _POOL, _POOL_LOCK, _COMPILE_LOCK = None, threading.Lock(), threading.Lock()


if hasattr(os, "register_at_fork"):  # (POSIX; there is no fork elsewhere)
    os.register_at_fork(after_in_child=_forget_pool)


def _batch_pool() -> ThreadPoolExecutor:
    """The process's thread pool for :func:`_solve_batch`, :func:`_threads` threads."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is None:
            _POOL = ThreadPoolExecutor(_threads(), thread_name_prefix="liesuslov-batch")
        return _POOL


def _solve_batch(solve_one, *args) -> None:
    """Every trajectory of the batch, in contiguous chunks over the cores: ``solve_one(lo, hi, *args)`` (the
    compiled :func:`~.loop._solve_one` of the problem's kind) releases the GIL, so threads run the chunks in
    parallel (no parfor to compile; no reduction across trajectories, so a trajectory's numbers do not depend
    on the chunking). Calls from several threads share the pool: their chunks queue, none waits on another's."""
    B = args[2].shape[0]
    workers = 1 if B == 1 else min(B, _threads())
    if workers <= 1:
        solve_one(0, B, *args)
        return
    bounds = np.linspace(0, B, 4 * workers + 1).astype(np.int64)
    list(_batch_pool().map(lambda c: solve_one(int(bounds[c]), int(bounds[c + 1]), *args), range(len(bounds) - 1)))


def solve(problem: Problem) -> RawResult:
    """Integrate ``problem`` on the compiled kernel (see the module docstring); ``RawResult.backend == "numba"``."""
    cache = _model_cache(problem.model)
    kind, cplan = _prepare(problem, cache)
    B, k, q = int(problem.B), int(problem.k), int(problem.q)
    record = problem.t_eval is None
    if record and B != 1:
        raise ValueError("t_eval=None (record every step) needs a single trajectory")
    iprm, fprm = _pack(problem, kind, cplan, record, cache)
    # fresh C-contiguous writable copies: the compiled loop's argument types never vary (see _compiled)
    xi0 = np.array(problem.xi0, dtype=float, order="C").reshape(B, k)
    G0 = np.array(problem.G0, dtype=float, order="C").reshape(B, q) if q else _empty((B, 0))
    gamma = problem.gamma
    gamma = np.array(gamma, dtype=float, order="C").reshape(B, -1) if gamma.size else _empty((B, 0))
    t_eval = _empty((0,)) if record else np.array(problem.t_eval, dtype=float, order="C")
    E = int(iprm[_I_NEV])
    if E:
        ev_coef = np.array(problem.event_coef, dtype=float, order="C").reshape(B, E, k + q)
        ev_off = np.array(problem.event_offset, dtype=float, order="C").reshape(B, E)
    else:
        ev_coef, ev_off, ev_count, ev_t, ev_xi, ev_G = _no_events(B, k, q)
    cap = EVENT_CAP if E else 0
    while True:
        M = 0 if record else t_eval.shape[0]
        xi_out, G_out = _nans((M, B, k)), _nans((M, B, q))
        counts = np.zeros((5, B), np.int64)  # rows: C-contiguous views, the loop's argument types
        status, failure, nfev, steps, rejected = counts
        t_stop = np.zeros(B)
        if E:
            ev_count = np.zeros((B, E), np.int64)
            ev_t = np.empty((B, E, cap))  # written before they are read, at ev_count
            ev_xi = np.empty((B, E, cap, k))
            ev_G = np.empty((B, E, cap, q))
        args = (iprm, fprm, xi0, G0, gamma, t_eval, ev_coef, ev_off, cap, xi_out, G_out, status, t_stop,
                failure, nfev, steps, rejected, ev_count, ev_t, ev_xi, ev_G)
        solve_one = _compiled(FAMILIES[KINDS[kind]], args)
        if record:
            t_rec, xi_rec, G_rec = solve_one(0, 1, *args)
        else:
            _solve_batch(solve_one, *args)
        top = int(ev_count.max()) if E else 0
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
