"""The machine a benchmark ran on: CPU, cores, versions, date and git commit (for the report)."""

from __future__ import annotations

import datetime as _dt
import os
import platform
import subprocess
from pathlib import Path

import numpy as np


def _version(dist: str) -> str:
    """The installed version of a distribution, or "not installed"."""
    from importlib import metadata

    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "not installed"


def _importable_version(dist: str) -> str:
    """:func:`_version`, saying so when the distribution is installed but cannot be imported (a broken numba
    is as absent as a missing one: the compiled targets are not measured)."""
    version = _version(dist)
    if version != "not installed":
        try:
            __import__(dist)
        except ImportError as exc:
            return f"{version} (cannot be imported: {exc})"
    return version


def machine_info() -> dict:
    """CPU model, cores, Python / numpy / scipy / numba / liesuslov versions, date, git commit."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        usable = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        usable = os.cpu_count() or 0
    import liesuslov as ls

    commit = ""
    here = Path(__file__).resolve().parents[1]  # the liesuslov package: its changes count
    try:
        res = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=here, capture_output=True, text=True,
                             timeout=5, check=False)
        if res.returncode == 0:
            commit = res.stdout.strip()
            dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", "."], cwd=here,
                                   capture_output=True, text=True, timeout=5, check=False)
            if dirty.returncode == 0 and dirty.stdout.strip():
                commit += " + uncommitted changes"
    except (OSError, subprocess.SubprocessError):
        pass
    return {"cpu": cpu, "cores": f"{usable} usable of {os.cpu_count()}", "platform": platform.platform(),
            "python": platform.python_version(), "numpy": np.__version__, "scipy": _version("scipy"),
            "numba": _importable_version("numba"), "liesuslov": getattr(ls, "__version__", "?"),
            "commit": commit or "unknown",
            "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS", "not set (the library's default)"),
            "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")}
