"""The store: one ``.npz`` shard per chunk and a JSON manifest, written atomically; read back lazily."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .._io import atomic_write
from .constants import (
    _ARRAYS,
    _STAT,
    FORMAT,
    MANIFEST,
    _shard_name,
)
from .result import Ensemble


# ====================================================================== the store
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


def _write_manifest(store: Path, manifest: dict) -> None:
    text = json.dumps(manifest, default=_jsonable, indent=1).encode()
    _atomic_write(store / MANIFEST, lambda f: f.write(text))


def _write_shard(store: Path, i: int, payload: dict) -> None:
    arrays = {k: v for k, v in payload.items() if k in ("t", *_ARRAYS, "status") or k.startswith(_STAT)}
    # UTF-8 bytes, not a numpy unicode string (4 bytes a character)
    meta = np.frombuffer(json.dumps(payload["meta"], default=_jsonable).encode(), dtype=np.uint8)
    _atomic_write(store / _shard_name(i), lambda f: np.savez(f, **arrays, __meta__=meta))


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
