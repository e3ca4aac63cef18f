"""Writing files so that nothing is ever half-written: the one atomic writer of the package; and reading the
``.npz`` files it wrote, a damaged or foreign one a clear error (:func:`read_npz`).

:func:`atomic_write` creates a file through a temporary name in the same folder and renames it into
place (``os.replace`` is atomic on POSIX and Windows within one file system), so a reader, a crash or
a full disk never leaves a truncated file. :func:`publish` moves files prepared in a staging folder
into the output folder, for commands that write several files (``liesuslov run``, the benchmark).
"""

from __future__ import annotations

import os
import secrets
import zipfile
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["atomic_write", "atomic_create", "write_text", "publish", "read_npz"]


@contextmanager
def read_npz(path: Path, what: str, fix: str) -> Iterator:
    """``np.load(path)`` of an ``.npz`` the package wrote, for the ``with`` body that reads it; any failure there
    — a truncated, overwritten or foreign file, a member or key missing — a ValueError naming ``what`` (e.g.
    "the file 'run.npz'") and saying ``fix``. A missing file stays a FileNotFoundError.

    numpy's own message for a file that is not an ``.npz`` suggests ``allow_pickle=True``, which is wrong here
    (the package writes no object arrays); members are read lazily (``z[key]``), so the whole body is covered:
    keep it to reading the file.
    """
    import numpy as np

    if not Path(path).exists():
        raise FileNotFoundError(f"{what} does not exist")
    try:
        with np.load(path, allow_pickle=False) as z:
            yield z
    except (ValueError, KeyError, TypeError, OSError, EOFError, zipfile.BadZipFile) as exc:
        detail = "" if "pickle" in str(exc) else f": {exc}"  # (not numpy's advice to load it with pickle)
        raise ValueError(f"{what} is damaged or was not written by liesuslov ({type(exc).__name__} reading it"
                         f"{detail}); {fix}") from exc


def _new_file(p: Path) -> tuple[int, str]:
    """``(fd, name)`` of a new file ``.{stem}-{random}{suffix}`` beside ``p``, open for writing and created
    exclusively with mode 0o666 less the umask — the mode an ordinary ``open(path, "w")`` gives, applied by the
    system (``mkstemp`` makes 0o600, and reading the umask means setting it: 0 for a moment, in which a file
    another thread creates is world-writable)."""
    flags = os.O_CREAT | os.O_EXCL | os.O_WRONLY | getattr(os, "O_BINARY", 0)
    for _ in range(100):
        name = str(p.parent / f".{p.stem}-{secrets.token_hex(6)}{p.suffix}")
        try:
            return os.open(name, flags, 0o666), name
        except FileExistsError:  # (48 random bits: another writer's name, by chance)
            continue
    raise FileExistsError(f"no free temporary name beside {p} after 100 tries")


def atomic_write(path, write: Callable[[str], object]) -> Path:
    """Create ``path`` through ``write(tmp)`` on a temporary name in the same folder, then rename it.

    Parameters
    ----------
    path : str or Path
        The file to create or replace; its folder is created if missing.
    write : callable
        ``write(tmp_path: str)`` writes the whole file (e.g. ``fig.savefig``, ``np.savez``,
        ``Path.write_text``).

    Returns
    -------
    Path
        ``path``. On any error the temporary file is removed and ``path`` is left as it was.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = _new_file(p)
    os.close(fd)
    try:
        write(tmp)  # (it truncates the file it opens: the mode given at creation stays)
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p


def atomic_create(path, data: bytes) -> Path:
    """Create ``path`` holding ``data``, whole, only if no file has that name: else ``FileExistsError``.

    The claim of a name by two writers at once (two runs started on one ensemble store): the file is written
    under a temporary name and hard-linked into place (``os.link`` fails if the name exists, and readers see
    the whole file or none); on a file system without hard links, an exclusive create (``open(path, "xb")``).

    Parameters
    ----------
    path : str or Path
        The file to create; its folder must exist.
    data : bytes
        Its whole content.

    Returns
    -------
    Path
        ``path``.
    """
    p = Path(path)
    fd, tmp = _new_file(p)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        try:
            os.link(tmp, p)
        except FileExistsError:
            raise
        except OSError:  # no hard links here (FAT, some network or FUSE file systems)
            with open(p, "xb") as f:
                f.write(data)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return p


def write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8, newlines as given) to ``path`` atomically."""
    return atomic_write(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8", newline=""))


def publish(stage, out, names: Iterable[str]) -> list[str]:
    """Move the files ``names`` from the staging folder ``stage`` into ``out`` (same file system).

    Each move is an atomic rename; the staging folder is the caller's to remove. Returns the paths in ``out``.
    """
    stage, out = Path(stage), Path(out)
    paths = []
    for name in names:
        os.replace(stage / name, out / name)
        paths.append(str(out / name))
    return paths
