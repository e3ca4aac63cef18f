"""The benchmark's command line: ``python -m liesuslov.bench`` and ``liesuslov bench`` share these options."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from .config import BenchConfig
from .run import run_bench
from .scenes import SCENES
from .tables import fmt, ms
from .targets import AGREEMENT_TOL


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the benchmark's options to ``parser`` (used by ``liesuslov bench`` and ``python -m liesuslov.bench``)."""
    parser.add_argument("--out", default="liesuslov-bench", metavar="DIR",
                        help="output folder for the CSV files, summary.md and the plots (default: liesuslov-bench)")
    parser.add_argument("--quick", action="store_true",
                        help="reduced set (rkmk4, rkmk45, rkmk853 x exp/cayley, 3 settings each; under a minute)")
    parser.add_argument("--scenes", default=None, metavar="LIST",
                        help=f"comma-separated scenes (default: all of {', '.join(SCENES)})")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--repeats", type=int, default=None, metavar="N",
                        help="timed repeats after the warm-up run (default 5; --quick 1)")
    parser.add_argument("--docs", default=None, metavar="PATH",
                        help="also write the documentation page (e.g. docs/performance.md; plots go to img/ beside it)")
    parser.add_argument("--backend", default=None, choices=("auto", "numpy", "numba"),
                        help="passed to integrate(backend=...) when liesuslov has the option (default: the "
                             "library's default; --quick: numpy, which needs no compilation)")


def run_from_args(args: argparse.Namespace) -> int:
    """Run the benchmark from parsed arguments (see :func:`add_arguments`); returns the exit status."""
    scenes = None if args.scenes is None else [s for s in args.scenes.split(",") if s.strip()]
    config = BenchConfig.quick() if args.quick else BenchConfig.full()
    if getattr(args, "backend", None) is not None:
        config = replace(config, backend=args.backend)
    try:
        report = run_bench(args.out, quick=args.quick, scenes=scenes, progress=not args.no_progress,
                           repeats=args.repeats, docs=args.docs, config=config)
    except ValueError as exc:
        print(f"liesuslov bench: error: {exc}", file=sys.stderr)
        return 2
    print(f"liesuslov bench: {len(report.rows)} runs in {report.elapsed:.1f} s")
    for r in report.ratios:
        ratio = f"{r['ratio']:.3f}" if np.isfinite(r["ratio"]) else "—"
        print(f"  {r['scene']:<17} {r['level']:.0e}: liesuslov {ms(r['liesuslov_time']):>10} "
              f"({r['liesuslov_route'] or '—'}), scipy {ms(r['scipy_time']):>10} ({r['scipy_route'] or '—'}), "
              f"ratio {ratio}")
    for r in report.targets:
        if "agreement" in r:  # the floor must compute what the library computes, or its ratio means nothing
            verdict = "agrees" if r["agrees"] else "DISAGREES"
            print(f"  floor check, n = {r['n']}{', batch' if 'batch' in r else ''}: max |floor - library| = "
                  f"{r['agreement']:.1e} ({verdict}, tolerance {AGREEMENT_TOL:.0e})")
    for t in report.target_summary:
        met = "—" if t["met"] is None or not np.isfinite(t["value"]) else ("met" if t["met"] else "not met")
        why = f" [{t['why']}]" if t.get("why") else ""
        print(f"  target {t['target']:<12} {fmt(t['value'], '.3g'):>8} (goal {t['goal']:g}, {met}): {t['what']}{why}")
    for name, p in report.paths.items():
        if not name.startswith("plot"):
            print(f"wrote {p}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m liesuslov.bench``."""
    parser = argparse.ArgumentParser(prog="python -m liesuslov.bench",
                                     description="liesuslov work-precision benchmark against scipy's solve_ivp")
    add_arguments(parser)
    return run_from_args(parser.parse_args(argv))
