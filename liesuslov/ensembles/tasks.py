"""The task a worker runs: one chunk integrated (and reduced) as one ``integrate`` call."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .constants import (
    _ARRAYS,
    _EVENT,
    _EVENT_FIELDS,
    _STAT,
    _USER_ERRORS,
    SAMPLER_BLOCK,
)
from .sampling import _draw_range


# ====================================================================== the task run on a worker
@dataclass
class _Task:
    index: int
    start: int
    stop: int
    system: Any
    t_span: tuple[float, float]
    t_eval: np.ndarray
    options: dict
    init: dict | None = None  # given data for this chunk, leading axis stop - start
    sampler: Any = None
    seed_parts: Any = None
    block: int = SAMPLER_BLOCK
    reduce: Any = None


def _run_chunk(task: _Task) -> dict[str, Any]:
    """Integrate one chunk (on a worker): the arrays with one flat batch axis, status per trajectory.

    Bad input (ValueError/TypeError) propagates, to be raised by :func:`ensemble`. Any other exception of
    the computation is deterministic (running it again gives it again), so it comes back as a result,
    ``{"error": ...}``, and the chunk's trajectories get status -1 without a retry; only a failure of the
    executor itself (a lost worker, a broken pool) reaches :func:`ensemble` as an exception and is retried.
    """
    try:
        return _integrate_chunk(task)
    except _USER_ERRORS:
        raise
    except Exception as exc:  # noqa: BLE001 - reported per chunk (status -1, message), not a crash
        import traceback

        return {"error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc()}


def _integrate_chunk(task: _Task) -> dict[str, Any]:
    from ..integrators import integrate

    c = task.stop - task.start
    init = dict(task.init or {})
    if task.sampler is not None:
        drawn = _draw_range(task.sampler, task.seed_parts, task.start, task.stop, task.block)
        drawn["Omega0"] = _sampled_coordinates(task.system, drawn["Omega0"], c)
        init.update(drawn)
    events = task.options.get("events")
    # Omega0 is given as coordinates (c, d). integrate reads a trailing (m, m) block that lies in the image of the
    # representation as one matrix: on so(3) and se(2) (d = m = 3) a chunk of 3 trajectories would be (3, 3),
    # and 3 coordinate vectors that happen to form such a matrix (three zero states, say) would be read as one.
    # That chunk gets a batch (3, 1), unambiguous, and its solution is flattened back to (3,) below.
    alg = task.system.algebra
    column = c == alg.dim and c == getattr(alg, "matrix_size", None)
    if column:
        init = {k: v[:, None] for k, v in init.items()}
        events = _events_column(events)
    options = dict(task.options) if events is None else {**task.options, "events": events}
    sol = integrate(task.system, init["Omega0"], task.t_span, Gamma0=init.get("Gamma0"), g0=init.get("g0"),
                    t_eval=task.t_eval, **options)
    if column:
        sol = _flat_batch(sol, c)
    sol = _apply_reduce(sol, task.reduce, c)
    out: dict[str, Any] = {"t": np.asarray(sol.t, dtype=float)}
    for name in _ARRAYS:
        a = getattr(sol, name, None)
        if a is not None:
            out[name] = np.asarray(a).reshape((a.shape[0], c) + a.shape[1 + _batch_ndim(a, sol):])
    # status: an int per trajectory (the per-trajectory integrate), or one int for the whole batch
    out["status"] = np.broadcast_to(np.asarray(sol.status, dtype=np.int64).reshape(-1) if np.ndim(sol.status)
                                    else np.asarray(sol.status, dtype=np.int64), (c,)).copy()
    # event crossings, with the flat index of the whole batch (the chunk's flat index + its start)
    for j, rec in enumerate(getattr(sol, "events", None) or []):
        for f in _EVENT_FIELDS:
            v = getattr(rec, f)
            if v is not None:
                out[f"{_EVENT}{j}__{f}"] = np.asarray(v) + task.start if f == "index" else np.asarray(v)
    # per-trajectory statistics (arrays of the batch shape) travel as arrays; the rest in the JSON meta
    stats = {}
    for k, v in sol.stats.items():
        if isinstance(v, np.ndarray) and v.size == c and v.ndim >= 1:
            out[_STAT + k] = v.reshape(c)
        else:
            stats[k] = v
    out["meta"] = {"stats": stats, "message": str(getattr(sol, "message", "")), "n": sol.n,
                   "algebra_name": sol.algebra_name, "events": len(getattr(sol, "events", None) or [])}
    return out


def _sampled_coordinates(system, Omega0, c: int) -> np.ndarray:
    """A sampler's Omega0 (c, d) coordinates or (c, m, m) matrices as coordinates (c, d), read by integrate's rule.

    The leading axis is the batch (one state per drawn trajectory): a singleton axis after it keeps integrate's
    reading (:func:`~liesuslov.algebra.elements.omega_coordinates`) from taking 3 coordinate vectors on so(3) or
    se(2) for one matrix.
    """
    from ..algebra.elements import omega_coordinates

    alg = system.algebra
    x = omega_coordinates(alg, Omega0[:, None], "Omega0 (drawn by the sampler)")
    if x.shape != (c, 1, alg.dim):
        m = getattr(alg, "matrix_size", None)
        mats = f" or (size, {m}, {m}) matrices of {alg.name}" if m is not None else ""
        raise ValueError(f"sampler must return 'Omega0' of shape (size, {alg.dim}) coordinates{mats}, got "
                         f"{Omega0.shape} for size {c}")
    return x[:, 0]


def _events_column(events):
    """``events`` for a chunk integrated with the batch (c, 1): per-trajectory LinearEvent rows as (c, 1, ...)."""
    from ..integrators.events import LinearEvent

    def col(a, core: int):
        return a if a is None or a.ndim <= core else a[:, None]

    def one(e):
        if not isinstance(e, LinearEvent):
            return e
        return LinearEvent(omega=col(e.omega, 1), Gamma=col(e.Gamma, 1), g=col(e.g, 2), offset=col(e.offset, 0),
                           terminal=e.terminal, direction=e.direction)

    if events is None:
        return None
    return [one(e) for e in events] if isinstance(events, (list, tuple)) else one(events)


def _flat_batch(sol, c: int):
    """A solution of the batch (c, 1) as one of (c,): the arrays, the status and the per-trajectory statistics."""
    from dataclasses import replace

    def flat(a, tail: int):
        return None if a is None else a.reshape((a.shape[0], c) + a.shape[a.ndim - tail:])

    stats = {k: (v.reshape(c) if isinstance(v, np.ndarray) and v.shape == (c, 1) else v) for k, v in sol.stats.items()}
    status = np.asarray(sol.status).reshape(c) if np.ndim(sol.status) else sol.status
    return replace(sol, xi=flat(sol.xi, 1), omega=flat(sol.omega, 1), Gamma=flat(sol.Gamma, 1), g=flat(sol.g, 2),
                   status=status, stats=stats)


def _batch_ndim(a: np.ndarray, sol) -> int:
    """Number of batch axes of a solution array (between the time axis and the component axes)."""
    return sol.omega.ndim - 2  # omega is (N, ..., d): the batch axes are shared by all arrays


def _apply_reduce(sol, reduce, c: int):
    """``reduce`` applied to a chunk's solution (c trajectories); a callable must give a Solution of the c."""
    if reduce is None:
        return sol
    if reduce == "final":
        from dataclasses import replace

        return replace(sol, t=sol.t[-1:], xi=sol.xi[-1:], omega=sol.omega[-1:],
                       Gamma=None if sol.Gamma is None else sol.Gamma[-1:], g=None if sol.g is None else sol.g[-1:])
    from ..integrators import Solution

    out = reduce(sol)
    # bad input, raised by ensemble at once (not a numerical failure of every chunk, status -1)
    name = getattr(reduce, "__name__", type(reduce).__name__)
    if not isinstance(out, Solution):
        raise TypeError(f"reduce must return a Solution (e.g. dataclasses.replace(sol, ...)), but reduce={name} "
                        f"returned {type(out).__name__}")
    if np.ndim(out.omega) < 2 or math.prod(out.omega.shape[1:-1]) != c:
        raise ValueError(f"reduce must keep the chunk's trajectories (batch axes {sol.omega.shape[1:-1]}), but "
                         f"reduce={name} returned omega of shape {np.shape(out.omega)}")
    return out
