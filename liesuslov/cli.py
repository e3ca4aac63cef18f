"""Command line: ``liesuslov run [SCENE.toml]`` (the main job), ``cases``, ``check`` and ``bench``.

``liesuslov run`` with no file integrates the built-in scene (:data:`liesuslov.scene.DEFAULT_SCENE`,
the n = 4 Klebsh–Tisserand body reconstructed on SO(4)); ``python -m liesuslov`` is the same program.

Exit status: 0 on success; 1 when the integration fails or ``check`` finds a drift or defect above
its tolerance; 2 for a user error (a bad scene file, a missing file, a bad option), reported as one
line on stderr without a traceback (``liesuslov --debug ...`` shows the traceback).
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import shutil
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ._io import publish

__all__ = ["main", "build_parser", "OUTPUT_FILES"]

#: Every file ``liesuslov run`` may write into its output folder (stale ones from earlier runs are removed).
OUTPUT_FILES = ("trajectory.npz", "scene.toml", "report.txt", "omega.png", "gamma.png", "path.png", "energy.png")


class _UserError(Exception):
    """A mistake of the user's (exit status 2, one line on stderr)."""


# ====================================================================== entry point
def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``liesuslov`` command line; returns the exit status.

    Parameters
    ----------
    argv : sequence of str, optional
        The arguments (default ``sys.argv[1:]``), e.g. ``["run", "scene.toml", "--out", "out"]``.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(argv)
    try:
        args, extra = parser.parse_known_args(argv)
        if extra and not getattr(args, "accept_extra", False):
            parser.error(f"unrecognized arguments: {' '.join(extra)}")
    except SystemExit as exc:  # --help, or a usage error already printed by argparse
        return int(exc.code or 0) if not isinstance(exc.code, str) else 2
    try:
        return int(args.func(args))
    except BrokenPipeError:  # `liesuslov run | head`: the reader left; stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except (_UserError, ValueError, TypeError, OSError) as exc:
        if getattr(args, "debug", False):
            raise
        print(f"liesuslov: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("liesuslov: interrupted (nothing written)", file=sys.stderr)
        return 130


def build_parser(argv: Sequence[str] = ()) -> argparse.ArgumentParser:
    """The argument parser; ``liesuslov.bench`` is imported only when ``argv`` asks for ``bench``."""
    from . import __version__

    parser = argparse.ArgumentParser(
        prog="liesuslov",
        description="Nonholonomic rigid-body dynamics on Lie groups: integrate scenes, list the integrable "
                    "cases, check integrals and structure, benchmark.",
        epilog="Run `liesuslov run` for the built-in scene; `liesuslov COMMAND --help` for a command.")
    parser.add_argument("--version", action="version", version=f"liesuslov {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = sub.add_parser("run", help="integrate a scene (default: the built-in n = 4 Klebsh–Tisserand body)",
                         description="Integrate a scene file (or the built-in scene), print what was modelled, "
                                     "the drift of the integrals and the structure defects, and write the "
                                     "trajectory (.npz), the scene, a report and figures to the output folder.")
    run.add_argument("scene", nargs="?", default=None, help="a scene TOML file (default: the built-in scene)")
    run.add_argument("--out", metavar="DIR", default=None,
                     help="output folder (default: the scene's [output].dir, else liesuslov-out)")
    run.add_argument("--no-figures", action="store_true", help="do not draw figures")
    _add_integrate_options(run)
    run.add_argument("--print-default", action="store_true",
                     help="print the built-in scene as TOML (a template for your own) and exit")
    run.set_defaults(func=_cmd_run)

    cases = sub.add_parser("cases", help="list the named integrable cases (parameters, first integrals)",
                           description="The named cases of ls.CASES with their example parameters and first "
                                       "integrals; with NAME, one case and a scene template for it.")
    cases.add_argument("name", nargs="?", default=None, help="one case: details and a scene template")
    cases.set_defaults(func=_cmd_cases)

    check = sub.add_parser("check", help="integrate a scene and check integrals, structure, reduction",
                           description="Integrate a scene and check the drift of its first integrals, the "
                                       "structure defects and, for the Lagrange case, the reduction to the "
                                       "spherical pendulum. Exit status 0 when all are within the tolerance, "
                                       "1 otherwise. Writes nothing.")
    check.add_argument("scene", nargs="?", default=None, help="a scene TOML file (default: the built-in scene)")
    check.add_argument("--tol", type=float, default=None,
                       help="tolerance (default: the scene's [check].tol, else 1e-8); drifts of integrals are "
                            "compared with tol * max(1, |F(0)|)")
    _add_integrate_options(check)
    check.set_defaults(func=_cmd_check)

    ens = sub.add_parser("ensemble", help="integrate N perturbed copies of a scene's initial state (ls.ensemble)",
                         description="Integrate N initial states drawn around the scene's (Omega0 + scale * z "
                                     "along the constraint subspace, z standard normal; Gamma0 perturbed by "
                                     "scale * w and renormalised; g0 kept: liesuslov.ensembles.Perturbation), "
                                     "reproducibly from --seed whatever --workers, on W worker processes, "
                                     "streaming the two ends of t_span (or only the final state) to a store "
                                     "folder read back by ls.open_ensemble(DIR). Exit status 1 if a trajectory "
                                     "failed.")
    ens.add_argument("scene", nargs="?", default=None, help="a scene TOML file (default: the built-in scene)")
    ens.add_argument("--n", type=int, default=1000, metavar="N", help="number of trajectories (default 1000)")
    ens.add_argument("--workers", type=int, default=0, metavar="W",
                     help="0: in this process (default); W >= 1: a local Dask cluster of W processes "
                          "(liesuslov[distributed]), else a process pool")
    ens.add_argument("--out", metavar="DIR", default="liesuslov-out/ensemble",
                     help="the store folder (replaced if it holds an ensemble; default liesuslov-out/ensemble)")
    ens.add_argument("--scale", type=float, default=1e-2, help="standard deviation of the perturbation (0.01)")
    ens.add_argument("--seed", type=int, default=0, help="root seed of the draws (default 0)")
    ens.add_argument("--chunk-size", type=int, default=None, metavar="C", help="trajectories per task")
    ens.add_argument("--final", action="store_true", help="keep only the final state (reduce='final')")
    ens.add_argument("--executor", choices=("auto", "dask", "process"), default="auto",
                     help="with W >= 1: dask (LocalCluster), process (ProcessPoolExecutor) or auto (dask if "
                          "installed)")
    _add_integrate_options(ens)
    ens.set_defaults(func=_cmd_ensemble)

    section = sub.add_parser("section", help="Poincaré section of a scene (crossings, integrals, figure)",
                             description="Integrate the scene's initial state and others on its energy level "
                                         "and write the crossings of a section (default Gamma_n = 0), the drift "
                                         "of the first integrals there and the figure (ls.poincare_section).")
    _research_commands().add_section_arguments(section)
    section.set_defaults(func=_cmd_section)

    phase = sub.add_parser("phase", help="period and monodromy of a scene's periodic reduced motion",
                           description="The first return of the reduced state (Omega, Gamma), the monodromy "
                                       "R = g(0)^-1 g(T), its rotation angles and, for the free body, "
                                       "Montgomery's dynamic and geometric phases (ls.reconstruction_phase). "
                                       "Exit status 1 when no return is found.")
    _research_commands().add_phase_arguments(phase)
    phase.set_defaults(func=_cmd_phase)

    bench = sub.add_parser("bench", help="work-precision benchmarks (liesuslov.bench)",
                           description="Work-precision benchmarks against scipy (see liesuslov.bench).")
    if _wants_bench(argv):
        try:
            bench_module = importlib.import_module(".bench", __package__)
        except Exception as exc:  # noqa: BLE001 - any failure to import is reported on use only
            bench.set_defaults(func=_bench_unavailable(exc), accept_extra=True)  # its options are unknown
        else:
            bench_module.add_arguments(bench)
            bench.set_defaults(func=bench_module.run_from_args)
    return parser


def _research_commands():
    from .research import commands

    return commands


def _cmd_section(args) -> int:
    return _research_commands().run_section(args, _load, _UserError)


def _cmd_phase(args) -> int:
    return _research_commands().run_phase(args, _load, _UserError)


def _wants_bench(argv: Sequence[str]) -> bool:
    """True iff the command (the first argument that is not an option) is ``bench``."""
    for a in argv:
        if not a.startswith("-"):
            return a == "bench"
    return False


def _bench_unavailable(exc: BaseException):
    def report(args) -> int:
        raise _UserError(f"the bench command is unavailable: liesuslov.bench could not be imported "
                         f"({type(exc).__name__}: {exc})")
    return report


# ====================================================================== run
def _cmd_run(args) -> int:
    from .scene import DEFAULT_SCENE

    if args.print_default:
        if args.scene is not None:
            raise _UserError("--print-default prints the built-in scene; it takes no scene file")
        sys.stdout.write(DEFAULT_SCENE)
        return 0
    scene = _load(args.scene, progress=args.progress or None, out_dir=args.out,
                  figures=False if args.no_figures else None, **_integrate_overrides(args))
    out = Path(scene.out_dir)
    _probe_out_dir(out)
    result = _integrate_and_report(scene, tol=None, failed_note=" (nothing written)")
    if result is None:
        return 1
    sol, lines, _ = result
    written = _write_outputs(scene, sol, lines, out)
    print(f"wrote {out}{os.sep}: {', '.join(written)}")
    return 0


def _probe_out_dir(out: Path) -> None:
    """Refuse, before integrating, an output folder that cannot be made (a file on its path, /proc, no
    permission): the run's minutes would otherwise end in an OSError. Made and removed again if it is new."""
    if out.exists():
        if not out.is_dir():
            raise _UserError(f"the output folder {out} exists and is not a folder; pass --out DIR")
        return
    try:
        out.mkdir(parents=True)
    except OSError as exc:
        raise _UserError(f"the output folder {out} cannot be created ({exc.strerror or exc}); pass --out DIR "
                         "(or [output].dir) with a folder you can write") from exc
    # only the folder itself: parents it made stay (harmless, and removing them could race with another run)
    out.rmdir()


def _add_integrate_options(parser) -> None:
    """The options of run, check and ensemble that override the scene's ``[integrate]`` table."""
    parser.add_argument("--t-end", type=float, metavar="T", default=None, help="integrate up to t = T instead")
    parser.add_argument("--progress", action="store_true", help="show a progress bar (needs tqdm)")
    parser.add_argument("--backend", default=None, metavar="NAME",
                        help="integrate(backend=...): auto, numpy or numba (default: the scene's, else auto)")
    parser.add_argument("--max-steps", type=int, default=None, metavar="N",
                        help="integrate(max_steps=N): a trajectory that needs more steps fails there (default: the "
                             "scene's, else 10^7 — minutes on the numpy backend)")


def _integrate_overrides(args) -> dict[str, Any]:
    """The scene overrides of :func:`_add_integrate_options` (``--progress`` is passed where it is used)."""
    return {"t_end": args.t_end, "backend": args.backend, "max_steps": args.max_steps}


def _load(path: str | None, **overrides: Any):
    from .scene import default_scene, load_scene

    scene = default_scene() if path is None else load_scene(path)
    opts = {k: v for k, v in overrides.items() if v is not None}
    return scene.with_options(**opts) if opts else scene


def _print_header(scene) -> None:
    origin = "built-in default; `liesuslov run --print-default` shows it" if scene.source == "<default scene>" \
        else scene.source
    print(f"scene: {scene.name}  ({origin})")
    if scene.description:
        print(f"  {scene.description}")
    if scene.case is not None:
        print(f"case: {scene.case.name}: {scene.case.description}")
    system = scene.system
    print(f"system: {system!r}")
    model = scene.model()
    print(f"model: {model.description()}")
    if scene.reconstruct:
        m = system.n
        print(f"state: {model.state_dim} + g ({m}x{m}) = {model.state_dim + m * m} numbers per trajectory")
    else:
        print(f"state: {model.state_dim} numbers per trajectory")
    if scene.backend != "numpy" and importlib.util.find_spec("numba") is not None:
        print("(backend: the compiled kernel if the model qualifies; the first compiled run on a machine "
              "compiles it, 20-90 s, once)")


def _integrate_and_report(scene, tol: float | None, failed_note: str = ""):
    """The sequence shared by ``run`` and ``check``: header, integration, report.

    Returns ``(sol, lines, failures)``, or None when the integration failed (the error is printed).
    """
    _print_header(scene)
    sol, wall = _integrate(scene)
    if not sol.success:
        print(f"liesuslov: error: the integration failed: {sol.message}{failed_note}", file=sys.stderr)
        return None
    lines, failures = _report(scene, sol, wall, tol=tol)
    for line in lines:
        print(line)
    return sol, lines, failures


def _integrate(scene):
    start = time.perf_counter()
    with np.errstate(over="ignore", invalid="ignore"):  # a blow-up ends the run with a failed status instead
        sol = scene.run()
    return sol, time.perf_counter() - start


# ====================================================================== diagnostics
def _diagnostics(scene, sol) -> tuple[list[tuple[str, float, float]], list[tuple[str, float]]]:
    """``([(integral name, F(0), max |F - F(0)|)], [(defect label, value)])`` along the solution."""
    x, G = sol.omega, sol.Gamma
    integrals = []
    for name, F in scene.integrals.items():
        vals = np.asarray(F(x, G), dtype=float)
        integrals.append((name, float(vals[0]), float(np.max(np.abs(vals - vals[0])))))
    defects = []
    D = scene.system.constraints
    if D.dim < scene.system.algebra.dim:
        defects.append(("constraints  max |<a^i, Omega>|", float(np.max(np.abs(x @ D.covectors.T)))))
    if G is not None:
        defects.append(("sphere       max ||Gamma| - 1|", float(np.max(np.abs(np.linalg.norm(G, axis=-1) - 1)))))
    if sol.g is not None:
        name = scene.system.algebra.name
        g = sol.g
        if name.startswith("so("):
            m = g.shape[-1]
            err = np.max(np.abs(np.swapaxes(g, -1, -2) @ g - np.eye(m)))
            defects.append(("group        max |g^T g - I|", float(err)))
        elif name in ("se(2)", "se(3)"):
            R = g[..., :-1, :-1]
            k = R.shape[-1]
            err = np.max(np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(k)))
            last = np.zeros(k + 1)
            last[-1] = 1.0
            err = max(float(err), float(np.max(np.abs(g[..., -1, :] - last))))
            defects.append(("group        max |R^T R - I|, last row", err))
    return integrals, defects


def _report(scene, sol, wall: float, tol: float | None) -> tuple[list[str], list[str]]:
    """The report lines and, when ``tol`` is given, the failures (one sentence each)."""
    st = sol.stats
    chart = f", {st['chart']} chart" if st.get("chart") else ""
    t0, t1 = scene.t_span
    backend = f", {st['backend']} backend" if st.get("backend") else ""
    lines = [f"integration: {st['method']}{chart}, {st['form']} form{backend}, t from {t0:g} to {t1:g}: "
             f"{st['steps']} steps, {st['rejected']} rejected, {st['nfev']} field evaluations, "
             f"{len(sol.t)} output times, {wall:.3f} s"]
    integrals, defects = _diagnostics(scene, sol)
    failures: list[str] = []
    width = max(len(n) for n, _, _ in integrals)
    lines.append("first integrals, max |F(t) - F(0)|:")
    for name, F0, drift in integrals:
        verdict = ""
        if tol is not None:
            bound = tol * max(1.0, abs(F0))
            ok = np.isfinite(drift) and drift <= bound
            verdict = "  ok" if ok else f"  FAIL (> {bound:.1e})"
            if not ok:
                failures.append(f"the drift of {name} is {drift:.3e} > {bound:.1e}")
        lines.append(f"  {name:<{width}}  F(0) = {F0: .10e}   drift {drift:.3e}{verdict}")
    if defects:
        lines.append("structure defects:")
        for label, val in defects:
            verdict = ""
            if tol is not None:
                ok = np.isfinite(val) and val <= tol
                verdict = "  ok" if ok else f"  FAIL (> {tol:.1e})"
                if not ok:
                    failures.append(f"{' '.join(label.split()[:1])} defect {val:.3e} > {tol:.1e}")
            lines.append(f"  {label:<38} {val:.3e}{verdict}")
    return lines, failures


# ====================================================================== output
def _write_outputs(scene, sol, lines: list[str], out: Path) -> list[str]:
    """Write everything into a temporary folder inside ``out``, then move the files in place.

    Nothing is half-written: a failure before the final renames leaves ``out`` as it was (and removes
    it if this call created it).
    """
    created = not out.exists()
    if out.exists() and not out.is_dir():
        raise _UserError(f"the output folder {out} exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".liesuslov-", dir=out))
    try:
        sol.save(tmp / "trajectory.npz")
        (tmp / "scene.toml").write_text(scene.to_toml(), encoding="utf-8")
        names = ["trajectory.npz", "scene.toml"]
        if scene.figures:
            figs = _figures(scene, sol, tmp)
            if figs is None:
                lines.append("(no figures: matplotlib is not installed; pip install 'liesuslov[plot]')")
                print(lines[-1])
            else:
                names += figs
        (tmp / "report.txt").write_text("\n".join(lines) + "\n", encoding="utf-8")
        names.insert(2, "report.txt")
        for stale in OUTPUT_FILES:
            if stale not in names and (out / stale).is_file():
                (out / stale).unlink()
        publish(tmp, out, names)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        if created:
            shutil.rmtree(out, ignore_errors=True)
        raise
    shutil.rmtree(tmp, ignore_errors=True)
    return names


def _labels(system) -> list[str]:
    alg = system.algebra
    if alg.name.startswith("so("):
        n = alg.n
        return [f"$\\Omega_{{{i + 1}{j + 1}}}$" for i in range(n) for j in range(i + 1, n)]
    if alg.name == "se(2)":
        return [r"$\omega$", "$v_x$", "$v_y$"]
    if alg.name == "se(3)":
        return [r"$\omega_1$", r"$\omega_2$", r"$\omega_3$", "$v_1$", "$v_2$", "$v_3$"]
    return [f"$x_{{{k + 1}}}$" for k in range(alg.dim)]


def _figures(scene, sol, folder: Path) -> list[str] | None:
    """Draw omega(t), Gamma (or the path on se(n)) and the drift of the integrals; None without matplotlib."""
    try:
        from matplotlib.figure import Figure
    except ImportError:
        return None
    names = []
    t, x = sol.t, sol.omega
    title = scene.name

    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.add_subplot()
    labels = _labels(scene.system)
    for k in range(x.shape[-1]):
        if np.any(x[:, k] != 0):
            ax.plot(t, x[:, k], label=labels[k], lw=1.2)
    ax.set_xlabel("t")
    ax.set_ylabel(r"components of $\Omega$")
    ax.set_title(f"{title}: angular velocity")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    fig.savefig(folder / "omega.png", dpi=110)
    names.append("omega.png")

    if sol.Gamma is not None:
        G = sol.Gamma
        n = G.shape[-1]
        pairs = [(0, 1), (n - 2, n - 1)] if n > 2 else [(0, 1)]
        fig = Figure(figsize=(4.2 * len(pairs), 4.4), layout="constrained")
        s = np.linspace(0, 2 * np.pi, 200)
        for k, (i, j) in enumerate(pairs):
            ax = fig.add_subplot(1, len(pairs), k + 1)
            ax.plot(np.cos(s), np.sin(s), color="0.8", lw=0.8)
            ax.plot(G[:, i], G[:, j], lw=0.9)
            ax.plot(G[0, i], G[0, j], "o", color="C3", ms=4, label="t = t0")
            ax.set_xlabel(f"$\\Gamma_{i + 1}$")
            ax.set_ylabel(f"$\\Gamma_{j + 1}$")
            ax.set_aspect("equal")
            ax.legend(loc="upper right", fontsize="small")
        fig.suptitle(f"{title}: $\\Gamma$ on $S^{{{n - 1}}}$, projections")
        fig.savefig(folder / "gamma.png", dpi=110)
        names.append("gamma.png")
    elif sol.g is not None and scene.system.algebra.name in ("se(2)", "se(3)"):
        p = sol.g[:, :-1, -1]
        fig = Figure(figsize=(5, 5), layout="constrained")
        ax = fig.add_subplot()
        ax.plot(p[:, 0], p[:, 1], lw=1.2)
        ax.plot(p[0, 0], p[0, 1], "o", color="C3", ms=4, label="t = t0")
        ax.set_xlabel("x")
        ax.set_ylabel("y")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(loc="best", fontsize="small")
        ax.set_title(f"{title}: path of the body's origin")
        fig.savefig(folder / "path.png", dpi=110)
        names.append("path.png")

    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.add_subplot()
    floor = 1e-18  # log scale: exact zeros are drawn at the floor
    for name, F in scene.integrals.items():
        vals = np.asarray(F(x, sol.Gamma), dtype=float)
        ax.semilogy(t, np.maximum(np.abs(vals - vals[0]), floor), label=name, lw=1.0)
    ax.set_xlabel("t")
    ax.set_ylabel(r"$|F(t) - F(0)|$")
    ax.set_title(f"{title}: energy error and drift of the first integrals")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    fig.savefig(folder / "energy.png", dpi=110)
    names.append("energy.png")
    return names


# ====================================================================== check
def _cmd_check(args) -> int:
    scene = _load(args.scene, progress=args.progress or None, **_integrate_overrides(args))
    tol = scene.tol if args.tol is None else args.tol
    if not (np.isfinite(tol) and tol > 0):
        raise _UserError(f"--tol must be a positive number, got {args.tol!r}")
    result = _integrate_and_report(scene, tol=tol)
    if result is None:
        return 1
    _, _, failures = result
    failures += _check_reduction(scene, tol)
    if failures:
        print(f"check FAILED (tol = {tol:g}): " + "; ".join(failures))
        return 1
    print(f"check passed: every drift and defect is within tol = {tol:g}")
    return 0


def _check_reduction(scene, tol: float) -> list[str]:
    """The Lagrange reduction report when the scene is the Lagrange case; the failures."""
    from .reduction import check_lagrange_reduction, lagrange_parameters

    try:
        lagrange_parameters(scene.system)
    except (ValueError, TypeError):
        return []

    extra = {"backend": scene.backend} if scene.backend is not None else {}
    try:
        r = check_lagrange_reduction(scene.system, scene.omega0, scene.Gamma0, scene.t_span, g0=scene.g0,
                                     method=scene.method, rtol=scene.rtol, atol=scene.atol,
                                     t_eval=scene.output_times(), h=scene.h, chart=scene.chart, **extra)
    except RuntimeError as exc:
        print(f"Lagrange reduction check: {exc}")
        return [f"the Lagrange reduction check could not run: {exc}"]
    print(r)
    if r.ok(tol):
        print(f"  reduction consistent within tol = {tol:g}")
        return []
    return [f"the Lagrange reduction differs from the spherical pendulum by more than {tol:g}"]


# ====================================================================== cases
def _fmt(v: Any) -> str:
    from .mechanics.potentials import Potential

    if isinstance(v, Potential):
        return repr(v)
    if callable(v):
        return f"<function {getattr(v, '__name__', '?')}>"
    if isinstance(v, (list, tuple, np.ndarray)):
        from .scene import _fmt_list

        return _fmt_list(v)
    if isinstance(v, float):
        return f"{v:g}"
    return repr(v)


def _cmd_cases(args) -> int:
    from .mechanics import CASES

    if args.name is not None:
        if args.name not in CASES:
            raise _UserError(f"unknown case {args.name!r}; the named cases are: {', '.join(CASES)}")
        _print_case(CASES[args.name])
        return 0
    print("Named cases (ls.CASES). In a scene file: [case] name = \"...\" and [case.parameters]; "
          "`liesuslov cases NAME` prints a template.\n")
    for name, entry in CASES.items():
        case = entry.build()
        print(f"{name}: {entry.description}")
        params = ", ".join(f"{k} = {_fmt(v)}" for k, v in entry.example.items())
        print(f"    parameters  {params}")
        print(f"    integrals   {', '.join(case.integrals)}")
        sysm = case.system
        print(f"    body        {sysm.algebra.name}, dim D = {sysm.constraints.dim}, "
              f"Gamma {'in the state' if sysm.needs_gamma else 'not needed (V = 0)'}")
        print()
    return 0


def _print_case(entry) -> None:
    import inspect

    from .scene import to_toml

    case = entry.build()
    doc = inspect.getdoc(entry.constructor) or ""
    # Everything but the scene itself is a TOML comment, so `liesuslov cases NAME > scene.toml` runs as is.
    prose = [f"{entry.name}: {entry.description}", "", *doc.splitlines(), "",
             f"first integrals: {', '.join(case.integrals)}", f"model: {case.system.model().description()}", ""]
    print("\n".join(f"# {line}".rstrip() for line in prose))
    params: dict[str, Any] = {}
    skipped = []
    for k, v in entry.example.items():
        if k in ("v1", "dv1", "v2", "dv2"):
            skipped.append(k)
        elif k == "potential":
            params[k] = _potential_table(v)
        else:
            params[k] = np.asarray(v).tolist() if isinstance(v, (list, tuple, np.ndarray)) else v
    omega, Gamma = case.random_state(rng=0, scale=1.0)
    D = case.system.constraints
    initial: dict[str, Any] = {"xi": [round(float(v), 3) for v in D.coordinates(omega)]}
    if Gamma is not None:
        G = np.round(Gamma, 3)
        initial["Gamma"] = (G / np.linalg.norm(G)).tolist()
    doc_toml = {"case": {"name": entry.name, "parameters": params}, "initial": initial,
                "integrate": {"t_span": [0.0, 10.0], "method": "rkmk45", "rtol": 1e-10, "atol": 1e-12,
                              "n_out": 501, "backend": "numpy"},
                "output": {"name": entry.name, "dir": f"liesuslov-out/{entry.name}", "figures": True}}
    print("# a scene for this case (save as scene.toml, then `liesuslov run scene.toml`)")
    if skipped:
        print(f"# {', '.join(skipped)} are Python functions: the example ones are used (set them in Python)")
    sys.stdout.write(to_toml(doc_toml))


def _potential_table(p) -> Any:
    if p is None or getattr(p, "is_zero", False):
        return "none"
    if p.kind == "linear":
        return {"kind": "linear", "B": np.asarray(p.B).tolist()}
    if p.kind == "quadratic":
        B = p.diagonal if p.diagonal is not None else p.matrix
        return {"kind": "quadratic", "B": np.asarray(B).tolist()}
    return "none"


# ====================================================================== ensemble
def _cmd_ensemble(args) -> int:
    from .ensembles import Perturbation, ensemble

    for name, value, low in (("--n", args.n, 1), ("--workers", args.workers, 0), ("--seed", args.seed, 0)):
        if value < low:
            raise _UserError(f"{name} must be >= {low}, got {value}")
    scene = _load(args.scene, **_integrate_overrides(args))
    system, kw = scene.build()
    sampler = Perturbation.around(system, kw.pop("Omega0"), Gamma0=kw.pop("Gamma0", None), g0=kw.pop("g0", None),
                                  scale=args.scale)
    t_span = kw.pop("t_span")
    for key in ("t_eval", "progress"):  # the ensemble records the ends of t_span; its own bar replaces integrate's
        kw.pop(key, None)
    executor, where, close = _ensemble_executor(args.workers, args.executor)
    start = time.perf_counter()
    try:
        ens = ensemble(system, None, t_span, sampler=sampler, n=args.n, seed=args.seed, chunk_size=args.chunk_size,
                       executor=executor, store=args.out, overwrite=True, reduce="final" if args.final else None,
                       progress=args.progress, **kw)
    finally:
        close()
    wall = time.perf_counter() - start
    ok = int(np.count_nonzero(ens.status >= 0))
    print(f"{scene.name}: {ok}/{args.n} trajectories reached t = {t_span[1]:g} in {wall:.1f} s "
          f"({args.n / wall:,.0f}/s, {where}); seed {args.seed}, scale {args.scale:g}")
    if not ens.success:
        print(f"liesuslov: error: {ens.message}", file=sys.stderr)  # (it counts the failures)
    print(f"wrote {args.out}{os.sep} (read it with liesuslov.open_ensemble({str(args.out)!r}))")
    return 0 if ens.success else 1


def _ensemble_executor(workers: int, kind: str):
    """(executor, description, close) for ``liesuslov ensemble --workers W --executor KIND``."""
    if workers == 0:
        return None, "in process", lambda: None
    if kind in ("auto", "dask"):
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            if kind == "dask":
                raise _UserError("--executor dask needs dask.distributed: "
                                 "pip install 'liesuslov[distributed]'") from None
        else:
            cluster = LocalCluster(n_workers=workers, processes=True, threads_per_worker=1, dashboard_address=None,
                                   host="127.0.0.1")
            client = Client(cluster)

            def close() -> None:
                client.close()
                cluster.close()
            return client, f"a local Dask cluster of {workers} processes", close
    from concurrent.futures import ProcessPoolExecutor

    pool = ProcessPoolExecutor(workers)
    return pool, f"a pool of {workers} processes", pool.shutdown
