"""What an ensemble returns: :class:`Ensemble`, arrays as a Solution's, in memory or read lazily from a store."""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .._io import read_npz
from .constants import (
    _ARRAYS,
    _EVENT,
    _EVENT_FIELDS,
    _STAT,
    _shard_name,
)


# ====================================================================== reading a shard
@contextmanager
def _read_shard(path: Path, run: str | None = None):
    """``np.load`` of a store's shard, a damaged one (truncated, overwritten, not an .npz) a ValueError naming it
    (:func:`~liesuslov._io.read_npz`: keep the ``with`` body to reading the shard), and one written by another run
    than ``run`` (the manifest's id, when it has one) a ValueError too."""
    other = run
    with read_npz(path, f"store {str(path.parent)!r}: the shard {path.name}", "delete it (its trajectories then read "
                  "as missing) or run the ensemble again with overwrite=True") as z:
        other = _shard_run(z) if run is not None else None
        if other == run:
            yield z
    if other != run:  # (a chunk file without an id under a manifest with one: an older version wrote it)
        raise ValueError(f"store {str(path.parent)!r}: the shard {path.name} was written by another run than the "
                         "manifest's (two runs wrote this store at once, one of them with overwrite=True): its "
                         "numbers are not this ensemble's; run the ensemble again with overwrite=True")


def _shard_run(z) -> str | None:
    """The run id in a shard's ``__meta__`` (None in a store written before runs had ids)."""
    meta = json.loads(z["__meta__"].tobytes().decode())
    return meta.get("run") if isinstance(meta, dict) else None


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
    events : list of EventRecord
        With ``events=`` (an option of integrate): the crossings, as a Solution's (empty without events).
    status : ndarray of int, shape (...)
        0 reached the end, 1 stopped by a terminal event, -1 failed (a failed or missing chunk too).
    success : bool
        Every status >= 0.
    stats : dict
        ``nfev``, ``steps``, ``rejected`` summed over the chunks computed (always present, 0 if none was;
        for a partial store the chunks in it, see :func:`open_ensemble`); ``chunks``, ``chunk_size``,
        ``failed_chunks`` (list of ``{"chunk", "start", "stop", "error"}``), ``retries``,
        ``wall_time``, ``executor``, ``seed`` (the entropy of a sampler run), and the first chunk's
        ``method``, ``chart``, ``form``, ``backend``; statistics integrate reports per trajectory
        (arrays of the batch shape, e.g. ``trajectory_steps``) assembled over the whole batch (0 or
        NaN for a failed or missing chunk).
    batch_shape : tuple of int
    complete : bool
        False for a store some of whose chunks are missing (their status is -1, their values NaN): a run
        interrupted or still going. A finished run's failed chunks (status -1 too) are not missing.
    store : Path or None
    """

    _run = None  # (an Ensemble pickled in memory before stores had run ids has none)

    def __init__(self, *, t, batch_shape, bounds, tails, stats, n=None, algebra_name="", message="",
                 arrays=None, status=None, store=None, present=None, traj_stats=None, complete=None,
                 n_events=0, event_parts=None, run=None):
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
        self._run = run  # the id of the run that wrote the store: every shard read is checked against it
        self._present = present
        self._n_events = int(n_events)
        # in memory: one dict of event arrays (shard keys) per finished chunk; a store reads its shards
        self._event_parts = event_parts
        # False only for a store with chunks missing (not for a finished run's failed chunks)
        self._complete = (present is None or all(present)) if complete is None else bool(complete)

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
        from ..algebra import so

        omega = self.omega
        Omega = so(self.n).hat(omega)
        gone = np.isnan(omega).any(axis=-1)  # stopped, failed or missing: NaN on the diagonal too, as a Solution
        if gone.any():
            Omega[gone] = np.nan
        return Omega

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
                with _read_shard(self._shard(i), self._run) as z:
                    if _STAT + name in z.files:
                        out[a:b] = z[_STAT + name]
        return out

    @property
    def events(self) -> list:
        """One :class:`~liesuslov.EventRecord` per event function (``events=`` of integrate), as a Solution's:
        the crossings of every trajectory computed, sorted by (index, t), ``index`` flat over the whole batch."""
        from ..integrators import EventRecord

        if self._event_parts is not None:
            parts = self._event_parts
        else:
            parts = []
            for i in range(len(self._bounds)):
                if self._has(i):
                    with _read_shard(self._shard(i), self._run) as z:
                        parts.append({k: z[k] for k in z.files if k.startswith(_EVENT)})
        out = []
        for j in range(self._n_events):
            cols = {}
            for f in _EVENT_FIELDS:
                key = f"{_EVENT}{j}__{f}"
                found = [p[key] for p in parts if key in p]
                cols[f] = np.concatenate(found) if found else None
            if cols["t"] is None:  # no chunk computed: empty arrays of the right trailing shapes
                cols["t"], cols["index"] = np.empty(0), np.empty(0, dtype=np.int64)
                cols["omega"] = np.empty((0,) + self._tails["omega"])
            # by trajectory; a trajectory's crossings come from one chunk, sorted by t (as integrate gives
            # them), which a stable sort keeps
            order = np.argsort(cols["index"], kind="stable")
            cols = {f: None if v is None else v[order] for f, v in cols.items()}
            out.append(EventRecord(n=self.n, algebra_name=self.algebra_name, **cols))
        return out

    @property
    def status(self) -> np.ndarray:
        if self._status is not None:
            return self._status
        st = np.full(self._B, -1, dtype=np.int64)
        for i, (a, b) in enumerate(self._bounds):
            if self._has(i):
                with _read_shard(self._shard(i), self._run) as z:
                    st[a:b] = z["status"]
        return st.reshape(self.batch_shape)

    @property
    def success(self) -> bool:
        """True iff every trajectory's status is >= 0 (reached the end or stopped by a terminal event)."""
        return bool(np.all(self.status >= 0))

    @property
    def complete(self) -> bool:
        return self._complete

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
                with _read_shard(self._shard(i), self._run) as z:
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
                # read, then yield outside: the caller's errors are its own
                with _read_shard(self._shard(i), self._run) as z:
                    arrays = {k: z[k] for k in (*_ARRAYS, "status") if k in z.files}
                yield a, b, arrays

    def to_solution(self):
        """All of it as a :class:`~liesuslov.Solution` (in memory)."""
        from ..integrators import Solution

        return Solution(t=self.t, xi=self.xi, omega=self.omega, Gamma=self.Gamma, g=self.g, stats=self.stats,
                        status=self.status, message=self.message, n=self.n, algebra_name=self.algebra_name,
                        events=self.events)

    def to_xarray(self):
        """An ``xarray.Dataset`` (dims ``time``, ``batch_0``, ..., components); needs ``liesuslov[xarray]``."""
        from ..xarray_io import solution_to_xarray

        return solution_to_xarray(self)

    def __getstate__(self):
        state = dict(self.__dict__)
        if self.store is not None:  # a store-backed ensemble travels as its path: reread the manifest
            state = {"store": self.store}
        return state

    def __setstate__(self, state):
        if set(state) == {"store"}:
            from .store import open_ensemble  # the store builds Ensembles: imported here, not at the top

            self.__dict__.update(open_ensemble(state["store"]).__dict__)
        else:
            self.__dict__.update(state)

    def __repr__(self) -> str:
        where = f", store={str(self.store)!r}" if self.store is not None else ""
        status = self.status
        ok = int(np.count_nonzero(status >= 0))
        return (f"Ensemble(batch_shape={self.batch_shape}, t: {self.t.shape}, success={ok}/{status.size}"
                f"{'' if self.complete else ', incomplete'}{where})")
