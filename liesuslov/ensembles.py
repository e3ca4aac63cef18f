"""Ensembles beyond one process: one batch of initial data split into chunks run on any executor.

:func:`ensemble` integrates a batch of initial data (given, or drawn on the workers by a sampler)
chunk by chunk, in this process, on a :class:`concurrent.futures.Executor` (a process pool, loky, an
MPI pool) or on a Dask cluster through a ``dask.distributed.Client``, and returns an :class:`Ensemble`
with the arrays of a :class:`~liesuslov.Solution`. The numbers are those of one
:func:`~liesuslov.integrate` call on the whole batch, whatever the executor and the chunk size, because
each trajectory's numbers do not depend on its batch mates.

Results stream to a ``store`` directory (one ``.npz`` shard per chunk and a JSON manifest, both
written atomically), so memory stays bounded by a few chunks; :func:`open_ensemble` reads a finished
or partial store back lazily. A chunk whose task fails for a reason other than bad input (a lost
worker, a broken pool) is resubmitted up to ``retries`` times, then reported as ``status = -1`` for
its trajectories.

Store layout (``FORMAT = "liesuslov-ensemble/1"``)::

    DIR/manifest.json        batch shape, chunk bounds, times, array shapes, stats, complete flag
    DIR/chunk-000000.npz     t, xi, omega, [Gamma], [g], status of trajectories [start, stop),
                             time axis first, then one flat batch axis; __meta__ (JSON) per chunk

Nothing here imports dask, xarray or tqdm until asked to.
"""

from __future__ import annotations

import concurrent.futures as cf
import inspect
import json
import math
import os
import pickle
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["ensemble", "open_ensemble", "Ensemble", "Perturbation", "draw", "REDUCTIONS", "SAMPLER_BLOCK",
           "FORMAT", "benchmark"]

#: Trajectories per random block: block ``j`` (trajectories ``[j B, (j + 1) B)``) is drawn by
#: ``sampler(numpy.random.default_rng(SeedSequence(seed).spawn(j + 1)[j]), B)``, whatever the chunking.
SAMPLER_BLOCK = 1024
#: Names accepted by ``reduce=`` (besides None and a module-level callable ``Solution -> Solution``).
REDUCTIONS = ("final",)
FORMAT = "liesuslov-ensemble/1"
MANIFEST = "manifest.json"
_ARRAYS = ("xi", "omega", "Gamma", "g")
_INIT_KEYS = ("Omega0", "Gamma0", "g0")
_SUMMED = ("nfev", "steps", "rejected")
_STAT = "stats__"  # shard key prefix of a per-trajectory statistic (e.g. stats__trajectory_steps)
_CORE = {"Omega0": None, "Gamma0": 1, "g0": 2}  # trailing (non-batch) axes; Omega0's is 1 or 2
# Exceptions a task raises on bad input: deterministic, so they are raised here, never retried.
_USER_ERRORS = (ValueError, TypeError)


# ====================================================================== sampling
@dataclass(frozen=True)
class Perturbation:
    """A sampler of initial data near a base point (module-level, so it pickles to any worker).

    ``Omega0 = Omega_base + scale * z @ basis`` with ``z`` standard normal (k,), so Omega0 stays in
    the constraint subspace D spanned by ``basis``; ``Gamma0 = (Gamma_base + gamma_scale * w) / |...|``
    with ``w`` standard normal (n,), a unit vector; ``g0`` is kept as given. Build it with
    :meth:`around`.

    Parameters
    ----------
    omega : ndarray, shape (d,)
        Base Omega in algebra coordinates.
    basis : ndarray, shape (k, d)
        Rows spanning D (``system.constraints.basis``).
    Gamma0 : ndarray, shape (n,), optional
    g0 : ndarray, shape (m, m), optional
    scale : float
        Standard deviation of the perturbation of Omega along each basis row.
    gamma_scale : float, optional
        Standard deviation of the perturbation of Gamma0 per component (default: ``scale``).
    """

    omega: np.ndarray
    basis: np.ndarray
    Gamma0: np.ndarray | None = None
    g0: np.ndarray | None = None
    scale: float = 1e-2
    gamma_scale: float | None = None

    @classmethod
    def around(cls, system, Omega0, *, Gamma0=None, g0=None, scale: float = 1e-2,
               gamma_scale: float | None = None) -> Perturbation:
        """The perturbation of one initial state of ``system`` (Omega0 a matrix (n, n) or coordinates (d,))."""
        alg = system.algebra
        O = np.asarray(Omega0, dtype=float)
        omega = alg.vee(O) if O.shape != (alg.dim,) and O.ndim == 2 else O
        if omega.shape != (alg.dim,):
            raise ValueError(f"Omega0 must be one state: shape ({alg.dim},) or a matrix, got {O.shape}")
        for name, v in (("scale", scale), ("gamma_scale", gamma_scale)):
            if v is not None and (isinstance(v, bool) or not np.isfinite(v) or v < 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        basis = np.asarray(system.constraints.basis, dtype=float)
        G = None if Gamma0 is None else np.asarray(Gamma0, dtype=float)
        g = None if g0 is None else np.asarray(g0, dtype=float)
        return cls(omega, basis, G, g, float(scale), None if gamma_scale is None else float(gamma_scale))

    def __call__(self, rng: np.random.Generator, size: int) -> dict[str, np.ndarray]:
        """Draw ``size`` initial states: ``Omega0`` (size, d), ``Gamma0`` (size, n), ``g0`` (size, m, m)."""
        z = rng.standard_normal((size, self.basis.shape[0]))
        out = {"Omega0": self.omega + self.scale * (z @ self.basis)}
        if self.Gamma0 is not None:
            s = self.scale if self.gamma_scale is None else self.gamma_scale
            G = self.Gamma0 + s * rng.standard_normal((size, self.Gamma0.shape[-1]))
            out["Gamma0"] = G / np.linalg.norm(G, axis=-1, keepdims=True)
        if self.g0 is not None:
            out["g0"] = np.broadcast_to(self.g0, (size,) + self.g0.shape).copy()
        return out


def _seed_parts(seed) -> tuple[Any, tuple[int, ...], int]:
    """(entropy, spawn_key, pool_size) of ``SeedSequence(seed)``: workers rebuild block ``j``'s child."""
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    return ss.entropy, tuple(ss.spawn_key), ss.pool_size


def _draw_range(sampler, seed_parts, start: int, stop: int, block: int) -> dict[str, np.ndarray]:
    """Trajectories ``[start, stop)`` of a sampler run: whole blocks drawn, then sliced."""
    entropy, key, pool = seed_parts
    parts: dict[str, list[np.ndarray]] = {}
    for j in range(start // block, -(-stop // block)):
        # the j-th child of SeedSequence(seed).spawn(...), built directly (no need to spawn j others)
        rng = np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=key + (j,), pool_size=pool))
        drawn = sampler(rng, block)
        if not isinstance(drawn, Mapping) or "Omega0" not in drawn:
            raise TypeError(f"sampler must return a dict with 'Omega0' (and optionally 'Gamma0', 'g0'), got "
                            f"{type(drawn).__name__}")
        extra = set(drawn) - set(_INIT_KEYS)
        if extra:
            raise ValueError(f"sampler returned unknown keys {sorted(extra)}; allowed: {list(_INIT_KEYS)}")
        lo, hi = max(start, j * block) - j * block, min(stop, (j + 1) * block) - j * block
        for k, v in drawn.items():
            v = np.asarray(v, dtype=float)
            if v.ndim == 0 or v.shape[0] != block:
                raise ValueError(f"sampler(rng, size) must return arrays with a leading axis of length size "
                                 f"({block}); {k!r} has shape {v.shape}")
            parts.setdefault(k, []).append(v[lo:hi])
    return {k: np.concatenate(v) for k, v in parts.items()}


def draw(sampler: Callable, n: int, seed=None, *, start: int = 0, stop: int | None = None,
         block: int = SAMPLER_BLOCK) -> dict[str, np.ndarray]:
    """The initial data an :func:`ensemble` run with ``sampler``, ``n`` and ``seed`` integrates.

    Parameters
    ----------
    sampler : callable
        ``sampler(rng, size) -> {"Omega0": (size, ...), "Gamma0": (size, n), "g0": (size, m, m)}``.
    n : int
        Number of trajectories.
    seed : int, SeedSequence or None
        As passed to :func:`ensemble` (None is not reproducible: pass the ``stats["seed"]`` of a run).
    start, stop : int
        Only trajectories ``[start, stop)`` (default all ``n``).

    Returns
    -------
    dict of ndarray
        Leading axis ``stop - start``.
    """
    n = _positive_int(n, "n")
    stop = n if stop is None else stop
    if not 0 <= start <= stop <= n:
        raise ValueError(f"need 0 <= start <= stop <= n, got start={start}, stop={stop}, n={n}")
    return _draw_range(sampler, _seed_parts(seed), start, stop, block)


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
    from .integrators import integrate

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
    # per-trajectory statistics (arrays of the batch shape) travel as arrays; the rest in the JSON meta
    stats = {}
    for k, v in sol.stats.items():
        if isinstance(v, np.ndarray) and v.size == c and v.ndim >= 1:
            out[_STAT + k] = v.reshape(c)
        else:
            stats[k] = v
    out["meta"] = {"stats": stats, "message": str(getattr(sol, "message", "")), "n": sol.n,
                   "algebra_name": sol.algebra_name}
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


# ====================================================================== the result
class Ensemble:
    """The result of :func:`ensemble` (or :func:`open_ensemble`): the arrays of a Solution.

    In memory, or backed by a store directory: then every array is assembled from the shards on each
    access (keep a reference, ``omega = ens.omega``, rather than reading ``ens.omega`` in a loop), and
    :meth:`chunks` walks the results with bounded memory. Pickles (a store-backed one as its path).

    Attributes
    ----------
    t : ndarray, shape (N,)
    xi : ndarray, shape (N, ..., k)
    omega : ndarray, shape (N, ..., d)
    Omega : ndarray, shape (N, ..., n, n), or None off so(n)
    Gamma : ndarray, shape (N, ..., n), or None
    g : ndarray, shape (N, ..., m, m), or None
    status : ndarray of int, shape (...)
        0 reached the end, 1 stopped by a terminal event, -1 failed (a failed or missing chunk too).
    success : bool
        Every status >= 0.
    stats : dict
        ``nfev``, ``steps``, ``rejected`` summed over chunks; ``chunks``, ``chunk_size``,
        ``failed_chunks`` (list of ``{"chunk", "start", "stop", "error"}``), ``retries``,
        ``wall_time``, ``executor``, ``seed`` (the entropy of a sampler run), and the first chunk's
        ``method``, ``chart``, ``form``, ``backend``; statistics integrate reports per trajectory
        (arrays of the batch shape, e.g. ``trajectory_steps``) assembled over the whole batch (0 or
        NaN for a failed or missing chunk).
    batch_shape : tuple of int
    complete : bool
        False for a store some of whose chunks are missing (their status is -1, their values NaN).
    store : Path or None
    """

    def __init__(self, *, t, batch_shape, bounds, tails, stats, n=None, algebra_name="", message="",
                 arrays=None, status=None, store=None, present=None, traj_stats=None):
        self._t = np.asarray(t, dtype=float)
        self.batch_shape = tuple(int(b) for b in batch_shape)
        self._bounds = [tuple(map(int, b)) for b in bounds]
        self._tails = {k: tuple(v) for k, v in tails.items()}
        self._stats = stats
        # per-trajectory statistics: {name: (B,) array} in memory, {name: dtype string} for a store
        self._traj_stats = traj_stats or {}
        self.n = n
        self.algebra_name = algebra_name
        self.message = message
        self._arrays = arrays
        self._status = status
        self.store = None if store is None else Path(store)
        self._present = present

    # ------------------------------------------------------------------ arrays
    @property
    def t(self) -> np.ndarray:
        return self._t

    @property
    def xi(self) -> np.ndarray:
        return self._get("xi")

    @property
    def omega(self) -> np.ndarray:
        return self._get("omega")

    @property
    def Gamma(self) -> np.ndarray | None:
        return self._get("Gamma")

    @property
    def g(self) -> np.ndarray | None:
        return self._get("g")

    @property
    def Omega(self) -> np.ndarray | None:
        """Omega as skew matrices (N, ..., n, n) on so(n); None on other algebras."""
        if not self.algebra_name.startswith("so(") or self.n is None:
            return None
        from .algebra import so

        return so(self.n).hat(self.omega)

    @property
    def stats(self) -> dict:
        out = dict(self._stats)
        for name, v in self._traj_stats.items():
            out[name] = (v if isinstance(v, np.ndarray) else self._assemble_stat(name, v)).reshape(self.batch_shape)
        return out

    def _assemble_stat(self, name: str, dtype: str) -> np.ndarray:
        dt = np.dtype(dtype)
        out = np.full(self._B, np.nan if dt.kind == "f" else 0, dtype=dt)
        for i, (a, b) in enumerate(self._bounds):
            if self._has(i):
                with np.load(self._shard(i), allow_pickle=False) as z:
                    if _STAT + name in z.files:
                        out[a:b] = z[_STAT + name]
        return out

    @property
    def status(self) -> np.ndarray:
        if self._status is not None:
            return self._status
        st = np.full(self._B, -1, dtype=np.int64)
        for i, (a, b) in enumerate(self._bounds):
            if self._has(i):
                with np.load(self._shard(i), allow_pickle=False) as z:
                    st[a:b] = z["status"]
        return st.reshape(self.batch_shape)

    @property
    def success(self) -> bool:
        """True iff every trajectory's status is >= 0 (reached the end or stopped by a terminal event)."""
        return bool(np.all(self.status >= 0))

    @property
    def complete(self) -> bool:
        return self._present is None or all(self._present)

    @property
    def _B(self) -> int:
        return math.prod(self.batch_shape)

    def _has(self, i: int) -> bool:
        return self._present is None or self._present[i]

    def _shard(self, i: int) -> Path:
        return self.store / _shard_name(i)

    def _get(self, name: str) -> np.ndarray | None:
        if name not in self._tails:
            return None
        if self._arrays is not None:
            return self._arrays[name]
        out = np.full((self._t.size, self._B) + self._tails[name], np.nan)
        for i, (a, b) in enumerate(self._bounds):
            if self._has(i):
                with np.load(self._shard(i), allow_pickle=False) as z:
                    if name in z.files:
                        out[:, a:b] = z[name]
        return out.reshape((self._t.size,) + self.batch_shape + self._tails[name])

    def chunks(self) -> Iterator[tuple[int, int, dict[str, np.ndarray]]]:
        """Yield ``(start, stop, arrays)`` per chunk: flat trajectory indices (C order) and the chunk's
        arrays (``xi``, ``omega``, ``Gamma``, ``g`` with shape (N, stop - start, ...), ``status``);
        missing chunks are skipped. Memory stays at one chunk."""
        for i, (a, b) in enumerate(self._bounds):
            if self._arrays is not None:
                flat = {k: v.reshape((v.shape[0], self._B) + self._tails[k])[:, a:b] for k, v in self._arrays.items()}
                flat["status"] = self.status.reshape(-1)[a:b]
                yield a, b, flat
            elif self._has(i):
                with np.load(self._shard(i), allow_pickle=False) as z:
                    yield a, b, {k: z[k] for k in (*_ARRAYS, "status") if k in z.files}

    def to_solution(self):
        """All of it as a :class:`~liesuslov.Solution` (in memory)."""
        from .integrators import Solution

        return Solution(t=self.t, xi=self.xi, omega=self.omega, Gamma=self.Gamma, g=self.g, stats=self.stats,
                        status=self.status, message=self.message, n=self.n, algebra_name=self.algebra_name)

    def to_xarray(self):
        """An ``xarray.Dataset`` (dims ``time``, ``batch_0``, ..., components); needs ``liesuslov[xarray]``."""
        from .xarray_io import solution_to_xarray

        return solution_to_xarray(self)

    def __getstate__(self):
        state = dict(self.__dict__)
        if self.store is not None:  # a store-backed ensemble travels as its path: reread the manifest
            state = {"store": self.store}
        return state

    def __setstate__(self, state):
        if set(state) == {"store"}:
            self.__dict__.update(open_ensemble(state["store"]).__dict__)
        else:
            self.__dict__.update(state)

    def __repr__(self) -> str:
        where = f", store={str(self.store)!r}" if self.store is not None else ""
        status = self.status
        ok = int(np.count_nonzero(status >= 0))
        return (f"Ensemble(batch_shape={self.batch_shape}, t: {self.t.shape}, success={ok}/{status.size}"
                f"{'' if self.complete else ', incomplete'}{where})")


# ====================================================================== the store
def _shard_name(i: int) -> str:
    return f"chunk-{i:06d}.npz"


def _atomic_write(path: Path, write: Callable[[Any], None], suffix: str) -> None:
    """Write through a temporary file in the same folder, then rename: readers never see half a file."""
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=suffix, dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _jsonable(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, Path):
        return str(x)
    return str(x)


def _write_manifest(store: Path, manifest: dict) -> None:
    text = json.dumps(manifest, default=_jsonable, indent=1).encode()
    _atomic_write(store / MANIFEST, lambda f: f.write(text), ".json")


def _write_shard(store: Path, i: int, payload: dict) -> None:
    arrays = {k: v for k, v in payload.items() if k in ("t", *_ARRAYS, "status") or k.startswith(_STAT)}
    # UTF-8 bytes, not a numpy unicode string (4 bytes a character)
    meta = np.frombuffer(json.dumps(payload["meta"], default=_jsonable).encode(), dtype=np.uint8)
    _atomic_write(store / _shard_name(i), lambda f: np.savez(f, **arrays, __meta__=meta), ".npz")


def open_ensemble(store) -> Ensemble:
    """Reopen the ensemble stored in a directory (finished or partial), reading arrays lazily.

    Parameters
    ----------
    store : str or PathLike
        The ``store=`` directory of an :func:`ensemble` run.

    Returns
    -------
    Ensemble
        ``complete`` is False when chunks are missing (a run interrupted or still going): their
        trajectories have status -1 and NaN values, and ``message`` says how many are missing.

    Raises
    ------
    FileNotFoundError
        If ``store`` holds no ``manifest.json``.
    ValueError
        If the manifest is of another format, or no chunk has finished yet.
    """
    if not isinstance(store, (str, os.PathLike)):
        raise TypeError(f"store must be a path (str or os.PathLike), got {type(store).__name__}")
    root = Path(store)
    path = root / MANIFEST
    if not path.is_file():
        raise FileNotFoundError(f"store {str(root)!r} holds no {MANIFEST}: not an ensemble store (or the run "
                                "has not started); pass the directory given as ensemble(..., store=DIR)")
    man = json.loads(path.read_text())
    if man.get("format") != FORMAT:
        raise ValueError(f"store {str(root)!r}: unknown format {man.get('format')!r} (expected {FORMAT!r})")
    bounds = man["bounds"]
    present = [(root / _shard_name(i)).is_file() for i in range(len(bounds))]
    t, tails, meta = man.get("t"), man.get("tails"), man.get("meta", {})
    if t is None or tails is None:  # the run stopped before its end: read them off a finished shard
        first = next((i for i, p in enumerate(present) if p), None)
        if first is None:
            raise ValueError(f"store {str(root)!r}: no chunk has finished yet (0 of {len(bounds)}); nothing to read")
        with np.load(root / _shard_name(first), allow_pickle=False) as z:
            t = z["t"]
            tails = {k: z[k].shape[2:] for k in _ARRAYS if k in z.files}
            meta = json.loads(z["__meta__"].tobytes().decode())
    missing = len(bounds) - sum(present)
    message = man.get("message", "")
    if missing:
        message = (f"{missing} of {len(bounds)} chunks missing from the store (status -1, values NaN); "
                   "the run was interrupted or is still going. " + message).strip()
    stats = dict(man.get("stats", {}))
    traj_stats = man.get("trajectory_stats")
    if traj_stats is None:
        first = next((i for i, p in enumerate(present) if p), None)
        traj_stats = {}
        if first is not None:
            with np.load(root / _shard_name(first), allow_pickle=False) as z:
                traj_stats = {k[len(_STAT):]: z[k].dtype.str for k in z.files if k.startswith(_STAT)}
    return Ensemble(t=t, batch_shape=man["batch_shape"], bounds=bounds, tails=tails, stats=stats,
                    n=meta.get("n"), algebra_name=meta.get("algebra_name", ""), message=message,
                    store=root, present=present, traj_stats=traj_stats)


# ====================================================================== executors
def _is_dask(executor) -> bool:
    return type(executor).__module__.split(".")[0] == "distributed" and hasattr(executor, "scheduler_info")


def _n_workers(executor) -> int:
    if executor is None:
        return 1
    if _is_dask(executor):
        try:
            return max(1, sum(w.get("nthreads", 1) for w in executor.scheduler_info()["workers"].values()))
        except Exception:  # noqa: BLE001 - only a default chunk size depends on it
            return 4
    return int(getattr(executor, "_max_workers", 4) or 4)


class _InProcess:
    """A future computed on the spot (executor=None): same interface as the others."""

    def __init__(self, fn, arg):
        try:
            self._value, self._exc = fn(arg), None
        except Exception as exc:  # noqa: BLE001 - reported like a worker's exception
            self._value, self._exc = None, exc

    def result(self):
        if self._exc is not None:
            raise self._exc
        return self._value


def _submit(executor, task: _Task, attempt: int):
    if executor is None:
        return _InProcess(_run_chunk, task)
    if _is_dask(executor):
        # pure=False: a resubmission gets a new key instead of Dask's cached failed result
        return executor.submit(_run_chunk, task, pure=False, key=f"liesuslov-chunk-{task.index}-{attempt}-"
                                                               f"{os.urandom(4).hex()}")
    return executor.submit(_run_chunk, task)


def _wait_first(executor, futures):
    if executor is None:
        return list(futures)
    if _is_dask(executor):
        from distributed import wait

        return list(wait(list(futures), return_when="FIRST_COMPLETED").done)
    return list(cf.wait(list(futures), return_when=cf.FIRST_COMPLETED).done)


# ====================================================================== the front door
def ensemble(system, Omega0=None, t_span=None, *, Gamma0=None, g0=None, t_eval=None, chunk_size: int | None = None,
             executor=None, store=None, sampler: Callable | None = None, n: int | None = None, seed=None,
             reduce: str | Callable | None = None, progress: bool = False, retries: int = 2,
             max_in_flight: int | None = None, overwrite: bool = False, **options) -> Ensemble:
    """Integrate a batch of initial data chunk by chunk on an executor: the numbers of one :func:`integrate`.

    Parameters
    ----------
    system : SuslovSystem or Model
        Must pickle when ``executor`` is not None (systems built from module-level callables do).
    Omega0 : array_like, shape (..., n, n) or (..., d), optional
        Initial data as for :func:`~liesuslov.integrate`; the batch axes of ``Omega0``, ``Gamma0`` and
        ``g0`` broadcast together. None with a ``sampler``.
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
        None runs the chunks here, one after the other.
    store : str or PathLike, optional
        A directory the results stream to (created; an existing store is refused unless
        ``overwrite=True``). The returned Ensemble then reads from it lazily.
    sampler : callable, optional
        A module-level callable (or :class:`Perturbation`) ``sampler(rng, size) -> dict`` with
        ``"Omega0"`` (size, ...) and optionally ``"Gamma0"``, ``"g0"``, called on the workers: block ``j``
        of :data:`SAMPLER_BLOCK` trajectories is drawn with ``default_rng(SeedSequence(seed).spawn(...)[j])``,
        so the run is the same whatever the executor, the number of workers and the chunk size.
        ``Gamma0``/``g0`` given here (one value each) are used when the sampler does not return them.
    n : int
        Number of trajectories drawn by ``sampler`` (only with a sampler).
    seed : int, SeedSequence or None
        Root of the sampler's seeds (None: fresh entropy, recorded in ``stats["seed"]``).
    reduce : None, "final" or callable
        Done on the workers before results travel: None keeps every output time; ``"final"`` keeps
        only the last one (time axis of length 1; NaN for a trajectory a terminal event stopped
        earlier, as in the Solution); a module-level callable ``reduce(sol) -> Solution`` (same batch
        axes, the same times for every chunk) anything else.
    progress : bool
        A progress bar over trajectories (needs tqdm: ``liesuslov[progress]``).
    retries : int
        Times a chunk whose task errored (lost worker, broken pool) is resubmitted before its
        trajectories get status -1. Bad input (ValueError/TypeError from a task) is raised at once.
    max_in_flight : int, optional
        Chunks submitted but not yet collected (default 3 per worker): bounds memory.
    overwrite : bool
        Replace an existing store.
    **options
        Passed to :func:`~liesuslov.integrate` (``method``, ``h``, ``rtol``, ``atol``, ``reconstruct``,
        ``chart``, ``backend``, ...).

    Returns
    -------
    Ensemble
        ``t`` (N,), ``omega`` (N, ..., d), ``Omega``, ``Gamma``, ``g``, ``status`` (...), ``success``,
        ``stats``; the batch axes are those of the initial data (``(n,)`` with a sampler).

    Raises
    ------
    ValueError, TypeError
        Bad arguments, naming the argument (also a bad initial state found by a worker).
    """
    from .integrators import integrate

    t0, t1 = _check_t_span(t_span)
    t_eval = np.array([t0, t1]) if t_eval is None else _check_t_eval(t_eval, t0, t1)
    if "alg" in options or not hasattr(system, "algebra"):
        raise TypeError(f"system must be a SuslovSystem (or a model), got {type(system).__name__}")
    allowed = set(inspect.signature(integrate).parameters) - {"system", "Omega0", "t_span", "Gamma0", "g0", "t_eval",
                                                              "progress"}
    unknown = sorted(set(options) - allowed)
    if unknown:
        raise TypeError(f"unknown option(s) {unknown} for integrate; allowed: {sorted(allowed)}")
    if not isinstance(progress, (bool, np.bool_)):
        raise TypeError(f"progress must be True or False, got {type(progress).__name__}")
    retries = _nonneg_int(retries, "retries")
    if executor is not None and not callable(getattr(executor, "submit", None)):
        raise TypeError(f"executor must be None, a concurrent.futures.Executor or a dask.distributed.Client "
                        f"(something with submit), got {type(executor).__name__}")
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
        for key, v in (("Gamma0", Gamma0), ("g0", g0)):
            if v is not None:
                init[key] = _as_array(v, key, _CORE[key])
        cores = {k: _CORE[k] for k in init}
        _broadcast_batch(init, cores, batch_shape)
    else:
        if Omega0 is None:
            raise ValueError("Omega0 is required (or draw initial data with sampler=... and n=...)")
        if n is not None or seed is not None:
            raise ValueError("n and seed are used only with sampler=...; the batch is the shape of Omega0")
        init["Omega0"] = _as_array(Omega0, "Omega0", 1)
        for key, v in (("Gamma0", Gamma0), ("g0", g0)):
            if v is not None:
                init[key] = _as_array(v, key, _CORE[key])
        cores = {k: (_omega_core(system, init[k]) if k == "Omega0" else _CORE[k]) for k in init}
        batch_shape = _broadcast_batch(init, cores, None)
    B = math.prod(batch_shape)
    if B == 0:
        raise ValueError(f"the batch of initial data is empty (batch shape {batch_shape})")

    W = _n_workers(executor)
    if chunk_size is None:
        chunk_size = B if (executor is None and store is None) else max(1, min(4096, -(-B // (4 * W))))
    chunk_size = _positive_int(chunk_size, "chunk_size")
    max_in_flight = 3 * W if max_in_flight is None else _positive_int(max_in_flight, "max_in_flight")
    bounds = [(a, min(a + chunk_size, B)) for a in range(0, B, chunk_size)]

    if executor is not None:  # a clear error here rather than a pickling traceback from a worker
        for name, obj in (("system", system), ("sampler", sampler), ("reduce", reduce)):
            try:
                pickle.dumps(obj)
            except Exception as exc:  # noqa: BLE001 - any pickling failure
                raise TypeError(f"{name} must pickle to be sent to the executor's workers ({exc}); build it from "
                                "module-level functions and classes (no lambdas or closures)") from exc

    root = None
    if store is not None:
        root = _prepare_store(store, overwrite)
    manifest = {"format": FORMAT, "batch_shape": list(batch_shape), "bounds": bounds, "complete": False,
                "chunk_size": chunk_size, "t_span": [t0, t1]}
    if root is not None:
        _write_manifest(root, manifest)

    def make_task(i: int) -> _Task:
        a, b = bounds[i]
        chunk = {k: _take(v, cores[k], batch_shape, a, b) for k, v in init.items()}
        return _Task(i, a, b, system, (t0, t1), t_eval, dict(options), chunk or None, sampler, seed_parts,
                     SAMPLER_BLOCK, reduce)

    bar = _progress_bar(progress, B)
    started = time.perf_counter()
    collected: dict[str, Any] = {"arrays": None, "status": np.full(B, -1, dtype=np.int64), "t": None,
                                 "tails": None, "meta": None, "stats": [], "failed": [], "retries": 0,
                                 "traj_stats": {}}
    try:
        _run_all(executor, make_task, bounds, retries, max_in_flight, collected, root, bar)
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - started

    stats = _merge_stats(collected["stats"])
    stats.update({"chunks": len(bounds), "chunk_size": chunk_size, "failed_chunks": collected["failed"],
                  "retries": collected["retries"], "wall_time": wall, "batch": B,
                  "executor": "none" if executor is None else type(executor).__name__,
                  "reduce": reduce if reduce is None or isinstance(reduce, str) else getattr(reduce, "__name__",
                                                                                             repr(reduce))})
    if seed_parts is not None:
        stats["seed"] = seed_parts[0]
    meta = collected["meta"] or {}
    message = (f"{len(collected['failed'])} of {len(bounds)} chunks failed (status -1): "
               f"{collected['failed'][0]['error']}" if collected["failed"] else meta.get("message", ""))
    t_out = collected["t"] if collected["t"] is not None else (t_eval[-1:] if reduce == "final" else t_eval)
    tails = collected["tails"] if collected["tails"] is not None else _fallback_tails(system, init, sampler, options)
    if root is not None:
        manifest.update({"complete": True, "t": t_out, "tails": {k: list(v) for k, v in tails.items()},
                         "meta": {"n": meta.get("n"), "algebra_name": meta.get("algebra_name", "")},
                         "stats": stats, "message": message,
                         "trajectory_stats": {k: v.dtype.str for k, v in collected["traj_stats"].items()}})
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
                    status=collected["status"].reshape(batch_shape), traj_stats=collected["traj_stats"])


def _run_all(executor, make_task, bounds, retries, max_in_flight, collected, root, bar) -> None:
    """Submit chunks (at most ``max_in_flight`` pending), collect them as they finish, retry failures."""
    todo = list(range(len(bounds)))[::-1]  # a stack: pop() gives chunks in order
    attempts: dict[int, int] = {}
    pending: dict[Any, int] = {}

    def submit(i: int) -> None:
        try:
            pending[_submit(executor, make_task(i), attempts.get(i, 0))] = i
        except _USER_ERRORS:
            raise
        except Exception as exc:  # noqa: BLE001 - a broken pool refuses submissions: count as a failed attempt
            fail(i, exc)

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
            for fut in _wait_first(executor, pending):
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
                cancel()


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
    if root is not None:
        _write_shard(root, i, payload)
        return
    if collected["arrays"] is None:
        T = payload["t"].size
        collected["arrays"] = {k: np.full((T, B) + payload[k].shape[2:], np.nan) for k in _ARRAYS if k in payload}
    for k, arr in collected["arrays"].items():
        arr[:, a:b] = payload[k]


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


def _merge_stats(chunk_stats: list[dict]) -> dict:
    """Counts (nfev, steps, rejected) summed over chunks; the rest (method, form, ...) from the first chunk."""
    out: dict[str, Any] = {}
    for st in chunk_stats:
        for k, v in st.items():
            if k in ("wall_time", "batch"):
                continue
            if k in _SUMMED and isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool):
                out[k] = out.get(k, 0) + v
            else:
                out.setdefault(k, v)
    return out


# ====================================================================== validation helpers
def _check_t_span(t_span) -> tuple[float, float]:
    try:
        t0, t1 = (float(v) for v in t_span)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"t_span must be a pair of numbers (t0, t1), got {t_span!r}") from exc
    if not (math.isfinite(t0) and math.isfinite(t1)) or t0 == t1:
        raise ValueError(f"t_span must be two finite, different numbers (t0, t1), got {t_span!r}")
    return t0, t1


def _check_t_eval(t_eval, t0: float, t1: float) -> np.ndarray:
    te = np.asarray(t_eval, dtype=float)
    if te.ndim != 1 or te.size == 0 or not np.all(np.isfinite(te)):
        raise ValueError(f"t_eval must be a non-empty 1-D array of finite times, got shape {te.shape}")
    if te.min() < min(t0, t1) or te.max() > max(t0, t1):
        raise ValueError(f"t_eval must lie within t_span = ({t0}, {t1})")
    if np.any(np.diff(te) * np.sign(t1 - t0) <= 0):
        raise ValueError("t_eval must be strictly increasing (decreasing for backward integration)")
    return te


def _positive_int(v, name: str) -> int:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"{name} must be a positive integer, got {type(v).__name__}")
    if v < 1:
        raise ValueError(f"{name} must be a positive integer, got {v}")
    return int(v)


def _nonneg_int(v, name: str) -> int:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"{name} must be an integer >= 0, got {type(v).__name__}")
    if v < 0:
        raise ValueError(f"{name} must be an integer >= 0, got {v}")
    return int(v)


def _as_array(v, name: str, core: int) -> np.ndarray:
    if v is None:
        raise TypeError(f"{name} must be an array, got None")
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be an array of numbers, got {type(v).__name__}") from exc
    if a.ndim < core:
        raise ValueError(f"{name} must have at least {core} axes, got shape {a.shape}")
    return a


def _omega_core(system, O: np.ndarray) -> int:
    """Trailing axes of Omega0 (2: matrices, 1: coordinates), by integrate's rule."""
    alg = system.algebra
    m = getattr(alg, "matrix_size", None)
    if alg.name.startswith("so(") and O.ndim >= 2 and O.shape[-2:] == (m, m):
        scale = max(1.0, float(np.abs(O).max()) if O.size else 1.0)
        if np.allclose(O, -np.swapaxes(O, -1, -2), rtol=0, atol=1e-12 * scale) or alg.dim != m:
            return 2
    if O.shape[-1] != alg.dim:
        raise ValueError(f"Omega0 must have shape (..., {alg.dim}) (coordinates)"
                         + (f" or (..., {m}, {m}) (skew matrices)" if alg.name.startswith("so(") else "")
                         + f", got {O.shape}")
    return 1


def _broadcast_batch(init: dict, cores: dict, batch_shape) -> tuple[int, ...]:
    shapes = {k: v.shape[:v.ndim - cores[k]] for k, v in init.items()}
    try:
        out = np.broadcast_shapes(*shapes.values(), *([batch_shape] if batch_shape is not None else []))
    except ValueError as exc:
        what = ", ".join(f"{k}: {s}" for k, s in shapes.items())
        raise ValueError(f"the batch axes of the initial data do not broadcast ({what}"
                         + (f", n: {batch_shape}" if batch_shape is not None else "") + ")") from exc
    if batch_shape is not None and out != tuple(batch_shape):
        raise ValueError(f"with a sampler, Gamma0 and g0 must be one value each (or n of them), got batch "
                         f"axes {shapes}")
    return tuple(out)


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


def _prepare_store(store, overwrite: bool) -> Path:
    if not isinstance(store, (str, os.PathLike)):
        raise TypeError(f"store must be None or a directory path (str or os.PathLike), got {type(store).__name__}")
    root = Path(store)
    if root.exists() and not root.is_dir():
        raise ValueError(f"store {str(root)!r} exists and is not a directory; pass a directory path")
    if (root / MANIFEST).exists():
        if not overwrite:
            raise ValueError(f"store {str(root)!r} already holds an ensemble; pass overwrite=True to replace it, "
                             "or another directory")
        for p in root.glob("chunk-*.npz"):
            p.unlink()
        (root / MANIFEST).unlink()
    root.mkdir(parents=True, exist_ok=True)
    return root


def _progress_bar(on: bool, total: int):
    if not on:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError as exc:
        raise ValueError("progress=True needs tqdm: pip install 'liesuslov[progress]'") from exc
    return tqdm(total=total, unit="traj", desc="ensemble")


# ====================================================================== benchmark (not a test)
def _benchmark_system():
    from .algebra import Inertia
    from .mechanics import LinearPotential, SuslovSystem

    J = Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0]))
    return SuslovSystem(J, potential=LinearPotential([0.2, 0.0, 1.0]))


def benchmark(n: int = 1_000_000, workers: tuple[int, ...] = (1, 2), *, n_throughput: int = 100_000,
              chunk_size: int = 8192, h: float = 0.05, t_end: float = 1.0, store=None,
              executor: str = "process", backend: str | None = None) -> dict[str, Any]:
    """Trajectories per second against workers, and the peak memory of a large final-state-only run.

    The scene is cheap on purpose (n = 3 Suslov body with a linear potential, RKMK4, ``t_end / h``
    fixed steps, initial data from :class:`Perturbation`), so the numbers show the ensemble machinery
    (chunking, transport, the store) rather than the integrator.

    Parameters
    ----------
    n : int
        Trajectories of the memory run (``reduce="final"``, streamed to ``store``, 2 workers at most).
    workers : tuple of int
        Worker counts of the throughput runs (each with ``n_throughput`` trajectories).
    executor : {"process", "dask"}
        A ``ProcessPoolExecutor`` or a local Dask cluster (``LocalCluster(processes=True)``).
    store : path, optional
        Directory of the memory run's store (default: a temporary one, removed afterwards).
    backend : str, optional
        integrate's backend; default "numba" when numba is installed (the compiled per-trajectory
        kernel: each worker loads it from the disk cache on its first chunk, in the warm-up), else "numpy".

    Returns
    -------
    dict
        ``throughput``: list of ``{"workers", "trajectories", "seconds", "per_second"}``; ``memory``:
        ``{"trajectories", "seconds", "per_second", "tracemalloc_peak_mb", "maxrss_mb", "store_mb",
        "workers", "worker_maxrss_mb"}`` (the peaks of this, the submitting, process, and the largest
        worker process's maximum resident size).
    """
    import resource
    import shutil
    import tracemalloc

    system = _benchmark_system()
    Omega0 = np.array([0.0, 0.6, -0.4])
    sampler = Perturbation.around(system, Omega0, Gamma0=np.array([0.0, 0.6, 0.8]), scale=0.1)
    if backend is None:
        import importlib.util

        backend = "numba" if importlib.util.find_spec("numba") is not None else "numpy"
    opts = {"method": "rkmk4", "h": h, "reduce": "final", "sampler": sampler, "seed": 0, "chunk_size": chunk_size,
            "backend": backend}

    def pool(w: int):
        if executor == "dask":
            from distributed import Client, LocalCluster

            cluster = LocalCluster(n_workers=w, processes=True, threads_per_worker=1, dashboard_address=None,
                                   host="127.0.0.1")
            client = Client(cluster)

            def close():
                client.close()
                cluster.close()
            return client, close
        ex = cf.ProcessPoolExecutor(w)
        return ex, ex.shutdown

    out: dict[str, Any] = {"throughput": [], "scene": f"SO(3) Suslov, rkmk4, {round(t_end / h)} steps, final state",
                           "executor": executor, "backend": backend}
    for w in workers:
        ex, close = pool(w)
        try:
            ensemble(system, None, (0.0, t_end), n=2 * w * 64, executor=ex, **{**opts, "chunk_size": 64})  # warm up
            t = time.perf_counter()
            ensemble(system, None, (0.0, t_end), n=n_throughput, executor=ex, **opts)
            dt = time.perf_counter() - t
        finally:
            close()
        out["throughput"].append({"workers": w, "trajectories": n_throughput, "seconds": dt,
                                  "per_second": n_throughput / dt})

    tmp = None
    if store is None:
        tmp = store = tempfile.mkdtemp(prefix="liesuslov-bench-")
    w = min(2, max(workers))
    ex, close = pool(w)
    try:
        ensemble(system, None, (0.0, t_end), n=2 * w * 64, executor=ex, **{**opts, "chunk_size": 64})
        tracemalloc.start()
        t = time.perf_counter()
        ens = ensemble(system, None, (0.0, t_end), n=n, executor=ex, store=Path(store) / "run", overwrite=True,
                       **opts)
        dt = time.perf_counter() - t
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        size = sum(p.stat().st_size for p in (Path(store) / "run").iterdir())
        ok = int(np.count_nonzero(ens.status >= 0))
    finally:
        close()
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    out["memory"] = {"trajectories": n, "workers": w, "seconds": dt, "per_second": n / dt, "succeeded": ok,
                     "tracemalloc_peak_mb": peak / 2**20,
                     "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "store_mb": size / 2**20,
                     # the largest worker process that has ended (the pools are shut down by now)
                     "worker_maxrss_mb": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024}
    return out
