"""The progress bar of integrate, ensemble and the research tools (tqdm, the optional ``progress`` extra)."""

from __future__ import annotations


def progress_bar(total: int, unit: str, desc: str | None = None, *, leave: bool = True):
    """A ``tqdm`` bar of ``total`` ``unit``s; a ValueError saying how to install tqdm when it is missing
    (progress=True is the only thing that needs it, so it is imported here, on demand)."""
    try:
        from tqdm.auto import tqdm
    except ImportError as exc:
        raise ValueError("progress=True (the CLI's --progress) needs tqdm: pip install 'liesuslov[progress]'") from exc
    return tqdm(total=total, unit=unit, desc=desc, leave=leave, mininterval=0.0 if not leave else 0.1)
