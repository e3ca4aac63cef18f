"""The store: one ``.npz`` shard per chunk and a JSON manifest, written atomically; read back lazily."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .._io import atomic_create, atomic_write
from ..integrators.problem import SUCCESS_MESSAGE
from .checks import _naming
from .constants import (
    _ARRAYS,
    _EVENT,
    _STAT,
    _SUMMED,
    FORMAT,
    MANIFEST,
    _shard_name,
)
from .result import Ensemble, _read_shard


# ====================================================================== the store
def _merge_stats(chunk_stats: list[dict]) -> dict:
    """Counts (nfev, steps, rejected) summed over chunks (0 for none); the rest (method, form, ...) from the first."""
    out: dict[str, Any] = dict.fromkeys(_SUMMED, 0)
    for st in chunk_stats:
        for k, v in st.items():
            if k in ("wall_time", "batch"):
                continue
            if k in _SUMMED and isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool):
                out[k] = out[k] + v
            elif k not in _SUMMED:
                out.setdefault(k, v)
    return out


def _read_meta(path: Path, run: str | None = None) -> dict:
    with _read_shard(path, run) as z:  # (a damaged meta is a damaged shard: the ValueError names it)
        meta = json.loads(z["__meta__"].tobytes().decode())
        if not isinstance(meta, dict):
            raise ValueError(f"__meta__ is a JSON {type(meta).__name__}, not an object")
    return meta


def _atomic_write(path: Path, write: Callable[[Any], None]) -> None:
    """``write(f)`` on a binary file object, through the package's atomic writer (readers never see half a file)."""

    def through(tmp: str) -> None:
        with open(tmp, "wb") as f:
            write(f)

    atomic_write(path, through)


def _jsonable(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, Path):
        return str(x)
    return str(x)


def _manifest_bytes(manifest: dict) -> bytes:
    return json.dumps(manifest, default=_jsonable, indent=1).encode()


def _claim_store(store: Path, manifest: dict) -> None:
    """Write the run's first manifest, only if the store has none (``FileExistsError`` else): of two runs started
    on one store at once, both passed the check for a manifest and wrote into each other's chunks (an audit).
    The manifest carries the run's id (``manifest["run"]``), which every chunk file of the run carries too."""
    atomic_create(store / MANIFEST, _manifest_bytes(manifest))


def _run_on_disk(store: Path) -> str | None:
    """The run id of the manifest in ``store`` now (None if it has none or cannot be read)."""
    try:
        man = json.loads((store / MANIFEST).read_bytes().decode("utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return man.get("run") if isinstance(man, dict) else None


def _write_manifest(store: Path, manifest: dict) -> None:
    text = _manifest_bytes(manifest)
    _atomic_write(store / MANIFEST, lambda f: f.write(text))


def _write_shard(store: Path, i: int, payload: dict, run: str) -> None:
    arrays = {k: v for k, v in payload.items()
              if k in ("t", *_ARRAYS, "status") or k.startswith(_STAT) or k.startswith(_EVENT)}
    # UTF-8 bytes, not a numpy unicode string (4 bytes a character)
    meta = np.frombuffer(json.dumps({**payload["meta"], "run": run}, default=_jsonable).encode(), dtype=np.uint8)
    _atomic_write(store / _shard_name(i), lambda f: np.savez(f, **arrays, __meta__=meta))


def _read_manifest(root: Path, path: Path) -> dict:
    """The manifest, checked enough that reading the store cannot fail on it with a raw KeyError or TypeError."""
    where = f"store {str(root)!r}: {MANIFEST}"
    # ensemble writes it atomically, so it was damaged or edited afterwards: only a new run restores it
    fix = "run the ensemble again with overwrite=True"
    try:
        man = json.loads(path.read_bytes().decode("utf-8"))
    except OSError as exc:  # the OS's reason (permissions, ...): its own class, the argument named
        message = f"{where} cannot be read ({exc.strerror or exc}); pass a store you can read"
        raise _naming(exc, message) from exc
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{where} is not valid JSON ({exc}); the file is damaged: {fix}") from exc
    if not isinstance(man, dict):
        raise ValueError(f"{where} holds a JSON {type(man).__name__}, not an object; the file is damaged: {fix}")
    if man.get("format") != FORMAT:
        raise ValueError(f"store {str(root)!r}: unknown format {man.get('format')!r} (expected {FORMAT!r})")
    missing = [k for k in ("batch_shape", "bounds") if k not in man]
    if missing:
        raise ValueError(f"{where} lacks {missing}; the file is damaged: {fix}")
    shape, bounds = man["batch_shape"], man["bounds"]
    if not (isinstance(shape, list) and all(type(b) is int and b >= 0 for b in shape)):
        raise ValueError(f"{where}: batch_shape must be a list of integers >= 0, got {shape!r}; {fix}")
    B = math.prod(shape)
    ok = isinstance(bounds, list) and all(isinstance(ab, list) and len(ab) == 2 and all(type(v) is int for v in ab)
                                          for ab in bounds)
    # the chunks cover the batch in order: [0, b0), [b0, b1), ..., [., B)
    if not (ok and [a for a, _ in bounds] == [0] + [b for _, b in bounds[:-1]] and all(a < b for a, b in bounds)
            and (bounds[-1][1] if bounds else 0) == B):
        raise ValueError(f"{where}: bounds must be the chunks [start, stop) covering the batch of {B} in order, got "
                         f"{str(bounds)[:80]}; {fix}")
    for key in ("stats", "meta", "tails"):
        if man.get(key) is not None and not isinstance(man[key], dict):
            raise ValueError(f"{where}: {key} must be a JSON object, got {type(man[key]).__name__}; {fix}")
    return man


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
        trajectories have status -1 and NaN values, and ``message`` says how many are missing. A
        finished run's failed chunks (``stats["failed_chunks"]``) have status -1 too but are not missing.
        ``stats`` has ``nfev``, ``steps`` and ``rejected`` as a Solution's: for a finished store those of the
        run; for a partial one the sums over the chunks in the store (the trajectories computed so far,
        whose status is not -1), with the first chunk's ``method``, ``form``, ... and the run's ``chunks``,
        ``chunk_size``, ``batch``, ``executor``, ``reduce`` and ``seed`` (``failed_chunks`` is then empty,
        ``retries`` and ``wall_time`` absent: they are known only at the end).

    Raises
    ------
    FileNotFoundError
        If ``store`` holds no ``manifest.json``.
    ValueError
        If the manifest is of another format, damaged (not JSON, keys missing or malformed), or no chunk has
        finished yet; a damaged shard, or one written by another run than the manifest's (two runs on one
        store, one with ``overwrite=True``), is a ValueError naming it when it is read.
    """
    if not isinstance(store, (str, os.PathLike)):
        raise TypeError(f"store must be a path (str or os.PathLike), got {type(store).__name__}")
    root = Path(store)
    path = root / MANIFEST
    if not path.is_file():
        raise FileNotFoundError(f"store {str(root)!r} holds no {MANIFEST}: not an ensemble store (or the run "
                                "has not started); pass the directory given as ensemble(..., store=DIR)")
    man = _read_manifest(root, path)
    bounds, run = man["bounds"], man.get("run")
    if run is not None and not isinstance(run, str):
        raise ValueError(f"store {str(root)!r}: {MANIFEST}: run must be a string, got {type(run).__name__}; the file "
                         "is damaged: run the ensemble again with overwrite=True")
    present = [(root / _shard_name(i)).is_file() for i in range(len(bounds))]
    first = next((i for i, p in enumerate(present) if p), None)
    t, tails, meta = man.get("t"), man.get("tails"), man.get("meta", {})
    if t is None or tails is None:  # the run stopped before its end: read them off a finished shard
        if first is None:
            raise ValueError(f"store {str(root)!r}: no chunk has finished yet (0 of {len(bounds)}); nothing to read")
        with _read_shard(root / _shard_name(first), run) as z:
            t = z["t"]
            tails = {k: z[k].shape[2:] for k in _ARRAYS if k in z.files}
        meta = _read_meta(root / _shard_name(first), run)
    stats = dict(man.get("stats", {}))
    # a finished run writes no shard for a chunk that failed: those are in failed_chunks, not missing
    failed = {int(f["chunk"]) for f in stats.get("failed_chunks", [])} if man.get("complete") else set()
    missing = [i for i, p in enumerate(present) if not p and i not in failed]
    message = man.get("message", "")
    if missing:
        # (the manifest's message is a finished run's: its success is not this store's)
        rest = "" if message in ("", SUCCESS_MESSAGE) else f" The run's message: {message}"
        message = (f"{len(missing)} of {len(bounds)} chunks missing from the store (status -1, values NaN); "
                   f"the run was interrupted or is still going, or a chunk file was removed.{rest}").strip()
    if missing or not man.get("complete"):
        # the manifest's counts are those of a finished run: here, the sums over the chunks in the store
        stats = {k: v for k, v in stats.items() if k not in _SUMMED}
        shard_stats = [_read_meta(root / _shard_name(i), run).get("stats", {}) for i, p in enumerate(present) if p]
        stats = {**_merge_stats(shard_stats), **stats}
        stats.setdefault("failed_chunks", [])
    traj_stats = man.get("trajectory_stats")
    if traj_stats is None:
        traj_stats = {}
        if first is not None:
            with _read_shard(root / _shard_name(first), run) as z:
                traj_stats = {k[len(_STAT):]: z[k].dtype.str for k in z.files if k.startswith(_STAT)}
    return Ensemble(t=t, batch_shape=man["batch_shape"], bounds=bounds, tails=tails, stats=stats,
                    n=meta.get("n"), algebra_name=meta.get("algebra_name", ""), message=message,
                    store=root, present=present, traj_stats=traj_stats, complete=not missing,
                    n_events=int(meta.get("events", 0) or 0), run=run)
