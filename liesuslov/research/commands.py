"""``liesuslov section SCENE`` and ``liesuslov phase SCENE``: the research tools on a scene file.

``section`` integrates the scene's initial state and ``--n - 1`` others on the same energy level (Gamma
perturbed, the velocity rescaled to the scene's energy) and writes the crossings of a section
(``section.npz``, ``section.txt`` with the drift of the first integrals at the crossings, ``section.png``).
``phase`` computes the period and the monodromy of the scene's initial state (``phase.txt``,
``phase.png``: the reduced state over one period and the returns).
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["add_section_arguments", "add_phase_arguments", "run_section", "run_phase", "same_energy_states"]


def add_section_arguments(p) -> None:
    p.add_argument("scene", nargs="?", default=None, help="a scene TOML file (default: the built-in scene)")
    p.add_argument("--out", metavar="DIR", default=None, help="output folder (default: the scene's, + /section)")
    p.add_argument("--t-end", type=float, metavar="T", default=None, help="integrate up to t = T (default: the "
                   "scene's t_span end)")
    p.add_argument("--n", type=int, default=8, metavar="N", help="trajectories on the scene's energy level (8)")
    p.add_argument("--seed", type=int, default=0, help="seed of the other initial states (0)")
    p.add_argument("--scale", type=float, default=0.3, help="size of the perturbation of Gamma0 and xi0 (0.3)")
    p.add_argument("--variable", choices=("Gamma", "omega"), default=None,
                   help="section on a component of Gamma (default when the scene has Gamma) or of omega")
    p.add_argument("--index", type=int, default=-1, help="its component (default -1: the last)")
    p.add_argument("--value", type=float, default=0.0, help="the section is variable[index] = value (0)")
    p.add_argument("--direction", type=int, choices=(-1, 0, 1), default=1, help="crossing direction (1)")
    _add_max_steps(p)
    p.add_argument("--no-figures", action="store_true", help="do not draw the figure")


def add_phase_arguments(p) -> None:
    p.add_argument("scene", nargs="?", default=None, help="a scene TOML file (default: the built-in scene)")
    p.add_argument("--out", metavar="DIR", default=None, help="output folder (default: the scene's, + /phase)")
    p.add_argument("--t-max", type=float, default=1000.0, metavar="T", help="search the return up to T (1000)")
    p.add_argument("--period", type=float, default=None, help="use this period instead of searching")
    _add_max_steps(p)
    p.add_argument("--no-figures", action="store_true", help="do not draw the figure")


def _add_max_steps(p) -> None:
    p.add_argument("--max-steps", type=int, default=None, metavar="N",
                   help="integrate(max_steps=N) for every integration of the tool (default: the scene's, else 10^7)")


def _options(scene) -> dict[str, Any]:
    """The scene's integrator options — its tolerances at most the research defaults' (1e-10, 1e-12) —, or the
    research defaults for a fixed-step scene without h; the scene's form, backend and max_steps as they are."""
    from ._runner import adaptive

    own = adaptive(scene.method)
    opts: dict[str, Any] = {}
    if own is not False or scene.h is not None:
        opts.update(method=scene.method, chart=scene.chart)
        if own:
            opts.update(rtol=min(scene.rtol, 1e-10), atol=min(scene.atol, 1e-12))
        else:
            opts["h"] = scene.h
    for name in ("backend", "max_steps"):
        if getattr(scene, name) is not None:
            opts[name] = getattr(scene, name)
    if scene.form != "auto":
        opts["form"] = scene.form
    return opts


def _drop_stale(path: Path, written: bool) -> None:
    """A figure a previous run left in the output folder goes when this run draws none (it would not match)."""
    if not written:
        path.unlink(missing_ok=True)


def same_energy_states(system, omega0: np.ndarray, Gamma0: np.ndarray | None, N: int, seed: int, scale: float):
    """``N`` states on the energy level of ``(omega0, Gamma0)`` (the first is the given one).

    Gamma and xi are perturbed by ``scale`` (relative), Gamma renormalised, and xi rescaled so that the
    kinetic energy is ``E0 - V(Gamma)``; draws with ``V(Gamma) >= E0`` are redrawn closer to the given state.
    """
    rng = np.random.default_rng(seed)
    Dbasis = system.constraints.basis
    xi0 = omega0 @ Dbasis.T
    E0 = float(system.energy(omega0, Gamma0))
    out_x, out_G = [omega0], [Gamma0]
    s = scale
    tries = 0
    while len(out_x) < N and tries < 100 * N:
        tries += 1
        G = None
        V = 0.0
        if Gamma0 is not None:
            G = Gamma0 + s * rng.standard_normal(Gamma0.shape)
            G = G / np.linalg.norm(G)
            V = float(system.energy(np.zeros_like(omega0), G))
        xi = xi0 + s * max(1.0, float(np.linalg.norm(xi0))) * rng.standard_normal(xi0.shape)
        x = xi @ Dbasis
        K = float(system.energy(x, G)) - V
        if E0 - V <= 0.0 or K <= 0.0:
            s *= 0.9
            continue
        out_x.append(x * np.sqrt((E0 - V) / K))
        out_G.append(G)
    if len(out_x) < N:
        raise ValueError(f"could not draw {N} states on the energy level E = {E0:.6g}; lower --n or --scale")
    return np.array(out_x), (None if Gamma0 is None else np.array(out_G))


def run_section(args, load, user_error) -> int:
    """The ``section`` command (``load(path, **overrides)`` reads the scene; ``user_error`` its exception)."""
    from ..research import coordinate_plane, poincare_section

    scene = load(args.scene, t_end=args.t_end, max_steps=args.max_steps)
    system = scene.system
    if args.n < 1:
        raise user_error(f"--n must be >= 1, got {args.n}")
    for opt, val in (("--value", args.value), ("--scale", args.scale)):
        if not np.isfinite(val):
            raise user_error(f"{opt} must be a finite number, got {val}")
    if args.scale <= 0.0:
        raise user_error(f"--scale must be positive, got {args.scale}")
    if args.seed < 0:
        raise user_error(f"--seed must be a non-negative integer, got {args.seed}")
    variable = args.variable or ("Gamma" if scene.Gamma0 is not None else "omega")
    if variable == "Gamma" and scene.Gamma0 is None:
        raise user_error("--variable Gamma: this scene has no Gamma (give [initial].Gamma or use --variable omega)")
    dim = system.n if variable == "Gamma" else system.algebra.dim
    try:
        sec = coordinate_plane(variable, args.index, args.value, dim=dim)
    except ValueError as exc:
        raise user_error(f"--index: {exc}") from exc
    omega, Gamma = same_energy_states(system, scene.omega0, scene.Gamma0, args.n, args.seed, args.scale)
    with warnings.catch_warnings():  # (a failure's RuntimeWarning: the report below says it, on one line)
        warnings.simplefilter("ignore", RuntimeWarning)
        rec = poincare_section(system, omega, scene.t_span, sec, Gamma0=Gamma, direction=args.direction,
                               **_options(scene))
    out = Path(args.out) if args.out else Path(scene.out_dir) / "section"
    out.mkdir(parents=True, exist_ok=True)
    arrays = {"t": rec.t, "index": rec.index, "omega": rec.omega}
    if rec.Gamma is not None:
        arrays["Gamma"] = rec.Gamma
    np.savez(out / "section.npz", **arrays)
    lines = [f"scene: {scene.name} ({scene.source})", f"section: {variable}[{args.index}] = {args.value:g}, "
             f"direction {args.direction:+d}, t_span = {scene.t_span}",
             f"trajectories: {args.n} on the energy level E = {float(system.energy(omega[0], _g(Gamma, 0))):.12g}",
             f"crossings: {rec.t.size} (per trajectory: {np.bincount(rec.index, minlength=args.n).tolist()})"]
    if rec.t.size:
        for name, F in scene.integrals.items():
            F0 = np.asarray(F(omega, Gamma))
            Fc = np.asarray(F(rec.omega, rec.Gamma))
            lines.append(f"max |{name} - {name}(0)| at the crossings: {float(np.max(np.abs(Fc - F0[rec.index]))):.3g}")
    elif not np.any(rec.status < 0):
        lines.append(f"(no crossing: {variable}[{args.index}] = {args.value:g} is not crossed in direction "
                     f"{args.direction:+d} within t_span; choose another section with --variable, --index, --value "
                     "or --direction, or a longer --t-end)")
    if np.any(rec.status < 0):
        lines.append(f"failed: {rec.message}")
    text = "\n".join(lines) + "\n"
    (out / "section.txt").write_text(text)
    print(text, end="")
    written = ["section.npz", "section.txt"]
    drawn = bool(not args.no_figures and rec.t.size
                 and _figure_section(system, rec, args.n, scene.name, out / "section.png"))
    _drop_stale(out / "section.png", drawn)
    if drawn:
        written.append("section.png")
    print(f"wrote {out}/: {', '.join(written)}")
    return 1 if np.any(rec.status < 0) else 0


def _g(G, k):
    return None if G is None else G[k]


def section_coordinates(system, omega: np.ndarray, Gamma: np.ndarray | None) -> tuple[np.ndarray, np.ndarray,
                                                                                       str, str]:
    """Two coordinates of a section point for a figure: the azimuth of Gamma and the angle of xi in D."""
    xi = omega @ system.constraints.basis.T
    if Gamma is not None and Gamma.shape[-1] >= 2:
        x = np.arctan2(Gamma[:, 1], Gamma[:, 0])
        xl = "atan2(Γ₂, Γ₁)"
    else:
        x = xi[:, 0]
        xl = "ξ₁"
    if xi.shape[-1] >= 2:
        y = np.arctan2(xi[:, 1], xi[:, 0])
        yl = "atan2(ξ₂, ξ₁)"
    else:
        y = xi[:, 0]
        yl = "ξ₁"
    return x, y, xl, yl


def _figure_section(system, rec, N: int, title: str, path: Path) -> bool:
    try:
        from matplotlib.figure import Figure
    except ImportError:
        print("(no figure: matplotlib is not installed; pip install 'liesuslov[plot]')")
        return False
    x, y, xl, yl = section_coordinates(system, rec.omega, rec.Gamma)
    fig = Figure(figsize=(6, 5), layout="constrained")
    ax = fig.add_subplot()
    ax.scatter(x, y, c=rec.index, s=2, cmap="tab10", vmin=0, vmax=max(N - 1, 1))
    ax.set_xlabel(xl)
    ax.set_ylabel(yl)
    ax.set_title(f"Poincaré section: {title}")
    fig.savefig(path, dpi=110)
    return True


def run_phase(args, load, user_error) -> int:
    """The ``phase`` command."""
    from ..research import reconstruction_phase

    scene = load(args.scene, max_steps=args.max_steps)
    system = scene.system
    if system.n is None:
        raise user_error(f"phase needs a matrix representation of {system.algebra.name}")
    ph = reconstruction_phase(system, scene.omega0, Gamma0=scene.Gamma0, period=args.period, t_max=args.t_max,
                              on_failure="nan", **_options(scene))
    out = Path(args.out) if args.out else Path(scene.out_dir) / "phase"
    out.mkdir(parents=True, exist_ok=True)
    np.set_printoptions(precision=12, suppress=False)
    lines = [f"scene: {scene.name} ({scene.source})"]
    if ph.status != 0:
        lines.append(f"no period: {ph.message}")
        text = "\n".join(lines) + "\n"
        (out / "phase.txt").write_text(text)
        _drop_stale(out / "phase.png", False)
        print(text, end="")
        return 1
    lines += [f"period T = {float(ph.period):.15g}" + ("" if args.period is not None else
              f" (first return, relative distance {float(ph.return_distance):.3g}, {float(ph.closure):.3g} on the "
              f"checking re-integration, {int(ph.crossings)} crossing(s); |T - T'| = {float(ph.period_error):.3g})"),
              "monodromy R = g(0)^-1 g(T):", str(ph.monodromy),
              f"rotation angles of R's invariant planes: {np.array2string(ph.angles, precision=12)}"]
    if system.n == 3:
        lines.append(f"axis ({ph.axis_kind}) = {np.array2string(ph.axis, precision=12)}, "
                     f"angle = {float(ph.angle):.15g}")
    if np.isfinite(ph.dynamic_phase):
        lines.append(f"free body (Montgomery): dynamic 2ET/|m| = {float(ph.dynamic_phase):.15g}, geometric "
                     f"(solid angle) = {float(ph.geometric_phase):.15g}, angle - (dynamic - geometric) mod 2pi = "
                     f"{float(ph.montgomery_defect()):.3g}")
    text = "\n".join(lines) + "\n"
    (out / "phase.txt").write_text(text)
    print(text, end="")
    written = ["phase.txt"]
    drawn = bool(not args.no_figures and _figure_phase(scene, ph, out / "phase.png"))
    _drop_stale(out / "phase.png", drawn)
    if drawn:
        written.append("phase.png")
    print(f"wrote {out}/: {', '.join(written)}")
    return 0


def _figure_phase(scene, ph, path: Path) -> bool:
    try:
        from matplotlib.figure import Figure
    except ImportError:
        print("(no figure: matplotlib is not installed; pip install 'liesuslov[plot]')")
        return False
    from ..integrators import integrate

    T = float(ph.period)
    tt = np.linspace(0.0, 1.5 * T, 600)
    kw: dict[str, Any] = {"method": "rkmk853", "rtol": 1e-10, "atol": 1e-12}
    if scene.Gamma0 is not None:
        kw["Gamma0"] = scene.Gamma0
    sol = integrate(scene.system, scene.omega0, (0.0, tt[-1]), t_eval=tt, **kw)
    xi = sol.omega @ scene.system.constraints.basis.T
    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.add_subplot()
    for i in range(xi.shape[-1]):
        ax.plot(tt, xi[:, i], label=f"ξ{i + 1}")
    if sol.Gamma is not None:
        for i in range(sol.Gamma.shape[-1]):
            ax.plot(tt, sol.Gamma[:, i], "--", label=f"Γ{i + 1}")
    ax.axvline(T, color="k", lw=0.8)
    ax.set_xlabel("t")
    ax.set_title(f"{scene.name}: the reduced state returns at T = {T:.10g}; R angles {np.round(ph.angles, 6)}")
    ax.legend(ncol=2, fontsize=8)
    fig.savefig(path, dpi=110)
    return True
