"""Work-precision diagram: RKMK (exp and Cayley charts) against scipy's solve_ivp, Klebsh–Tisserand n = 4.

The scene is the Klebsh–Tisserand body in SO(4) with reconstruction of the attitude g over ``[0, 20]``
(``liesuslov.bench``'s "klebsh-tisserand" scene). liesuslov integrates ``(xi, g)`` by RKMK — rkmk4
over a sweep of step sizes, rkmk45 and rkmk853 over a sweep of tolerances, each with the exponential
and the Cayley chart; scipy's ``solve_ivp`` (RK45, DOP853) integrates the same motion written as an
ordinary ODE on ``R^3 x R^16``, state ``(xi, vec g)`` with ``Gamma = g^T gamma``, with a hand-written
numpy right-hand side. The error is taken at the final time against the closed form (Omega, Gamma) and
two independent tight runs (g); the wall time is the minimum of 3 repeats after a warm-up.

The measuring is :func:`liesuslov.bench.run_bench` restricted to this scene (no duplicated logic:
``python -m liesuslov.bench`` runs the full benchmark); this script draws the diagram and prints the
fastest route of each library per error level. The right panel is the point of the Lie-group
methods: the RKMK attitude stays orthogonal to rounding at every tolerance, the ODE solution's
``|g^T g - I|`` follows its error.

Run: ``python examples/work_precision.py [--out DIR] [--quick]``.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from _common import command_line, save_figure  # examples/_common.py
from matplotlib.figure import Figure

from liesuslov import bench

NAME = "work_precision.png"
SCENE = "klebsh-tisserand"


def config(quick: bool) -> bench.BenchConfig:
    """The benchmark restricted to one scene, the three RKMK methods and scipy's RK45 / DOP853."""
    # only the speed-against-error sweeps: no throughput, scaling, long run, nor the benchmark's targets
    # (cold compilation in a fresh process and the floor comparisons take minutes and are not drawn here)
    common = dict(scenes=(SCENE,), charts=("exp", "cayley"), batch_sizes=(), scaling_sizes=(), long_run_steps=0,
                  plots=False, targets=False, cold_compile=False)
    if quick:
        # numpy stepper: a quick run never waits for the one-off compilation of the optional numba kernel
        return bench.BenchConfig(methods=("rkmk4", "rkmk853"), scipy_methods=("DOP853",), repeats=1, backend="numpy",
                                 fixed_factors={"rkmk4": (0.5, 1.0)},
                                 tolerances={"rkmk853": (1e-6, 1e-9), "DOP853": (1e-6, 1e-9)},
                                 levels=(1e-6, 1e-8), **common)
    return bench.BenchConfig(methods=("rkmk4", "rkmk45", "rkmk853"), scipy_methods=("RK45", "DOP853"), repeats=3,
                             levels=(1e-5, 1e-7, 1e-9, 1e-11), **common)


def main(out_dir=None, quick: bool = False) -> Path:
    """Run the sweeps, print the summary, save the figure; return its path."""
    with tempfile.TemporaryDirectory() as tmp:
        report = bench.run_bench(tmp, config=config(quick), progress=False)
    ref = report.references[SCENE]
    rows = [r for r in report.rows if r["status"] == "ok" and np.isfinite(r["error"]) and r["error"] > 0]
    routes: dict[str, list[dict]] = {}
    for r in rows:
        routes.setdefault(r["route"], []).append(r)
    for rs in routes.values():
        rs.sort(key=lambda r: -r["setting"])             # coarse to fine

    backends = ", ".join(sorted({str(r.get("backend", "numpy")) for r in rows if r["library"] == "liesuslov"}))
    print(f"Work-precision, {ref['title']}, t1 = {ref['t1']:g}; reference uncertainty {ref['uncertainty']:.1e}; "
          f"liesuslov backend: {backends}")
    print(f"  {'route':26s} {'setting':>9s} {'error':>9s} {'time (s)':>9s} {'nfev':>6s} {'|g^T g - I|':>11s}")
    for route, rs in routes.items():
        for r in (rs[0], rs[-1]):                        # coarsest and finest setting of each route
            print(f"  {route:26s} {r['setting']:9.1e} {r['error']:9.1e} {r['wall_time']:9.4f} {int(r['nfev']):6d} "
                  f"{r['orth_defect']:11.1e}")
    print("  fastest route to each error level (time interpolated along the sweeps):")
    for q in report.ratios:
        print(f"    {q['level']:7.0e}: {q['liesuslov_route'] or '-':26s} {q['liesuslov_time']:.4f} s | "
              f"{q['scipy_route'] or '-':12s} {q['scipy_time']:.4f} s | time ratio {q['ratio']:.2f}")
    lie_orth = max(r["orth_defect"] for r in rows if r["library"] == "liesuslov")
    sp = [r["orth_defect"] for r in rows if r["library"] == "scipy"]
    print(f"  max |g^T g - I| over all RKMK runs {lie_orth:.1e}; scipy runs {min(sp):.1e} … {max(sp):.1e}")
    print(f"  whole benchmark {report.elapsed:.1f} s")

    fig = Figure(figsize=(14, 5.5), layout="constrained")
    axs = fig.subplots(1, 3)
    methods = sorted({r["method"] for r in rows if r["library"] == "liesuslov"})
    marks = {"RK45": "s", "DOP853": "D"}

    def style(rs):
        r = rs[0]
        if r["library"] == "scipy":
            return dict(color="k", ls="--", marker=marks.get(r["method"], "x"), ms=5, mfc="none")
        return dict(color=f"C{methods.index(r['method'])}", ls="-" if r["chart"] == "exp" else ":", marker="o", ms=3.5)

    for route, rs in sorted(routes.items()):
        e = [r["error"] for r in rs]
        axs[0].loglog([r["wall_time"] for r in rs], e, label=route, **style(rs))
        axs[1].loglog([r["nfev"] for r in rs], e, label=route, **style(rs))
        axs[2].loglog(e, [max(r["orth_defect"], 1e-17) for r in rs], label=route, **style(rs))
    for ax in axs[:2]:
        ax.axhline(ref["uncertainty"], color="0.6", lw=0.8, ls="-.")
        ax.set_ylabel("error at t1 (max abs over Omega, Gamma, g)")
    axs[0].set_xlabel("wall time (s), min of repeats")
    axs[0].set_title("work-precision: time", fontsize=10)
    axs[1].set_xlabel("right-hand-side evaluations")
    axs[1].set_title("work-precision: evaluations", fontsize=10)
    axs[2].set_xlabel("error at t1")
    axs[2].set_ylabel(r"$\max_t |g^Tg - I|$")
    axs[2].set_title("orthogonality defect of the attitude", fontsize=10)
    axs[2].legend(fontsize=7, loc="center right")
    fig.suptitle(f"{ref['title']}, t in [0, {ref['t1']:g}]: liesuslov RKMK ({backends}; solid: exp, dotted: "
                 "Cayley) vs scipy solve_ivp on the embedded ODE (dashed)")
    return save_figure(fig, out_dir, NAME)


if __name__ == "__main__":
    command_line(main, __doc__)
