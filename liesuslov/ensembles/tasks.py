"""The task a worker runs: one chunk integrated (and reduced) as one ``integrate`` call."""

from __future__ import annotations

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

    init = task.init if task.sampler is None else {
        **(task.init or {}), **_draw_range(task.sampler, task.seed_parts, task.start, task.stop, task.block)}
    c = task.stop - task.start
    sol = integrate(task.system, init["Omega0"], task.t_span, Gamma0=init.get("Gamma0"), g0=init.get("g0"),
                    t_eval=task.t_eval, **task.options)
    sol = _apply_reduce(sol, task.reduce)
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


def _batch_ndim(a: np.ndarray, sol) -> int:
    """Number of batch axes of a solution array (between the time axis and the component axes)."""
    return sol.omega.ndim - 2  # omega is (N, ..., d): the batch axes are shared by all arrays


def _apply_reduce(sol, reduce):
    if reduce is None:
        return sol
    if reduce == "final":
        from dataclasses import replace

        return replace(sol, t=sol.t[-1:], xi=sol.xi[-1:], omega=sol.omega[-1:],
                       Gamma=None if sol.Gamma is None else sol.Gamma[-1:], g=None if sol.g is None else sol.g[-1:])
    return reduce(sol)
