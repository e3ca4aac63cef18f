"""The front door: :func:`run_bench` runs the configured measurements and writes the report."""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from . import targets
from .config import BenchConfig, BenchReport, integrate_kwargs
from .files import write_outputs
from .machine import machine_info
from .metrics import fit_exponent, ratio_table
from .runners import (
    build_reference,
    execute_tasks,
    long_run,
    plan_tasks,
    scaling_backends,
    scaling_sweep,
    throughput_sweep,
)
from .scenes import build_scene


def run_bench(out_dir, *, quick: bool = False, scenes: Sequence[str] | None = None, progress: bool = True,
              repeats: int | None = None, docs=None, config: BenchConfig | None = None) -> BenchReport:
    """Run the benchmark and write its report into ``out_dir``.

    Parameters
    ----------
    out_dir : str or Path
        Output folder (created). Receives ``results.csv``, ``ratios.csv``, ``throughput.csv``,
        ``nscaling.csv``, ``longrun.csv`` (those measured), ``summary.md`` and PNG plots.
    quick : bool
        The reduced preset (:meth:`BenchConfig.quick`, under a minute); else :meth:`BenchConfig.full`.
    scenes : sequence of str, optional
        Keys of :data:`SCENES` (default: all).
    progress : bool
        A tqdm progress bar over the runs (on stderr).
    repeats : int, optional
        Timed repeats after the warm-up (default 5, quick 1).
    docs : str or Path, optional
        Also write the documentation page there (plots copied to ``img/`` next to it).
    config : BenchConfig, optional
        A full configuration (overrides ``quick``; ``scenes`` and ``repeats`` still apply when given).

    Returns
    -------
    BenchReport

    Raises
    ------
    ValueError
        An unknown scene (the message lists the valid ones), ``repeats < 1``, or an invalid configuration.
    """
    if config is None:
        config = BenchConfig.quick() if quick else BenchConfig.full()
    if scenes is not None:
        if isinstance(scenes, str):
            scenes = [s for s in scenes.split(",") if s.strip()]
        config = replace(config, scenes=tuple(scenes))
    if repeats is not None:
        config = replace(config, repeats=repeats)
    config = config.validated()
    extra_kw = integrate_kwargs(config.backend)
    out = Path(out_dir)
    start = time.perf_counter()
    built = {k: build_scene(k) for k in config.scenes}
    plans = {k: plan_tasks(config, built[k]) for k in config.scenes}
    total = (sum(len(p) + 1 for p in plans.values()) + len(config.batch_sizes) * len(config.batch_dims)
             + len(config.scaling_sizes) * len(config.charts) * len(scaling_backends(config))
             + (1 if config.long_run_steps else 0) + (5 if config.targets else 0))
    bar = _bar(total, progress)

    def tick(desc: str | None = None) -> None:
        if bar is not None:
            if desc:
                bar.set_postfix_str(desc, refresh=False)
            bar.update(1)

    report = BenchReport(machine=machine_info())
    try:
        for key in config.scenes:
            scene = built[key]
            entry = {"how": scene.reference, "title": scene.title, "t1": scene.t1}
            try:
                ref = build_reference(scene, extra_kw)
            except (ValueError, RuntimeError, FloatingPointError, np.linalg.LinAlgError) as exc:
                # Without a reference no error can be measured: the scene is reported as failed, the rest runs.
                report.references[key] = {**entry, "uncertainty": float("nan"), "details": {},
                                          "how": f"reference failed ({type(exc).__name__}: {exc})"}
                for _ in range(len(plans[key]) + 1):
                    tick(f"{key}: reference failed")
                continue
            report.references[key] = {**entry, "uncertainty": ref.uncertainty, "details": ref.details}
            tick(f"{key}: reference")
            report.rows.extend(execute_tasks(plans[key], scene, ref, config.repeats, extra_kw,
                                             lambda task, key=key: tick(f"{key}: {task.route} "
                                                                        f"{task.kind}={task.value:.2g}")))
        report.throughput = throughput_sweep(config, extra_kw, lambda: tick("throughput"))
        report.scaling = scaling_sweep(config, extra_kw, lambda: tick("n-scaling"))
        report.scaling_exponent = fit_exponent(report.scaling)
        report.longrun = long_run(config, extra_kw, lambda: tick("long run"))
        if config.targets:
            report.targets = targets.run_targets(config, extra_kw, lambda: tick("targets"))
    finally:
        if bar is not None:
            bar.close()
    report.ratios = ratio_table(report.rows, config.scenes, config.levels, report.references)
    if config.targets:
        report.target_summary = targets.summary(report.targets, report.scaling_exponent, report.scaling,
                                                report.ratios)
    report.elapsed = time.perf_counter() - start
    write_outputs(report, config, out, docs)
    return report


def _bar(total: int, on: bool):
    """A tqdm progress bar on stderr, or None (off, or tqdm missing)."""
    if not on:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None
    return tqdm(total=total, unit="run", desc="liesuslov bench", file=sys.stderr, dynamic_ncols=True)
