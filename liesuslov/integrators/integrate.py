"""The front door: :func:`integrate` a scene with a Lie-group method, over a batch of initial data.

The call is validated here and turned into a :class:`~.problem.Problem`; a solver — the compiled kernel
(:mod:`.kernel`, numba) or the numpy reference (:mod:`.solve_numpy`) — integrates every trajectory on its
own (own steps, status and events), and the :class:`~.problem.RawResult` becomes a :class:`~.solution.Solution`.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, replace

import numpy as np

from .._progress import progress_bar
from .._validation import (
    as_float_array,
    check_positive,
    check_rigid_motions,
    check_rotations,
    check_t_eval,
    check_t_span,
    tolerance_for,
    unit_vectors,
)
from ..algebra.elements import body_vector, omega_coordinates
from ..groups import orthonormalize
from ..mechanics.protocol import ModelProtocol
from ..mechanics.system import SuslovSystem
from .charts import CHARTS
from .events import EventRecord, LinearEvent, event_flags
from .plan import plan_for
from .problem import STATUS_TERMINAL, Problem, RawResult, run_message
from .solution import Solution

__all__ = ["integrate", "METHODS", "Method", "BACKENDS"]


@dataclass(frozen=True)
class Method:
    """A named method: a tableau (by name), whether the step size is adapted, and the weight of its error norm.

    ``error_scale`` multiplies the embedded error estimate (the stage plan's error weights). The classical
    pairs' estimators are calibrated on ODEs; applied to RKMK's chart stages they estimate the error of a
    companion method in the chart, which on coupled scenes underestimates the true local error relative to
    scipy's calibration (measured over random states of four scenes, docs/numerics.md "What the tolerance
    means"): the factor makes rtol mean what it means in scipy — same work for the same error, the global
    error at equal rtol near scipy's or below.
    """

    tableau: str
    adaptive: bool
    description: str
    error_scale: float = 1.0


METHODS: dict[str, Method] = {
    "lie-euler": Method("euler", False, "Lie–Euler, order 1, fixed step"),
    "rkmk2": Method("midpoint", False, "RKMK with the explicit midpoint rule, order 2, fixed step"),
    "rkmk-heun": Method("heun2", False, "RKMK with Heun's method, order 2, fixed step"),
    "rkmk3": Method("kutta3", False, "RKMK with Kutta's third-order method, fixed step"),
    "rkmk4": Method("rk4", False, "RKMK with the classical fourth-order tableau, fixed step"),
    "rkmk5": Method("dopri5", False, "RKMK with the Dormand–Prince 5 weights, order 5, fixed step"),
    "rkmk8": Method("dop853", False, "RKMK with the DOP853 weights, order 8, fixed step"),
    "rkmk23": Method("bs3", True, "RKMK with the Bogacki–Shampine 3(2) pair, adaptive", error_scale=3.0),
    "rkmk45": Method("dopri5", True, "RKMK with the Dormand–Prince 5(4) pair, adaptive", error_scale=3.0),
    "rkmk853": Method("dop853", True, "RKMK with the Dormand–Prince 8(5,3) pair, adaptive", error_scale=20.0),
}

BACKENDS = ("auto", "numpy", "numba")
#: max_steps above this is this (the compiled loop counts in int64; no run gets near it).
_MAX_STEPS = 2**62


def integrate(system, Omega0, t_span, *, Gamma0=None, g0=None, reconstruct: bool = False,
              method: str = "rkmk4", chart: str = "exp", h: float | None = None, rtol: float = 1e-8,
              atol: float = 1e-10, t_eval=None, dense_output: bool = False, events=None, form: str = "auto",
              first_step: float | None = None, max_steps: int = 10_000_000, progress: bool = False,
              backend: str = "auto", reproject: bool = True) -> Solution:
    """Integrate a Suslov / Euler–Poincaré–Suslov system by a Runge–Kutta–Munthe-Kaas method.

    The smallest exact model of the scene is integrated (see ``system.model``): reduced coordinates
    ``xi`` in the constraint subspace D (so the constraints hold exactly), Gamma only when the potential
    needs it or ``Gamma0`` is given, the attitude g only when ``reconstruct=True`` — and then Gamma is read
    off it, ``Gamma = g^T gamma``. Each trajectory of a batch is integrated on its own: its own steps,
    accepted and rejected, its own status and events, the same numbers alone or in any batch.

    Parameters
    ----------
    system : SuslovSystem or ModelProtocol
        A system (its smallest model is chosen) or a model (:class:`liesuslov.mechanics.ModelProtocol`).
    Omega0 : array_like, shape (..., n, n) or (..., d)
        Initial angular velocity in D: skew matrices (so(n)) or coordinates in the algebra basis.
    t_span : (t0, t1)
        Integration interval; ``t1 < t0`` integrates backward.
    Gamma0 : array_like, shape (..., n), optional
        Initial vertical in the body frame (unit vectors). Required when the potential is not zero.
    g0 : array_like, shape (..., m, m), optional
        Initial attitude (default the identity); only with ``reconstruct=True``. Checked to be in SO(n) on
        so(n) and in SE(n) on se(n) (``[[R, p], [0, 1]]``, R in SO(n)); taken as given on other algebras.
    reconstruct : bool
        Also integrate ``g^{-1} dg/dt = Omega`` on the group.
    method : str
        A key of :data:`METHODS` ("lie-euler", "rkmk2", "rkmk-heun", "rkmk3", "rkmk4", "rkmk5", "rkmk8"
        fixed step; "rkmk23", "rkmk45", "rkmk853" adaptive).
    chart : {"exp", "cayley"}
    h : float, optional
        Step size, required by fixed-step methods; the first step of adaptive ones.
    rtol, atol : float
        Tolerances of adaptive methods: the error per step of each trajectory, in the state (xi and g or
        Gamma), scaled like scipy's (``atol + rtol |y|`` per component, RMS over the state's components).
    t_eval : array_like, shape (M,), optional
        Output times (sorted in the direction of integration), served by the method's continuous
        extension: they do not change the steps taken. Default: every step for a single trajectory (no
        batch axes; stopped by a terminal event, the event's state last), the two ends of t_span for a
        batch (also of one).
    dense_output : bool
        Keep what :meth:`Solution.at` needs to give the state at any time of t_span.
    events : callable or list of callables, optional
        ``event(t, Omega, Gamma, g) -> (...)`` with scipy's ``terminal`` and ``direction`` attributes,
        called with the batch axes leading (see :mod:`liesuslov.integrators.events`; Omega is given as
        coordinates (..., d) on algebras other than so(n), such as se(2), se(3)); crossings in ``sol.events``.
    form : str
        Force a model form ("auto", "reduced", "eigenspace", "symmetric", "multiplier").
    first_step : float, optional
        Initial step of adaptive methods (default: Hairer's estimate).
    max_steps : int
        Per trajectory (accepted and rejected); a trajectory reaching it fails (status -1). The default 10⁷
        is seconds on the compiled kernel but can be an hour on the numpy solver (~2500 steps/s for one
        rkmk853 trajectory on so(3)): lower it for a numpy run that may not converge (a stiff scene).
    progress : bool
        Show a progress bar over the trajectories (needs tqdm): the numpy solver advances it as each
        trajectory ends, the compiled batch at its end.
    backend : {"auto", "numpy", "numba"}
        "auto" runs the compiled kernel (``liesuslov[fast]``) when numba is installed and the problem
        qualifies (a polynomial field — built-in potentials, gyroscopic term; a group part on a matrix
        algebra — so(n), se(2), se(3); events that are :class:`LinearEvent`), else the numpy solver;
        ``stats["backend"]`` says which ran and ``stats["backend_reason"]`` why. "numba" raises ValueError
        saying why it cannot run.
    reproject : bool
        Re-orthonormalise g (renormalise Gamma) every max(64, n) accepted steps, a correction far below
        the truncation error; False leaves the structure to the chart alone.

    Returns
    -------
    Solution
        ``t (N,)``, ``omega (N, ..., d)``, ``Omega``, ``Gamma (N, ..., n)`` or None, ``g (N, ..., m, m)`` or
        None, ``status (...)`` (0 reached t1, 1 terminal event, -1 failed; NaN after a trajectory stopped),
        ``events``, ``stats``.
    """
    is_model = system_is_model(system)
    # one test of the usual types first; the loops name the argument (~2 µs a call saved); reconstruct and form
    # are _initial_data's (which ensembles and the research tools call too)
    if not (type(method) is str and type(chart) is str and type(backend) is str):
        for name, value in (("method", method), ("chart", chart), ("backend", backend)):
            if not isinstance(value, str):
                raise TypeError(f"{name} must be a string, got {type(value).__name__}")
    if not (type(dense_output) is bool and type(reproject) is bool and type(progress) is bool):
        for name, value in (("dense_output", dense_output), ("reproject", reproject), ("progress", progress)):
            if not isinstance(value, (bool, np.bool_)):
                raise TypeError(f"{name} must be True or False, got {type(value).__name__}")
    if isinstance(h, (bool, np.bool_)):
        raise TypeError("h must be a positive number (the step size), got a bool")
    if method not in METHODS:
        raise ValueError(f"method must be one of {sorted(METHODS)}, got {method!r}")
    if chart not in CHARTS:
        raise ValueError(f"chart must be one of {CHARTS}, got {chart!r}")
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if isinstance(max_steps, (bool, np.bool_)) or not isinstance(max_steps, (int, np.integer)):
        raise TypeError(f"max_steps must be an integer, got {max_steps!r}" + (" (write 10_000_000, not 1e7)"
                                                                              if isinstance(max_steps, float) else ""))
    if max_steps < 1:
        raise ValueError(f"max_steps must be a positive integer, got {max_steps!r}")
    meth = METHODS[method]
    t0, t1 = check_t_span(t_span)
    # checked whether or not the method reads them: a bad value is a mistake either way
    rtol = check_positive(rtol, "rtol")
    atol = check_positive(atol, "atol")
    if first_step is not None:
        first_step = check_positive(first_step, "first_step")
    if meth.adaptive:
        step0 = 0.0
        if first_step is not None:
            step0 = first_step
        elif h is not None:
            step0 = check_positive(h, "h")
    else:
        if h is None:
            raise ValueError(f"h (the step size) is required by the fixed-step method {method!r}; "
                             "pass h=..., or use an adaptive method such as 'rkmk45'")
        step0 = check_positive(h, "h")
    te = check_t_eval(t_eval, t0, t1)
    model, x0, G0, g_init, batch_shape = _initial_data(system, is_model, Omega0, Gamma0, g0, reconstruct, form)
    plan = plan_for(meth.tableau, meth.error_scale)
    problem = _problem(model, plan, chart, x0, G0, g_init, batch_shape, t0, t1, meth.adaptive, step0, rtol, atol,
                       min(int(max_steps), _MAX_STEPS), te, events, bool(reproject))
    if te is None and batch_shape != ():  # a batch (also of one) reports the two ends; one trajectory every step
        problem.t_eval = np.array([t0, t1])
    solver, used, reason = _choose_solver(problem, backend)
    start = time.perf_counter()
    raw = _run(solver, problem, progress)
    wall = time.perf_counter() - start
    sol = _solution(raw, problem, batch_shape, method, chart, wall, reason)
    if dense_output:
        sol._dense = _Replay(problem, solver, batch_shape, method, chart)
    return sol


# ---------------------------------------------------------------------------------------------------------
def system_is_model(system) -> bool:
    """True for a model (:class:`ModelProtocol`), False for a :class:`SuslovSystem`; a TypeError naming
    ``system`` for anything else. (The SuslovSystem test first: a runtime Protocol check walks the class's
    attributes, ~20 µs a call.)"""
    if isinstance(system, SuslovSystem):
        return False
    if isinstance(system, ModelProtocol):
        return True
    raise TypeError(f"system must be a SuslovSystem (or a model such as system.model()), got {type(system).__name__}")


def _initial_data(system, is_model, Omega0, Gamma0, g0, reconstruct, form):
    """The model and the validated initial data: x0 (..., d), Gamma0, g0, the broadcast batch shape.

    The one reading of initial data: integrate, ensemble and the research tools call it (``is_model`` from
    :func:`system_is_model`); it also checks the types of ``reconstruct`` and ``form``, which choose the model.
    """
    if type(reconstruct) is not bool and not isinstance(reconstruct, np.bool_):
        raise TypeError(f"reconstruct must be True or False, got {type(reconstruct).__name__}")
    if type(form) is not str:
        raise TypeError(f"form must be a string, got {type(form).__name__}")
    reconstruct = bool(reconstruct)
    if is_model and form != "auto":
        raise ValueError(f"form={form!r} chooses the model of a SuslovSystem; system is already a model "
                         f"({type(system).__name__}): pass the system, or leave form out")
    if is_model:
        model = system
        if Gamma0 is not None and not model.has_gamma:
            raise ValueError("Gamma0 was given but this model has no Gamma; build it with system.model(gamma=True)")
    else:
        if Gamma0 is not None and not system.is_so:
            raise ValueError(f"Gamma0 must be None on {system.algebra.name}: the vertical Gamma exists only for a "
                             "body in SO(n)")
        model = system.model(gamma=True if Gamma0 is not None else None, form=form)
    alg = model.algebra
    if model.has_gamma and Gamma0 is None:
        raise ValueError("Gamma0 is required: the potential (or gyroscopic term) depends on Gamma; "
                         "pass a unit vector of shape (..., n)")
    x0 = omega_coordinates(alg, Omega0, "Omega0")
    # the constraints of the scene, also for the multiplier form (whose own subspace is the whole algebra)
    D = getattr(getattr(model, "system", None), "constraints", None) or model.subspace
    inside = D.contains(x0, 1e-9)
    if not (inside if inside.ndim == 0 else inside.all()):  # (ndarray.all: ~2 µs on one vector)
        dist = np.max(D.distance(x0))
        raise ValueError(f"Omega0 is not in the constraint subspace D (distance {dist:.3g}); "
                         "project it first, e.g. D.project(omega) with D = system.constraints")
    m = model.n
    shapes = [x0.shape[:-1]]
    G0_ = None
    if model.has_gamma:
        G0_ = unit_vectors(as_float_array(Gamma0, "Gamma0", ndim_min=1, tail=(m,)), "Gamma0",
                           tol=tolerance_for(Gamma0))
        shapes.append(G0_.shape[:-1])
    g_init = None
    if reconstruct:
        if m is None:
            raise ValueError(f"reconstruct=True needs a matrix representation of {alg.name}")
        if g0 is None:
            g_init = np.eye(m)
        else:
            g_init = as_float_array(g0, "g0", ndim_min=2, tail=(m, m))
            # accepted within 1e-8 of the group (float32: 16 ulps), then moved onto it (as Gamma0 is normalised):
            # the structure is exact from t0 on (to rounding), and the solution owns its copy (a later change of
            # the caller's array would change what sol.at replays)
            tol = tolerance_for(g0)  # float32 data is orthogonal only to its own rounding
            if alg.name.startswith("so("):
                check_rotations(g_init, "g0", tol=tol)
                g_init = orthonormalize(g_init)
            elif alg.name.startswith("se("):
                check_rigid_motions(g_init, "g0", tol=tol)
                g_init = g_init.copy()
                g_init[..., :-1, :-1] = orthonormalize(g_init[..., :-1, :-1])
            else:
                g_init = g_init.copy()
        shapes.append(g_init.shape[:-2])
    elif g0 is not None:
        raise ValueError("g0 was given but reconstruct=False; pass reconstruct=True to integrate g")
    try:  # (np.broadcast_shapes builds arrays: ~3 µs even for equal shapes)
        batch_shape = shapes[0] if shapes.count(shapes[0]) == len(shapes) else np.broadcast_shapes(*shapes)
    except ValueError as exc:
        raise ValueError(f"the batch axes of Omega0, Gamma0 and g0 do not broadcast: {shapes}") from exc
    if math.prod(batch_shape) == 0:
        names = ["Omega0"] + (["Gamma0"] if G0_ is not None else []) + (["g0"] if g_init is not None else [])
        empty = ", ".join(f"{name} {shape}" for name, shape in zip(names, shapes, strict=True)
                          if math.prod(shape) == 0 and shape != ())
        raise ValueError(f"the batch of initial data is empty (batch shape {batch_shape}: the batch axes of {empty}); "
                         "pass at least one initial state")
    return model, x0, G0_, g_init, batch_shape


def _problem(model, plan, chart, x0, G0, g_init, batch_shape, t0, t1, adaptive, step0, rtol, atol, max_steps, te,
             events, reproject) -> Problem:
    B = math.prod(batch_shape)
    k = int(model.k)
    xi = model.xi_from_coords(_batch_rows(x0, batch_shape, B))
    xi = np.ascontiguousarray(xi, dtype=float)
    m = int(model.n) if model.n is not None else 0
    gamma = np.zeros((B, 0))
    if g_init is not None:
        mode = "g"
        G = np.ascontiguousarray(_batch_rows(g_init, batch_shape, B, 2), dtype=float)
        if model.has_gamma:
            Gam = _batch_rows(G0, batch_shape, B)
            gamma = np.ascontiguousarray(np.matmul(G.reshape(B, m, m), Gam[:, :, None])[:, :, 0])  # g0 Gamma0
    elif model.has_gamma:
        mode = "gamma"
        G = np.ascontiguousarray(_batch_rows(G0, batch_shape, B), dtype=float)
    else:
        mode, G, m = "none", np.zeros((B, 0)), 0
    skew = model.algebra.name.startswith("so(")
    q = G.shape[1]
    problem = Problem(model=model, mode=mode, chart=chart if mode != "none" else None, kind=None, skew=skew,
                      plan=plan, k=k, m=m, q=q, B=B, xi0=xi, G0=G, gamma=gamma, t0=t0, t1=t1, adaptive=adaptive,
                      h=float(step0), rtol=float(rtol), atol=float(atol), max_steps=max_steps, t_eval=te,
                      reproject=reproject, batch_shape=tuple(batch_shape))
    _add_events(problem, events, batch_shape)
    return problem


def _batch_rows(a: np.ndarray, batch_shape: tuple, B: int, tail: int = 1) -> np.ndarray:
    """``a`` (..., *tail axes) broadcast to the batch and flattened to (B, prod(tail axes)) (no broadcast when
    ``a`` already has the batch's shape: ~5 µs a call on small arrays)."""
    lead, rest = a.shape[:a.ndim - tail], a.shape[a.ndim - tail:]
    if lead != tuple(batch_shape):
        a = np.broadcast_to(a, tuple(batch_shape) + rest)
    return a.reshape(B, math.prod(rest))


def _add_events(P: Problem, events, batch_shape) -> None:
    """Normalise ``events`` into the problem: flags, and the linear form of each :class:`LinearEvent`."""
    if events is None:
        return
    evs = list(events) if isinstance(events, (list, tuple)) else [events]
    flags = [event_flags(e) for e in evs]
    P.events = evs
    P.event_terminal = np.array([int(f[0]) for f in flags], dtype=np.int64)
    P.event_direction = np.array([f[1] for f in flags], dtype=np.int64)
    W = np.asarray(P.model.omega_coords(np.eye(P.k)), dtype=float)  # (k, d): omega = xi @ W
    lin = []
    for i, e in enumerate(evs):
        if not isinstance(e, LinearEvent):
            lin.append(None)
            continue
        n = P.model.n
        for name, c, tail in (("Gamma", e.Gamma, (n,)), ("g", e.g, (P.m, P.m))):
            if c is not None and n is not None and (c.ndim < len(tail) or c.shape[c.ndim - len(tail):] != tail):
                raise ValueError(f"events[{i}]: LinearEvent {name} coefficients must have shape (..., "
                                 f"{', '.join(map(str, tail))}), got {c.shape}")
        heads = [c.shape[:c.ndim - core] for c, core in ((e.omega, 1), (e.Gamma, 1), (e.g, 2)) if c is not None]
        try:  # (a coefficient with more batch axes than the batch broadcasts, but not *to* the batch)
            if np.broadcast_shapes(*heads, np.shape(e.offset), batch_shape) != tuple(batch_shape):
                raise ValueError
        except ValueError:
            raise ValueError(f"events[{i}]: the batch axes of the LinearEvent's coefficients and offset "
                             f"({', '.join(map(str, heads + [np.shape(e.offset)]))}) do not broadcast to the batch "
                             f"shape {tuple(batch_shape)}: one plane for all, or one per trajectory") from None
        coef = np.zeros(batch_shape + (P.k + P.q,))
        if e.omega is not None:
            if e.omega.shape[-1] != W.shape[1]:
                raise ValueError(f"LinearEvent omega coefficients must have {W.shape[1]} components, got "
                                 f"{e.omega.shape[-1]}")
            coef[..., : P.k] += np.broadcast_to(e.omega @ W.T, batch_shape + (P.k,))
        if e.Gamma is not None:
            if P.mode == "gamma":
                coef[..., P.k:] += np.broadcast_to(e.Gamma, batch_shape + (P.q,))
            elif P.mode == "g" and P.gamma.shape[1]:
                gam = P.gamma.reshape(batch_shape + (P.m,))
                bG = np.broadcast_to(e.Gamma, batch_shape + (P.m,))
                coef[..., P.k:] += (gam[..., :, None] * bG[..., None, :]).reshape(batch_shape + (P.q,))
            else:
                raise ValueError("a LinearEvent on Gamma needs a scene with Gamma (pass Gamma0)")
        if e.g is not None:
            if P.mode != "g":
                raise ValueError("a LinearEvent on g needs reconstruct=True")
            coef[..., P.k:] += np.broadcast_to(e.g, batch_shape + (P.m, P.m)).reshape(batch_shape + (P.q,))
        off = np.broadcast_to(e.offset, batch_shape)
        lin.append((np.ascontiguousarray(coef.reshape(P.B, -1)), np.ascontiguousarray(off.reshape(P.B), dtype=float)))
    P.event_linear = lin


@functools.cache
def _kernel():
    """The compiled kernel's package, imported on first use (it imports numba: ~0.5 s); ImportError without
    numba. (Cached: an import statement in the front door costs ~1 µs a call.)"""
    from . import kernel

    return kernel


@functools.cache
def _numpy_solver():
    """The numpy reference solver's module, imported on first use (~15 ms of ``import liesuslov`` saved)."""
    from . import solve_numpy

    return solve_numpy


def _choose_solver(P: Problem, backend: str):
    """``(solver module, name, reason)``: the compiled kernel when allowed and possible, else numpy."""
    solve_numpy = _numpy_solver()
    if backend == "numpy":
        return solve_numpy, "numpy", "backend='numpy' was asked for"
    try:
        kernel = _kernel()
    except ImportError as exc:  # numba is not installed
        if backend == "numba":
            raise ValueError("backend='numba' needs numba: pip install 'liesuslov[fast]'") from exc
        return solve_numpy, "numpy", "numba is not installed (pip install 'liesuslov[fast]')"
    try:
        P.kind = kernel.kind_for(P.model, P.mode, P.chart)
        kernel.check(P)
    except ValueError as exc:
        P.kind = None
        if backend == "numba":
            raise ValueError(f"backend='numba' cannot run this problem: {exc}") from exc
        return solve_numpy, "numpy", str(exc)
    return kernel, "numba", "compiled kernel"


def _run(solver, P: Problem, progress: bool) -> RawResult:
    """``solver.solve(P)``; with ``progress`` a bar over the trajectories (the numpy solver reports each one
    as it ends; the compiled batch, which has no Python per trajectory, reports them all at its end)."""
    if not progress:
        return solver.solve(P)
    from . import solve_numpy

    with progress_bar(P.B, "trajectory", leave=False) as bar:
        if solver is solve_numpy:
            return solver.solve(P, done=bar.update)
        raw = solver.solve(P)
        bar.update(P.B)
        return raw


def _solution(raw: RawResult, P: Problem, batch_shape, method, chart, wall, reason) -> Solution:
    """Turn a solver's flat result into the user's arrays (time axis first, then the batch axes)."""
    model = P.model
    if P.t_eval is None and raw.status[0] == STATUS_TERMINAL:
        raw = _with_stop_point(raw, P)
    N = raw.t.shape[0]
    xi = raw.xi.reshape((N,) + tuple(batch_shape) + (P.k,))
    omega = model.omega_coords(xi)
    if np.count_nonzero(raw.status):  # the components outside D are 0, not NaN, after a stop: NaN as well
        omega = np.where(np.isnan(xi).any(axis=-1, keepdims=True), np.nan, omega)
    g, Gamma = _group_arrays(P, raw.G, (N,) + tuple(batch_shape), lambda: np.arange(P.B).reshape(batch_shape))
    status = raw.status.reshape(batch_shape)
    stats = {"nfev": _total(raw.nfev), "steps": _total(raw.steps), "rejected": _total(raw.rejected),
             "method": method, "chart": P.chart, "form": model.form, "backend": raw.backend,
             "backend_reason": reason, "kernel": P.kind,
             "state_dim": P.k + P.q, "batch": P.B, "wall_time": wall,
             "trajectory_nfev": raw.nfev.reshape(batch_shape), "trajectory_steps": raw.steps.reshape(batch_shape),
             "trajectory_rejected": raw.rejected.reshape(batch_shape), "t_stop": raw.t_stop.reshape(batch_shape),
             "failure": raw.failure.reshape(batch_shape)}
    records = []
    for e in range(P.n_events):
        idx, t_e, xi_e, G_e = raw.event_index[e], raw.event_t[e], raw.event_xi[e], raw.event_G[e]
        if P.direction < 0 and idx.size > 1:
            # both solvers give each trajectory's crossings in the order met: decreasing t on a backward run;
            # the record is sorted by (index, t) (API.md), as a forward run's is by construction
            order = np.lexsort((t_e, idx))
            idx, t_e, xi_e, G_e = idx[order], t_e[order], xi_e[order], G_e[order]
        ge, Ge = _group_arrays(P, G_e[:, None, :], (idx.size, 1), lambda idx=idx: idx[:, None])
        records.append(EventRecord(t=t_e, index=idx, omega=model.omega_coords(xi_e),
                                   Gamma=None if Ge is None else Ge[:, 0], g=None if ge is None else ge[:, 0],
                                   n=model.n, algebra_name=model.algebra.name))
    return Solution(t=np.asarray(raw.t, dtype=float), xi=xi, omega=omega, Gamma=Gamma, g=g, stats=stats,
                    status=status, message=run_message(raw.status, raw.t_stop, raw.failure),
                    n=model.n, algebra_name=model.algebra.name,
                    events=records)


def _with_stop_point(raw: RawResult, P: Problem) -> RawResult:
    """One trajectory reported at every step, stopped by a terminal event: its last point is the event's (the
    state at ``t_stop``, as scipy's ``solve_ivp`` ends ``sol.t`` there)."""
    t_stop = raw.t_stop[0]
    if raw.t.size and raw.t[-1] == t_stop:
        return raw
    for e in np.flatnonzero(P.event_terminal):
        at = np.flatnonzero(raw.event_t[e] == t_stop)
        if at.size:
            i = at[0]
            return replace(raw, t=np.append(raw.t, t_stop),
                           xi=np.concatenate([raw.xi, raw.event_xi[e][i].reshape(1, 1, -1)]),
                           G=np.concatenate([raw.G, raw.event_G[e][i].reshape(1, 1, -1)]))
    return raw


def _total(a: np.ndarray) -> int:
    """The sum of a count over the batch, as an int (a reduction of one entry costs ~1.5 µs)."""
    return int(a[0]) if a.size == 1 else int(a.sum())


def _group_arrays(P: Problem, G: np.ndarray, lead: tuple, which):
    """``(g, Gamma)`` from the flat group part G (..., B, q) of the trajectories ``which()`` (lead-shaped; a
    callable, as only Gamma = g^T gamma needs them)."""
    if P.mode == "g":
        g = G.reshape(lead + (P.m, P.m))
        Gamma = None
        if P.model.has_gamma:
            gam = P.gamma[np.asarray(which())]  # (…, n) per trajectory, broadcast over time
            Gamma = body_vector(g, gam)
        return g, Gamma
    if P.mode == "gamma":
        return None, G.reshape(lead + (P.q,))
    return None, None


class _Replay:
    """Dense output: the solve again with the asked times as t_eval (the steps do not depend on t_eval)."""

    def __init__(self, problem: Problem, solver, batch_shape, method, chart) -> None:
        self.problem, self.solver, self.batch_shape = problem, solver, batch_shape
        self.method, self.chart = method, chart

    def __getstate__(self) -> dict:
        # a module does not pickle: the solver by name, imported again on loading (a pickled Solution keeps
        # its dense output wherever its problem — model, initial data, events — pickles)
        return {**self.__dict__, "solver": "numba" if self.solver is not _numpy_solver() else "numpy"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self.solver = _numpy_solver() if state["solver"] == "numpy" else _kernel()

    def __call__(self, t) -> Solution:
        P = self.problem
        ts = np.array(as_float_array(t, "t"), dtype=float)  # the Solution's own t, not a view of the caller's
        if ts.ndim > 1:
            raise ValueError(f"sol.at(t): t must be a time or a 1-D array of times (M,), got shape {ts.shape}")
        ts = ts.reshape(-1)
        lo, hi = min(P.t0, P.t1), max(P.t0, P.t1)
        if ts.size == 0:
            raise ValueError("sol.at(t): t is empty; pass at least one time within t_span")
        if ts.min() < lo or ts.max() > hi:
            raise ValueError(f"sol.at(t): every t must lie within t_span = ({P.t0}, {P.t1})")
        order = np.argsort(P.direction * ts, kind="stable")
        uniq, inverse = np.unique(P.direction * ts[order], return_inverse=True)
        Q = replace(P, t_eval=P.direction * uniq)
        raw = self.solver.solve(Q)
        sol = _solution(raw, Q, self.batch_shape, self.method, self.chart, 0.0, "dense output")
        take = np.empty(ts.size, dtype=np.int64)
        take[order] = inverse
        def pick(a):
            return None if a is None else a[take]

        out = Solution(t=ts, xi=sol.xi[take], omega=sol.omega[take], Gamma=pick(sol.Gamma), g=pick(sol.g),
                       stats=sol.stats, status=sol.status, message=sol.message, n=sol.n,
                       algebra_name=sol.algebra_name)
        return out


# ---------------------------------------------------------------------------------------------------------
