"""Benchmark (not a test): trajectories per second against workers, memory of a large run with a store."""

from __future__ import annotations

import concurrent.futures as cf
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from .run import ensemble
from .sampling import Perturbation


# ====================================================================== benchmark (not a test)
def _benchmark_system():
    from ..algebra import Inertia
    from ..mechanics import LinearPotential, SuslovSystem

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
    n_throughput : int
        Trajectories of each throughput run.
    chunk_size : int
        Trajectories per chunk (task), in every run.
    h : float
        RKMK4's step.
    t_end : float
        Each trajectory is integrated over ``(0, t_end)``: ``t_end / h`` steps.
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
