"""The report as text: CSV, markdown tables and the generated sections of ``summary.md`` and the docs page."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from .config import GOAL_RATIO, BenchConfig, BenchReport


def fmt(x, spec: str = ".3g") -> str:
    """A cell: numbers in ``spec`` (nan, inf spelled out), bools and strings as they are, None empty."""
    if x is None or x == "":
        return ""
    if isinstance(x, (bool, np.bool_)):
        return str(bool(x))
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        if math.isnan(x):
            return "nan"
        if math.isinf(x):
            return "inf"
        return format(float(x), spec)
    return str(x)


def csv_text(rows: list[dict], columns: Sequence[str] | None = None) -> str:
    """CSV of ``rows`` (columns: the given ones, else every key in order of appearance; floats in full)."""
    if columns is None:
        columns = []
        for r in rows:
            columns.extend(k for k in r if k not in columns)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([fmt(r.get(c, ""), ".17g") if isinstance(r.get(c), (float, np.floating)) else fmt(r.get(c, ""))
                    for c in columns])
    return buf.getvalue()


def md_table(header: Sequence[str], body: Iterable[Sequence[Any]]) -> str:
    """A markdown table; ``|`` inside cells is escaped."""
    def cell(c: Any) -> str:
        return str(c).replace("|", "\\|")
    lines = ["| " + " | ".join(cell(c) for c in header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(cell(c) for c in row) + " |" for row in body]
    return "\n".join(lines)


def status_cell(row: dict) -> str:
    """A row's status, with the reason when it is not "ok"."""
    return row["status"] if row["status"] == "ok" else f"{row['status']}: {row.get('message', '')}"


def ms(t: float) -> str:
    """Seconds as milliseconds, or a dash when not measured."""
    if not np.isfinite(t):
        return "—"
    return f"{t * 1e3:.3g} ms"


def summary_sections(report: BenchReport, config: BenchConfig, image_dir: str | None) -> list[str]:
    """The generated markdown (shared by summary.md and the docs page)."""
    sec = []
    m = report.machine
    sec.append("## Machine\n\n" + md_table(["", ""], [
        ["CPU", m["cpu"]], ["cores", m["cores"]], ["platform", m["platform"]], ["Python", m["python"]],
        ["numpy", m["numpy"]], ["scipy", m["scipy"]], ["numba", m["numba"]], ["liesuslov", m["liesuslov"]],
        ["commit", m["commit"]], ["date", m["date"]], ["OPENBLAS_NUM_THREADS", m.get("blas_threads", "?")],
        ["mode", f"{config.preset}, backend asked: {config.backend or 'the default (auto)'}, "
                 f"{report.elapsed:.0f} s in all"],
        ["backends seen", ", ".join(sorted({str(r.get('backend')) for r in report.rows
                                           if r["library"] == "liesuslov" and r.get("backend")})) or "—"]]))
    if report.target_summary:
        sec.append(targets_section(report))
    # ratio table, compact
    levels = list(config.levels)
    body = []
    for s in config.scenes:
        cells = [s]
        for lv in levels:
            r = next(x for x in report.ratios if x["scene"] == s and x["level"] == lv)
            if np.isfinite(r["ratio"]):
                mark = "✓" if r["goal_met"] else "✗"
                cells.append(f"{r['ratio']:.2f} {mark}" + ("" if r["reliable"] else " (†)"))
            else:
                cells.append("—")
        body.append(cells)
    sec.append("## Ratio table\n\nTime of the fastest liesuslov route divided by the time of the fastest scipy "
               f"route reaching the same error at t1 (goal: ≤ {GOAL_RATIO}; ✓ met, ✗ not met; — a side never "
               "reached the level in its sweep; † level within 10× the reference's own uncertainty).\n\n"
               + md_table(["scene"] + [f"{lv:.0e}" for lv in levels], body))
    body = []
    for r in report.ratios:
        body.append([r["scene"], f"{r['level']:.0e}", r["liesuslov_route"] or "—", ms(r["liesuslov_time"]),
                     r["scipy_route"] or "—", ms(r["scipy_time"]),
                     f"{r['ratio']:.3f}" if np.isfinite(r["ratio"]) else "—"])
    sec.append("### Fastest routes per level\n\n" + md_table(
        ["scene", "error", "fastest liesuslov", "time", "fastest scipy", "time", "ratio"], body))
    # references
    body = [[s, report.references[s]["title"], f"{report.references[s]['t1']:.6g}",
             f"{report.references[s]['uncertainty']:.1e}", report.references[s]["how"]] for s in config.scenes]
    sec.append("## Scenes and references\n\nThe reference's uncertainty is the largest disagreement among its "
               "independent determinations (closed form, liesuslov rkmk853 and scipy DOP853 at rtol 1e-13).\n\n"
               + md_table(["scene", "description", "t1", "uncertainty", "reference"], body))
    # structure
    body = []
    for s in config.scenes:
        for lib in ("liesuslov", "scipy"):
            rs = [r for r in report.rows if r["scene"] == s and r["library"] == lib and r["status"] == "ok"]
            if not rs:
                continue

            def mx(key, rs=rs):
                v = [r[key] for r in rs if np.isfinite(r[key])]
                return f"{max(v):.1e}" if v else "—"
            tight = min(rs, key=lambda r: r["error"] if np.isfinite(r["error"]) else math.inf)
            body.append([s, lib, mx("orth_defect"), mx("sphere_defect"), mx("constraint_defect"),
                         f"{tight['error']:.1e} ({tight['route']})", f"{tight['drift_energy']:.1e}"])
    sec.append("## Structure\n\nLargest defects over every run of the sweep (maxima over all steps): the "
               "orthogonality defect max|gᵀg − I|, the sphere defect max||Γ| − 1|, the constraint defect "
               "max|⟨aⁱ, Ω⟩|; and the most accurate run with its energy drift.\n\n"
               + md_table(["scene", "library", "orthogonality", "sphere", "constraints", "best error (route)",
                            "its energy drift"], body))
    if image_dir is not None and config.plots:
        imgs = [f"![{s}]({image_dir}/bench-{s}.png)" for s in config.scenes]
        sec.append("## Work-precision plots\n\nError at t1 against wall time (log-log); solid: exponential "
                   "chart, dotted: Cayley; black dashed: scipy.\n\n" + "\n\n".join(imgs))
    if report.throughput:
        body = [[r["n"], r["scene"], r["batch"], r.get("steps", ""), fmt(r.get("traj_steps_per_s"), ".3g"),
                 fmt(r.get("ns_per_traj_step"), ".4g"), fmt(r.get("us_per_step"), ".4g"), r.get("backend", ""),
                 status_cell(r)]
                for r in report.throughput]
        txt = ("## Batch throughput\n\nRKMK4 (exponential chart, h = 0.01) with reconstruction on SO(n), random "
               "initial data in D, one vectorised run per batch; output at the final time only.\n\n"
               + md_table(["n", "scene", "batch", "steps", "trajectory-steps/s", "ns per trajectory-step",
                            "µs per step", "backend", "status"], body))
        if image_dir is not None and config.plots:
            txt += f"\n\n![throughput]({image_dir}/bench-throughput.png)"
        sec.append(txt)
    if report.scaling:
        body = [[r["n"], r["chart"], r.get("requested", ""), r.get("steps", ""), fmt(r.get("us_per_step"), ".4g"),
                 fmt(r.get("orth_defect"), ".1e"), r.get("form", ""), r.get("backend", ""),
                 status_cell(r)]
                for r in report.scaling]
        fits = "; ".join(f"{c}: time per step ∝ n^{v['exponent']:.2f} (fit over n = {v['sizes']})"
                         for c, v in report.scaling_exponent.items()) or "no fit (fewer than two sizes)"
        txt = ("## Cost per step against n\n\nKlebsh–Tisserand with the Fedorov–Kozlov D (I = linspace(1, 2, n)), "
               "RKMK4, h = 0.01, reconstruction of g ∈ SO(n), one trajectory. Fitted growth: " + fits
               + " (the goal is n², not n³).\n\n"
               + md_table(["n", "chart", "backend asked", "steps", "µs per step", "max|gᵀg − I|", "form",
                            "backend ran", "status"], body))
        if image_dir is not None and config.plots:
            txt += f"\n\n![n-scaling]({image_dir}/bench-nscaling.png)"
        sec.append(txt)
    if report.longrun:
        body = [[r["scene"], r["method"], r["h"], r["steps"], fmt(r.get("wall_time"), ".3g"),
                 fmt(r.get("us_per_step"), ".3g"), fmt(r.get("orth_defect"), ".1e"),
                 fmt(r.get("sphere_defect"), ".1e"), fmt(r.get("energy_error"), ".1e"), fmt(r.get("energy0"), ".4g"),
                 status_cell(r)]
                for r in report.longrun]
        sec.append("## Long run\n\nOne trajectory, fixed step, output every 1% of the interval.\n\n"
                   + md_table(["scene", "method", "h", "steps", "wall time (s)", "µs per step", "max|gᵀg − I|",
                                "max||Γ| − 1|", "max|E − E0|", "E0", "status"], body))
    return sec


def targets_section(report: BenchReport) -> str:
    """The targets of issue 10 as ratios, and the check that the floor computes what the library computes."""
    body = []
    for t in report.target_summary:
        mark = "—" if t["met"] is None or not np.isfinite(t["value"]) else ("✓" if t["met"] else "✗")
        goal = f"~{t['goal']:g}" if t["target"] == "d" else f"≤ {t['goal']:g}"
        body.append([t["target"], t["what"], fmt(t["value"], ".3g"), goal, mark, t["detail"]])
    checks = [r for r in report.targets if "agreement" in r]
    lines = [f"- n = {r['n']}" + (f", batch of {r['batch']}" if "batch" in r else "")
             + f": max |floor − library| = {r['agreement']:.1e} over the state and g "
             + ("(✓ ≤ 1e-12)" if r["agrees"] else "(✗ above 1e-12: the ratio compares different computations)")
             for r in checks]
    return ("## Targets\n\nThe targets of the compiled time loop (issue 10), as ratios: to the *floor* — a plain "
            "compiled loop of the same method (`liesuslov/bench/floor.py`: RKMK4, exponential chart, Rodrigues, "
            "the library's dexp⁻¹ — closed form on so(3), the series to ad² on each so(3) factor of so(4) —, "
            "h = 0.005, no allocation per step) — or to the same run without output. "
            "✓ met, ✗ not met.\n\n"
            + md_table(["target", "what", "measured", "goal", "", "detail"], body)
            + ("\n\nThe floor computes what the library computes (same field, same method, same initial data):\n\n"
               + "\n".join(lines) if lines else ""))


DOCS_INTRO = """# Performance

!!! note "Regenerate this page"
    Every number below is produced by one command, run from the repository root:

        python -m liesuslov.bench --docs docs/performance.md

    (`liesuslov bench --docs docs/performance.md` is the same; add `--out DIR` for the CSV files,
    `--quick` for a one-minute subset.) Everything after the section *How it is measured* is generated.

Speed only matters at a given accuracy, so liesuslov is measured the way integrators are compared:
**work-precision sweeps** — wall time against the error actually reached — on scenes whose
motion is known exactly, against scipy's `solve_ivp` integrating the same motion.

## How it is measured

**Scenes.** Five motions with independent references: the Klebsh–Tisserand body in SO(4) with its
attitude (closed form on the invariant torus for Ω and Γ); the Kharlamova body in SO(5) over one
period (the state returns to itself); the Lagrange body in SO(3) mapped to the spherical pendulum
(`q = g e_n`, `v = g Ω e_n` against the Jacobi elliptic solution); the free rigid body (Euler top) with
its attitude; and Suslov's problem in SO(3) with V = 0 (the explicit tanh law). Where the closed form
does not give a quantity (the attitude g), the reference is the mean of a liesuslov rkmk853 run and a
scipy DOP853 run at rtol 1e-13 (ten times tighter than any swept run), written independently; their
disagreement (and that with the closed form) is the reference's *uncertainty*, listed with the scenes.

**Routes.** Every liesuslov method (fixed step: lie-euler, rkmk2, rkmk-heun, rkmk3, rkmk4, rkmk5,
rkmk8 over a sweep of step sizes; adaptive: rkmk23, rkmk45, rkmk853 over a sweep of tolerances) in both
charts (exponential and Cayley), and scipy's `solve_ivp` with RK45, DOP853 and Radau over tolerance
sweeps (atol = 10⁻² rtol for both libraries). scipy integrates the *embedded* ODE — the state
(ξ, vec g) with Γ = gᵀγ when the attitude is reconstructed, (ξ, Γ) otherwise — with a numpy right-hand
side written by hand for each scene, as a user would.

**Timing.** Wall time of the whole call (`ls.integrate` or `solve_ivp`), the minimum over repeats
after one warm-up run (repeats stop once they add up to 0.6 s, at least one); as in `timeit`, one
garbage collection before the repeats and none during them. BLAS threads as the environment sets them
(the machine table says what `OPENBLAS_NUM_THREADS` was: 1 is advised, since on a loaded 2-core machine a
threaded BLAS makes small products erratic for both libraries).

**Errors.** At the final time t1, where both libraries land exactly: the largest absolute component
error of Ω (so(n) coordinates), of Γ, of g, and of the pendulum's (q, v); a run's *error* is the largest
of those its scene has. Structure: max|gᵀg − I|, max||Γ| − 1| and the constraint components max|⟨aⁱ, Ω⟩|,
and the drift max|F(t) − F(0)| of every first integral, all over every step of the run.

**Throughput, cost against n, long run.** RKMK4 with reconstruction, h = 0.01, output at the final time
only: a batch of random initial data in D advanced in one vectorised run (n = 3: Lagrange, n = 4:
Klebsh–Tisserand); one trajectory of the Klebsh–Tisserand body in SO(n), n = 3 … 256, with the growth
exponent fitted over the three largest sizes (sizes above 64 run in a child process with memory and
time limits: a failure there is recorded, not fatal); one trajectory of 10⁶ steps. The n-sweep is
measured with `backend="numpy"` and with `backend="numba"` (asked for by name: where the compiled path
stops, the row says why); every table names the backend that ran. `--quick` runs the numpy path (no
one-off kernel compilation).

**Targets and the floor.** The targets of the compiled time loop are reported as ratios, which drift
less than times on a shared machine. The *floor* is a plain compiled loop (numba) of the method the
library runs — RKMK4 in the exponential chart with Rodrigues' formula and the library's dexp⁻¹ (the
closed form on so(3); on so(4) the series to ad² on each so(3) factor, as the library's so(4) kind), the
free rigid body in SO(3) and the Klebsh–Tisserand body in SO(4) (so(4) = so(3) ⊕ so(3) by quaternions),
h = 0.005, one scalar loop without allocation — checked against the library's result (to 1e-12) in
every run. Library and floor are timed in alternating rounds (up to 15, the fastest of each), so that a
slow spell of the shared machine hits both sides of the ratio. (a) one trajectory: library / floor time
per step; (b) 10⁴ trajectories: library / floor (single thread) per trajectory-step; (c) the default
scene of `liesuslov run` with 500 output times: field evaluations / those of the end point only (and
for comparison, the same ratio for scipy's DOP853 on the embedded ODE); (d)
the exponent of the n-sweep on numba; (e) the fastest liesuslov route / scipy DOP853 at equal error;
(f) `import liesuslov` and the first compiled call after installation (an empty numba cache: it loads the
kernel that the build compiled, `build_backend/`), each in a fresh process; beside it, the same call
compiling the kernel itself (`LIESUSLOV_PRECOMPILED=off`), the next process loading numba's cache, and the
build's precompile step (every family, in parallel processes, on a copy of the package).

**The ratio table and the goal.** For each scene and error level 10⁻⁵ … 10⁻¹⁰, the time of the fastest
route of each library to reach it (log time interpolated linearly in log error between consecutive points
of a route's sweep), and their ratio. The goal is liesuslov ≤ 0.1 × scipy at every level (compiled), with the
structure exact — reported here, never asserted in the tests.
"""
