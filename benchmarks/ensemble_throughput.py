"""Ensemble benchmark: trajectories per second against workers, and the peak memory of a 10^6 run.

Run: ``.venv/bin/python benchmarks/ensemble_throughput.py [--n 1000000] [--executor process|dask]``;
it prints the markdown tables of ``docs/ensembles.md`` (see :func:`liesuslov.ensembles.benchmark`).
"""

from __future__ import annotations

import argparse
import os
import platform

from liesuslov.ensembles import benchmark


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=1_000_000, help="trajectories of the memory run")
    p.add_argument("--n-throughput", type=int, default=100_000, help="trajectories of each throughput run")
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    p.add_argument("--executor", choices=("process", "dask"), default="process")
    a = p.parse_args()
    r = benchmark(a.n, tuple(a.workers), n_throughput=a.n_throughput, executor=a.executor)
    print(f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; scene: {r['scene']}; "
          f"executor: {r['executor']}, backend: {r['backend']}\n")
    print("| workers | trajectories | seconds | trajectories/s |\n|---|---|---|---|")
    for row in r["throughput"]:
        print(f"| {row['workers']} | {row['trajectories']:,} | {row['seconds']:.2f} | {row['per_second']:,.0f} |")
    m = r["memory"]
    print(f"\nMemory run: {m['trajectories']:,} trajectories on {m['workers']} workers, final state only, store: "
          f"{m['seconds']:.1f} s ({m['per_second']:,.0f}/s), {m['succeeded']:,} succeeded; peak traced memory of "
          f"the submitting process {m['tracemalloc_peak_mb']:.1f} MB (max RSS {m['maxrss_mb']:.0f} MB, largest "
          f"worker {m['worker_maxrss_mb']:.0f} MB); "
          f"store {m['store_mb']:.1f} MB.")


if __name__ == "__main__":
    main()
