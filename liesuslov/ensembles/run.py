"""The front door :func:`ensemble`: split, submit, retry lost chunks, collect, merge."""

from __future__ import annotations

import inspect
import math
import os
import pickle
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .._progress import progress_bar
from .._validation import check_t_eval, check_t_span
from ..integrators.integrate import _initial_data, system_is_model
from ..integrators.problem import run_message
from .checks import _as_given, _naming, _nonneg_int, _positive_int
from .constants import (
    _ARRAYS,
    _CORE,
    _EVENT,
    _STAT,
    _USER_ERRORS,
    FORMAT,
    MANIFEST,
    REDUCTIONS,
    SAMPLER_BLOCK,
)
from .executors import _check_running, _n_workers, _pickles, _submit, _wait_first
from .result import Ensemble
from .sampling import _seed_parts
from .store import _claim_store, _merge_stats, _run_on_disk, _write_manifest, _write_shard, open_ensemble
from .tasks import _Task


# ====================================================================== the front door
def ensemble(system, Omega0=None, t_span=None, *, Gamma0=None, g0=None, t_eval=None, chunk_size: int | None = None,
             executor=None, store=None, sampler: Callable | None = None, n: int | None = None, seed=None,
             reduce: str | Callable | None = None, progress: bool = False, retries: int = 2,
             max_in_flight: int | None = None, overwrite: bool = False, **options) -> Ensemble:
    """Integrate a batch of initial data chunk by chunk on an executor: the numbers of one :func:`integrate`.

    Parameters
    ----------
    system : SuslovSystem or Model
        Must pickle (systems built from module-level callables do) unless ``executor`` is None or a
        :class:`concurrent.futures.ThreadPoolExecutor`: the threads of this process share it as it is, so
        there a potential built from lambdas works. Every other executor (a process pool, loky, an MPI
        pool, a Dask client, or one not known here) is taken to pickle what it is sent; the same holds
        for ``sampler`` and ``reduce``, and what does not pickle is a TypeError naming it before anything runs.
    Omega0 : array_like, shape (..., m, m) or (..., d), optional
        Initial data as for :func:`~liesuslov.integrate`, read and checked once on the whole batch by its
        code (representation matrices on so(n), se(2), se(3), or coordinates, by its rule); the batch axes of
        ``Omega0``, ``Gamma0`` and ``g0`` broadcast together. None with a ``sampler``.
    t_span : (t0, t1)
    Gamma0 : array_like, shape (..., n), optional
    g0 : array_like, shape (..., m, m), optional
        Only with ``reconstruct=True`` (an option of integrate).
    t_eval : array_like, shape (N,), optional
        Output times; default the two ends of ``t_span``.
    chunk_size : int, optional
        Trajectories per task (default: a quarter of the batch per worker, at most 4096; the whole
        batch in one chunk when ``executor`` and ``store`` are None). It does not change the numbers.
    executor : None, concurrent.futures.Executor or dask.distributed.Client
        None runs the chunks here, one after the other; a ``ThreadPoolExecutor`` on its threads, nothing
        pickled (the compiled kernel releases the GIL; numpy code on small arrays mostly holds it).
    store : str or PathLike, optional
        A directory the results stream to (created; an existing store is refused unless
        ``overwrite=True``; ``""`` is refused: pass ``"."`` for the current directory). An existing directory
        that holds no store is written into: its own files stay, and even ``overwrite=True`` only ever deletes
        a store's ``chunk-*.npz`` files and manifest. The returned Ensemble then reads from it lazily.
    sampler : callable, optional
        A module-level callable (or :class:`Perturbation`) ``sampler(rng, size) -> dict`` with
        ``"Omega0"`` (size, ...) and optionally ``"Gamma0"``, ``"g0"``, called on the workers: block ``j``
        of :data:`SAMPLER_BLOCK` trajectories is drawn with ``default_rng(SeedSequence(seed).spawn(...)[j])``,
        so the run is the same whatever the executor, the number of workers and the chunk size.
        ``Gamma0``/``g0`` given here (one value each) are used when the sampler does not return them.
    n : int
        Number of trajectories drawn by ``sampler`` (only with a sampler).
    seed : int >= 0, sequence of them, SeedSequence or None
        Root of the sampler's seeds (None: fresh entropy, recorded in ``stats["seed"]``).
    reduce : None, "final" or callable
        Done on the workers before results travel: None keeps every output time; ``"final"`` keeps
        only the last one (time axis of length 1; NaN for a trajectory a terminal event stopped
        earlier, as in the Solution); a module-level callable ``reduce(sol) -> Solution`` (same batch
        axes, the same times for every chunk) anything else; returning anything but a Solution is a
        TypeError naming ``reduce``, raised by the first chunk that does.
    progress : bool
        A progress bar over trajectories (needs tqdm: ``liesuslov[progress]``).
    retries : int
        Times a chunk whose task errored (lost worker, broken pool) is resubmitted before its
        trajectories get status -1. Bad input (ValueError/TypeError from a task) is raised at once.
    max_in_flight : int, optional
        Chunks submitted but not yet collected (default 3 per worker): bounds memory.
    overwrite : bool
        Replace an existing store (one run writes a store at a time: see the RuntimeError below).
    **options
        Passed to :func:`~liesuslov.integrate` (``method``, ``h``, ``rtol``, ``atol``, ``reconstruct``,
        ``chart``, ``backend``, ``events``, ...); with ``events`` (callables that pickle, as ``system``) the
        crossings come back in ``ens.events`` as in a Solution. ``dense_output=True`` is refused (TypeError):
        nothing but the arrays at ``t_eval`` comes back.

    Returns
    -------
    Ensemble
        ``t`` (N,), ``omega`` (N, ..., d), ``Omega``, ``Gamma``, ``g``, ``status`` (...), ``success``,
        ``stats``, ``events``; the batch axes are those of the initial data (``(n,)`` with a sampler).

    Raises
    ------
    ValueError, TypeError
        Bad arguments, naming the argument (also a bad initial state drawn on a worker); a store path that
        cannot be a directory is a ValueError naming ``store``, and so is a store another run claimed first
        (two runs started on one directory at once).
    OSError
        A store directory the system will not let this process write (its class, ``store`` named).
    RuntimeError
        The store was replaced by another run (``overwrite=True``) while this one ran.
    """
    from ..integrators import integrate

    t0, t1 = check_t_span(t_span)
    t_eval = np.array([t0, t1]) if t_eval is None else check_t_eval(t_eval, t0, t1)
    is_model = system_is_model(system)  # integrate's test (and its TypeError)
    allowed = set(inspect.signature(integrate).parameters) - {"system", "Omega0", "t_span", "Gamma0", "g0", "t_eval",
                                                              "progress"}
    unknown = sorted(set(options) - allowed)
    if unknown:
        raise TypeError(f"unknown option(s) {unknown} for integrate; allowed: {sorted(allowed)}")
    if options.get("dense_output"):
        raise TypeError("dense_output=True is not supported by ensemble (only the arrays at t_eval come back); "
                        "pass the times you need as t_eval")
    if not isinstance(progress, (bool, np.bool_)):
        raise TypeError(f"progress must be True or False, got {type(progress).__name__}")
    retries = _nonneg_int(retries, "retries")
    if isinstance(executor, type):  # the class has a submit too, an unbound one
        raise TypeError(f"executor must be an executor instance, got the class {executor.__name__}; pass "
                        f"{executor.__name__}(...), e.g. {executor.__name__}(max_workers=2), and shut it down after")
    if executor is not None and not callable(getattr(executor, "submit", None)):
        raise TypeError(f"executor must be None, a concurrent.futures.Executor or a dask.distributed.Client "
                        f"(something with submit), got {type(executor).__name__}")
    _check_running(executor)
    if reduce is not None and not callable(reduce) and reduce not in REDUCTIONS:
        raise ValueError(f"reduce must be None, one of {list(REDUCTIONS)} or a module-level callable "
                         f"reduce(sol) -> Solution, got {reduce!r}")

    init: dict[str, np.ndarray] = {}
    seed_parts = None
    if sampler is not None:
        if not callable(sampler):
            raise TypeError(f"sampler must be a callable sampler(rng, size) -> dict, got {type(sampler).__name__}")
        if Omega0 is not None:
            raise ValueError("Omega0 must be None when a sampler draws the initial data (sampler=...)")
        if n is None:
            raise ValueError("n (the number of trajectories to draw) is required with sampler=...")
        batch_shape = (_positive_int(n, "n"),)
        seed_parts = _seed_parts(seed)
        # the drawn states are checked by integrate on the workers; these two by each chunk's integrate too
        for key, v in (("Gamma0", Gamma0), ("g0", g0)):
            if v is not None:
                init[key] = _as_given(v, key, _CORE[key])
        _broadcast_batch(init, batch_shape)
    else:
        if Omega0 is None:
            raise ValueError("Omega0 is required (or draw initial data with sampler=... and n=...)")
        if n is not None or seed is not None:
            raise ValueError("n and seed are used only with sampler=...; the batch is the shape of Omega0")
        init, batch_shape = _given_initial_data(system, is_model, Omega0, Gamma0, g0, options)
    cores = {k: _CORE[k] for k in init}
    B = math.prod(batch_shape)
    if B == 0:
        raise ValueError(f"the batch of initial data is empty (batch shape {batch_shape})")
    _check_bookkeeping(B)

    W = _n_workers(executor)
    if chunk_size is None:
        chunk_size = B if (executor is None and store is None) else max(1, min(4096, -(-B // (4 * W))))
    chunk_size = _positive_int(chunk_size, "chunk_size")
    max_in_flight = 3 * W if max_in_flight is None else _positive_int(max_in_flight, "max_in_flight")
    bounds = [(a, min(a + chunk_size, B)) for a in range(0, B, chunk_size)]

    if _pickles(executor):  # a clear error here rather than a pickling traceback from a worker
        for name, obj in (("system", system), ("sampler", sampler), ("reduce", reduce),
                          ("events", options.get("events"))):
            try:
                pickle.dumps(obj)
            except Exception as exc:  # noqa: BLE001 - any pickling failure
                raise TypeError(f"{name} must pickle to be sent to the workers of a {type(executor).__name__} "
                                f"({exc}); build it from module-level functions and classes (no lambdas or "
                                "closures), or run with executor=None or a concurrent.futures.ThreadPoolExecutor, "
                                "which do not pickle") from exc

    # what is known before any chunk runs: in the manifest from the start, so a partial store keeps it
    run_stats: dict[str, Any] = {
        "chunks": len(bounds), "chunk_size": chunk_size, "batch": B,
        "executor": "none" if executor is None else type(executor).__name__,
        "reduce": reduce if reduce is None or isinstance(reduce, str) else getattr(reduce, "__name__", repr(reduce))}
    if seed_parts is not None:
        run_stats["seed"] = seed_parts[0]
    root = None
    if store is not None:
        root = _prepare_store(store, overwrite)
    run_id = uuid.uuid4().hex  # the store's manifest and every chunk file it writes carry it
    manifest = {"format": FORMAT, "run": run_id, "batch_shape": list(batch_shape), "bounds": bounds,
                "complete": False, "chunk_size": chunk_size, "t_span": [t0, t1], "stats": run_stats}
    if root is not None:
        try:
            _claim_store(root, manifest)
        except FileExistsError:
            raise ValueError(f"store {str(root)!r} already holds an ensemble: another run started on it at the same "
                             "time; pass another directory (or overwrite=True once that run is over)") from None
        except OSError as exc:  # a directory that exists but takes no files (permissions, a read-only disk)
            raise _store_error(root, exc) from exc

    def make_task(i: int) -> _Task:
        a, b = bounds[i]
        chunk = {k: _take(v, cores[k], batch_shape, a, b) for k, v in init.items()}
        opts = dict(options)
        if opts.get("events") is not None:
            opts["events"] = _chunk_events(opts["events"], batch_shape, a, b)
        return _Task(i, a, b, system, (t0, t1), t_eval, opts, chunk or None, sampler, seed_parts,
                     SAMPLER_BLOCK, reduce)

    bar = _progress_bar(progress, B)
    started = time.perf_counter()
    collected: dict[str, Any] = {"arrays": None, "status": np.full(B, -1, dtype=np.int64), "t": None,
                                 "tails": None, "meta": None, "stats": [], "failed": [], "retries": 0,
                                 "traj_stats": {}, "events": [],
                                 # what the run's message reads, whatever the store (16 bytes a trajectory)
                                 "ends": {"t_stop": np.full(B, np.nan), "failure": np.zeros(B, dtype=np.int64)},
                                 "run": run_id}
    try:
        _run_all(executor, make_task, bounds, retries, max_in_flight, collected, root, bar)
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - started

    stats = _merge_stats(collected["stats"])
    stats.update(run_stats)
    stats.update({"failed_chunks": collected["failed"], "retries": collected["retries"], "wall_time": wall})
    meta = collected["meta"] or {}
    if collected["failed"]:
        message = (f"{len(collected['failed'])} of {len(bounds)} chunks failed (status -1): "
                   f"{collected['failed'][0]['error']}")
    else:  # the whole batch's, as one integrate call would say it (not one chunk's)
        message = run_message(collected["status"], collected["ends"]["t_stop"], collected["ends"]["failure"])
    t_out = collected["t"] if collected["t"] is not None else (t_eval[-1:] if reduce == "final" else t_eval)
    tails = collected["tails"] if collected["tails"] is not None else _fallback_tails(system, init, sampler, options)
    ev = options.get("events")
    n_events = 0 if ev is None else (len(ev) if isinstance(ev, (list, tuple)) else 1)
    if root is not None:
        manifest.update({"complete": True, "t": t_out, "tails": {k: list(v) for k, v in tails.items()},
                         "meta": {"n": meta.get("n"), "algebra_name": meta.get("algebra_name", ""),
                                  "events": n_events},
                         "stats": stats, "message": message,
                         "trajectory_stats": {k: v.dtype.str for k, v in collected["traj_stats"].items()}})
        _check_still_ours(root, run_id)
        _write_manifest(root, manifest)
        ens = open_ensemble(root)
        ens.message = message
        return ens
    if collected["arrays"] is not None:
        arrays = {k: v.reshape((v.shape[0],) + batch_shape + tails[k]) for k, v in collected["arrays"].items()}
    else:  # every chunk failed: NaN arrays of the shapes a success would have had
        arrays = {k: np.full((t_out.size,) + batch_shape + v, np.nan) for k, v in tails.items()}
    return Ensemble(t=t_out, batch_shape=batch_shape, bounds=bounds, tails=tails, stats=stats, n=meta.get("n"),
                    algebra_name=meta.get("algebra_name", ""), message=message, arrays=arrays,
                    status=collected["status"].reshape(batch_shape), traj_stats=collected["traj_stats"],
                    n_events=n_events, event_parts=collected["events"])


def _run_all(executor, make_task, bounds, retries, max_in_flight, collected, root, bar) -> None:
    """Submit chunks (at most ``max_in_flight`` pending), collect them as they finish, retry failures."""
    todo = list(range(len(bounds)))[::-1]  # a stack: pop() gives chunks in order
    attempts: dict[int, int] = {}
    pending: dict[Any, int] = {}

    submitted = False

    def submit(i: int) -> None:
        nonlocal submitted
        try:
            pending[_submit(executor, make_task(i), attempts.get(i, 0))] = i
        except _USER_ERRORS:
            raise
        except Exception as exc:  # noqa: BLE001 - a broken pool refuses submissions: count as a failed attempt
            if not submitted:  # refused from the start: the executor itself is unusable (bad input)
                raise ValueError(f"executor: {type(executor).__name__} refused the first chunk "
                                 f"({type(exc).__name__}: {exc}); pass a running executor") from exc
            fail(i, exc)
        else:
            submitted = True

    def fail(i: int, exc: BaseException | None, error: str | None = None) -> None:
        attempts[i] = attempts.get(i, 0) + 1
        if error is None and attempts[i] <= retries:
            collected["retries"] += 1
            todo.append(i)
        else:
            a, b = bounds[i]
            error = error or f"{type(exc).__name__}: {exc}"
            collected["failed"].append({"chunk": i, "start": a, "stop": b, "error": error})
            if bar is not None:
                bar.update(b - a)

    try:
        while todo or pending:
            while todo and len(pending) < max_in_flight:
                submit(todo.pop())
            if not pending:
                continue
            try:
                done = _wait_first(executor, pending)
            except _USER_ERRORS:
                raise
            except Exception as exc:  # noqa: BLE001 - the executor went away (a Dask client closed mid-run)
                for fut, i in list(pending.items()):
                    del pending[fut]
                    fail(i, exc)
                continue
            for fut in done:
                i = pending.pop(fut)
                try:
                    payload = fut.result()
                except _USER_ERRORS:
                    raise
                except Exception as exc:  # noqa: BLE001 - lost worker, broken pool, ...: retry then give up
                    fail(i, exc)
                    continue
                if "error" in payload:  # the computation itself failed: the same again on a retry
                    fail(i, None, payload["error"])
                    continue
                _collect(i, bounds[i], payload, collected, root)
                if bar is not None:
                    bar.update(bounds[i][1] - bounds[i][0])
                del fut, payload  # release the result (Dask frees it on the cluster too)
    finally:
        for fut in pending:  # on an error raised here, leave nothing running on the executor
            cancel = getattr(fut, "cancel", None)
            if cancel is not None:
                try:
                    cancel()
                except Exception:  # noqa: BLE001 - a closed client cannot cancel: nothing runs there anyway
                    pass


def _collect(i: int, bound, payload: dict, collected: dict, root: Path | None) -> None:
    a, b = bound
    if collected["t"] is None:
        collected["t"] = payload["t"]
        collected["tails"] = {k: payload[k].shape[2:] for k in _ARRAYS if k in payload}
        collected["meta"] = payload["meta"]
    elif payload["t"].shape != collected["t"].shape:
        raise ValueError(f"chunks returned different output times ({payload['t'].shape} and "
                         f"{collected['t'].shape}); reduce must keep the same times for every chunk")
    collected["status"][a:b] = payload["status"]
    collected["stats"].append(payload["meta"]["stats"])
    B = collected["status"].size
    for key, v in payload.items():
        if key.startswith(_STAT):
            name = key[len(_STAT):]
            if name not in collected["traj_stats"]:
                # a store keeps them in its shards: only their dtype here (memory stays bounded)
                collected["traj_stats"][name] = (np.empty(0, dtype=v.dtype) if root is not None else
                                                 np.full(B, np.nan if v.dtype.kind == "f" else 0, dtype=v.dtype))
            if root is None:
                collected["traj_stats"][name][a:b] = v
            if name in collected["ends"]:
                collected["ends"][name][a:b] = v
    if root is not None:
        _check_still_ours(root, collected["run"])  # (before writing: a replaced store's chunks stay its new run's)
        _write_shard(root, i, payload, collected["run"])
        return
    collected["events"].append({k: v for k, v in payload.items() if k.startswith(_EVENT)})
    if collected["arrays"] is None:
        T = payload["t"].size
        collected["arrays"] = {k: np.full((T, B) + payload[k].shape[2:], np.nan) for k in _ARRAYS if k in payload}
    for k, arr in collected["arrays"].items():
        arr[:, a:b] = payload[k]


def _check_still_ours(root: Path, run: str) -> None:
    """RuntimeError when another run replaced the store (``overwrite=True``) while this one ran: this run stops
    before writing into it (each chunk and the final manifest check)."""
    if _run_on_disk(root) != run:
        raise RuntimeError(f"store {str(root)!r} was replaced by another run (overwrite=True) while this one ran: "
                           "this run stopped without writing into it; run it again into another directory")


def _fallback_tails(system, init: dict, sampler, options: dict) -> dict[str, tuple[int, ...]]:
    """Trailing shapes of the arrays when no chunk came back (every one failed): from the system."""
    alg = system.algebra
    k = getattr(getattr(system, "constraints", None), "dim", None) or getattr(system, "k", alg.dim)
    tails = {"xi": (int(k),), "omega": (alg.dim,)}
    m = getattr(alg, "matrix_size", None)
    if m is not None and ("Gamma0" in init or (sampler is not None and alg.name.startswith("so("))):
        tails["Gamma"] = (m,)
    if m is not None and options.get("reconstruct"):
        tails["g"] = (m, m)
    return tails


# ====================================================================== validation helpers
def _given_initial_data(system, is_model, Omega0, Gamma0, g0, options) -> tuple[dict, tuple[int, ...]]:
    """The whole batch's initial data, read and checked by integrate's own code (``_initial_data``), for the chunks.

    Omega0 travels as the coordinates integrate reads off it on the whole batch (matrices or coordinates, the
    so(3)/se(2) ambiguity and the constraints decided once, by integrate's rule, not per chunk); Gamma0 and g0 as
    the float arrays the user gave (checked here): integrate normalises Gamma0 per trajectory on each chunk, as it
    would on the whole batch, so the numbers are the same bit for bit.
    """
    _, x0, _, _, batch_shape = _initial_data(system, is_model, Omega0, Gamma0, g0, options.get("reconstruct", False),
                                             options.get("form", "auto"))
    init = {"Omega0": x0}
    for key, v in (("Gamma0", Gamma0), ("g0", g0)):  # already checked by _initial_data
        if v is not None:
            init[key] = _as_given(v, key, _CORE[key])
    return init, tuple(batch_shape)


def _broadcast_batch(init: dict, batch_shape: tuple[int, ...]) -> None:
    """Gamma0 and g0 given with a sampler: one value each, or ``n`` of them."""
    shapes = {k: v.shape[:v.ndim - _CORE[k]] for k, v in init.items()}
    try:
        out = np.broadcast_shapes(*shapes.values(), batch_shape)
    except ValueError as exc:
        what = ", ".join(f"{k}: {s}" for k, s in shapes.items())
        raise ValueError(f"the batch axes of the initial data do not broadcast ({what}, n: {batch_shape})") from exc
    if out != tuple(batch_shape):
        raise ValueError(f"with a sampler, Gamma0 and g0 must be one value each (or n of them), got batch "
                         f"axes {shapes}")


def _take(a: np.ndarray, core: int, batch_shape: tuple[int, ...], start: int, stop: int) -> np.ndarray:
    """Flat (C-order) trajectories ``[start, stop)`` of ``a`` broadcast to ``batch_shape``: (stop - start, core...)."""
    lead = a.shape[:a.ndim - core]
    tail = a.shape[a.ndim - core:]
    if lead == tuple(batch_shape):  # the common case: a view, no index arithmetic
        return np.ascontiguousarray(a.reshape((-1,) + tail)[start:stop])
    idx = np.unravel_index(np.arange(start, stop), batch_shape) if batch_shape else ()
    pad = len(batch_shape) - len(lead)
    sel = tuple(np.zeros(stop - start, dtype=np.intp) if s == 1 else idx[pad + j] for j, s in enumerate(lead))
    if not lead:
        return np.broadcast_to(a, (stop - start,) + tail).copy()
    return np.ascontiguousarray(a[sel])


def _chunk_events(events, batch_shape: tuple[int, ...], start: int, stop: int):
    """``events`` for the chunk ``[start, stop)``: a :class:`~liesuslov.integrators.LinearEvent` with
    per-trajectory coefficients (leading batch axes) gets the chunk's rows of them, so that every
    trajectory has its own plane as in one integrate call; a callable is passed as it is (a chunk calls it
    with its own batch, (stop - start,)): it must work per trajectory."""
    from ..integrators.events import LinearEvent

    def rows(a, core: int):
        return a if a is None or a.ndim <= core else _take(a, core, batch_shape, start, stop)

    def one(e):
        if not isinstance(e, LinearEvent):
            return e
        return LinearEvent(omega=rows(e.omega, 1), Gamma=rows(e.Gamma, 1), g=rows(e.g, 2), offset=rows(e.offset, 0),
                           terminal=e.terminal, direction=e.direction)

    return [one(e) for e in events] if isinstance(events, (list, tuple)) else one(events)


#: Bytes this process keeps per trajectory whatever the store (status, stop time and failure code, the chunk list).
_BYTES_PER_TRAJECTORY = 32


def _check_bookkeeping(B: int) -> None:
    """``ValueError`` when the per-trajectory bookkeeping of ``B`` trajectories would not fit in half the machine's
    memory (n = 10^11 grew to the whole memory, then died in a MemoryError)."""
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):  # not POSIX: no check
        return
    need = _BYTES_PER_TRAJECTORY * B
    if need > memory // 2:
        raise ValueError(f"n / the batch: {B} trajectories need {need / 1e9:.3g} GB of bookkeeping in this process "
                         f"(status, stop time per trajectory), more than half of its {memory / 1e9:.3g} GB; split "
                         "the run into several ensembles")


def _prepare_store(store, overwrite: bool) -> Path:
    if not isinstance(store, (str, os.PathLike)) or not isinstance(os.fspath(store), str):
        raise TypeError(f"store must be None or a directory path (str or os.PathLike), got {type(store).__name__}")
    if os.fspath(store) == "":
        # Path("") is the current directory: the shards and the manifest would land there (and overwrite=True
        # would delete chunk files there); an empty string is most likely an unset variable, not a choice
        raise ValueError("store must be a directory path, got the empty string; pass a directory such as "
                         "'runs/ensemble' (or '.' to write into the current directory)")
    root = Path(store)
    if root.exists() and not root.is_dir():
        raise ValueError(f"store {str(root)!r} exists and is not a directory; pass a directory path")
    try:
        if (root / MANIFEST).exists():
            if not overwrite:
                raise ValueError(f"store {str(root)!r} already holds an ensemble; pass overwrite=True to replace "
                                 "it, or another directory")
            # missing_ok: another run replacing the same store may have deleted them first
            for p in [*root.glob("chunk-*.npz"), *root.glob(".chunk-*.npz")]:  # (the latter: cut off mid-write)
                p.unlink(missing_ok=True)
            (root / MANIFEST).unlink(missing_ok=True)
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _store_error(root, exc) from exc
    return root


def _store_error(root: Path, exc: OSError) -> Exception:
    """The error of a store directory that cannot be created or written, naming ``store`` and the fix.

    A path that cannot be a directory (a part of it is a file, or a file system such as /proc that takes no new
    directories) is bad input: ValueError. Other causes (permissions, a full or read-only disk) are the
    system's: the same OSError subclass and errno, with the argument named in the message.
    """
    where = f"store {str(root)!r}"
    if isinstance(exc, (NotADirectoryError, FileExistsError, FileNotFoundError)):
        return ValueError(f"{where} cannot be created as a directory ({exc.strerror or exc}: a part of the path is "
                          "a file, or the file system takes no new directories there); pass a directory path "
                          "you can write to")
    message = (f"{where} cannot be written ({exc.strerror or exc}); pass a directory you can write to, or free "
               "space on its disk")
    return _naming(exc, message)


def _progress_bar(on: bool, total: int):
    return progress_bar(total, "traj", "ensemble") if on else None
