"""Compile the kernel ahead of use: its loops into numba's on-disk cache, several at once.

The compiled loop is specialised per family of kinds (:data:`~.common.FAMILIES`: no group part, the closed
forms so3 and so4, and the matrix algorithms dense and lowrank): the first run of a family on a machine
compiles it (~20 s with no group part, ~30 s for the closed forms, ~70–90 s for the matrices, on a 2-core
machine; numba compiles one function at a time, under a lock), later processes load it from the cache
(< 1 s). :func:`compile_kinds` compiles them in parallel processes — one per core — so a cluster node, a
container image or a test session pays that once, in the wall time of the slowest rather than the sum::

    python -m liesuslov.integrators.kernel.warm            # every family (dense, so3 and none)
    python -m liesuslov.integrators.kernel.warm so4        # the family of one kind

Each process runs one short integration of its kind through the front door (so exactly what a user's
first call compiles is compiled) and the cache decides the rest: a kind already cached costs a process
start and a cache load.

Installing the package runs this module (``build_backend/liesuslov_build.py``) with ``LIESUSLOV_PRECOMPILED=write``:
every family goes into the package's precompiled directory (:data:`~.common.PRECOMPILED_DIR`), read before numba's
cache, so that a first call loads it; what is written here otherwise goes to numba's own cache.

A user's first call of a family that neither holds compiles it the same way, in one child process
(:func:`~.wrapper._compiled`), then loads it from the cache: the loop loaded from numba's cache runs faster
than the same loop compiled in the calling process (measured: an so(3) RKMK4 step 0.58 -> 0.34 µs, 4.3 -> 2.6×
the plain loop; numba issue #10617 reports the same effect), and the compiler's ~10⁶ Python objects do
not stay in the user's process.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: The kind whose scene compiles each family (:data:`~.common.FAMILIES`), the longest to compile first.
FAMILY_KIND = {2: "dense", 1: "so3", 0: "none"}
#: One kind of each family compiles the family: the default of :func:`compile_kinds`, the longest first (the
#: other two then share the second core while it compiles).
FAMILY_KINDS = tuple(FAMILY_KIND.values())
#: Set in the processes :func:`compile_kinds` starts: they compile their loop themselves (see
#: :func:`~.wrapper._compiled`, which otherwise has a first call compile in such a process).
COMPILE_HERE_ENV = "LIESUSLOV_KERNEL_COMPILE_HERE"
#: The kinds and, for each, the (n, reconstruct, constraints) of a scene that runs it.
KIND_SCENES = {
    "none": (3, False, "none"),
    "so3": (3, True, "none"),
    "so4": (4, True, "none"),
    "dense": (5, True, "none"),
    "lowrank": (8, True, "fedorov_kozlov"),
}


def run_kind(kind: str) -> str:
    """One short integration that runs (and so compiles) ``kind`` on the compiled kernel; the backend that ran."""
    import numpy as np

    from ...algebra.inertia import Inertia
    from ...mechanics.system import SuslovSystem
    from ..integrate import integrate

    if kind not in KIND_SCENES:
        raise ValueError(f"kind must be one of {sorted(KIND_SCENES)}, got {kind!r}")
    n, reconstruct, constraints = KIND_SCENES[kind]
    system = SuslovSystem(Inertia.from_mass_tensor(np.diag(np.linspace(1.0, 2.0, n))), constraints=constraints)
    Omega0 = np.zeros((n, n))
    Omega0[0, n - 1], Omega0[n - 1, 0] = 0.3, -0.3
    sol = integrate(system, Omega0, (0.0, 0.1), method="rkmk4", h=0.05, reconstruct=reconstruct, backend="numba")
    return str(sol.stats.get("backend"))


def compile_kinds(kinds=None, processes: int | None = None, timeout: float = 900.0) -> dict[str, float]:
    """Compile the kernel's loop of each kind into numba's cache, ``processes`` kinds at a time.

    Parameters
    ----------
    kinds : iterable of str, optional
        Names of :data:`KIND_SCENES` (default: :data:`FAMILY_KINDS`, which compiles every kind).
    processes : int, optional
        Concurrent processes (default: the number of cores).
    timeout : float
        Seconds one kind may take.

    Returns
    -------
    dict
        Seconds each kind's process took (wall time).

    Raises
    ------
    RuntimeError
        When a kind's process fails (its last line of error output in the message).
    """
    kinds = list(FAMILY_KINDS if kinds is None else kinds)
    for kind in kinds:
        if kind not in KIND_SCENES:
            raise ValueError(f"kinds: each must be one of {sorted(KIND_SCENES)}, got {kind!r}")
    processes = max(1, int(processes or os.cpu_count() or 1))
    # the children import this very package (whatever put it on this process's path) and compile in place
    package_root = str(Path(__file__).resolve().parents[3])
    env = {**os.environ, COMPILE_HERE_ENV: "1",
           "PYTHONPATH": os.pathsep.join(p for p in (package_root, os.environ.get("PYTHONPATH", "")) if p)}
    pending, running, seconds = list(kinds), {}, {}
    while pending or running:
        while pending and len(running) < processes:
            kind = pending.pop(0)
            cmd = [sys.executable, "-c", f"from liesuslov.integrators.kernel.warm import run_kind; run_kind({kind!r})"]
            log = tempfile.TemporaryFile(mode="w+")  # not a pipe: a chatty child cannot block on it
            running[kind] = (subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=log, text=True, env=env), log,
                             time.perf_counter())
        time.sleep(0.05)
        for kind, (proc, log, start) in list(running.items()):
            if proc.poll() is None:
                if time.perf_counter() - start > timeout:
                    proc.kill()
                    raise RuntimeError(f"compiling kind {kind!r} took more than {timeout:.0f} s")
                continue
            del running[kind]
            log.seek(0)
            err = log.read()
            log.close()
            if proc.returncode != 0:
                raise RuntimeError(f"compiling kind {kind!r} failed: {(err.strip().splitlines() or ['?'])[-1]}")
            seconds[kind] = time.perf_counter() - start
    return seconds


if __name__ == "__main__":
    t0 = time.perf_counter()
    for name, sec in compile_kinds(sys.argv[1:] or None).items():
        print(f"{name:8s} {sec:6.1f} s")
    print(f"all      {time.perf_counter() - t0:6.1f} s")
