"""Command line: ``liesuslov run [SCENE.toml]`` (the main job) and friends."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["main", "default_scene"]


def default_scene():
    """The built-in scene: the n = 4 Klebsh–Tisserand body on a torus, with reconstruction on SO(4).

    Returns
    -------
    dict with ``system``, ``Omega0``, ``Gamma0``, ``t_span``, ``integrals`` and integration options.
    """
    from .algebra import Inertia
    from .mechanics import QuadraticPotential, SuslovSystem

    I = np.array([1.0, 1.5, 2.0, 0.5])
    B = np.array([4.0, 3.0, 2.5, 1.0])
    system = SuslovSystem(Inertia.from_mass_tensor(np.diag(I)), potential=QuadraticPotential(B))
    u = np.array([0.3, -0.2, 0.25])
    Omega0 = np.zeros((4, 4))
    Omega0[:3, 3], Omega0[3, :3] = u, -u
    Gamma0 = np.array([0.3, 0.2, -0.25, 0.0])
    Gamma0[3] = np.sqrt(1 - np.sum(Gamma0[:3] ** 2))

    def F(omega, Gamma):  # Klebsh–Tisserand integrals F_i = (B_i - B_n) Gamma_i^2 + (I_i + I_n) Omega_in^2
        Oin = omega[..., [2, 4, 5]]
        return (B[:3] - B[3]) * Gamma[..., :3] ** 2 + (I[:3] + I[3]) * Oin ** 2

    return {"name": "klebsh-tisserand n=4", "system": system, "Omega0": Omega0, "Gamma0": Gamma0,
            "t_span": (0.0, 50.0), "reconstruct": True, "method": "rkmk853", "chart": "exp",
            "rtol": 1e-10, "atol": 1e-12, "integrals": {"F_i (Klebsh-Tisserand)": F}}


def _run(args) -> int:
    from .integrators import integrate

    scene = default_scene() if args.scene is None else _load_scene(args.scene)
    out = Path(args.out)
    system = scene["system"]
    kw = {k: scene[k] for k in ("reconstruct", "method", "chart", "rtol", "atol", "h") if k in scene}
    t_span = scene["t_span"]
    t_eval = np.linspace(t_span[0], t_span[1], args.samples)
    start = time.perf_counter()
    sol = integrate(system, scene["Omega0"], t_span, Gamma0=scene.get("Gamma0"), t_eval=t_eval,
                    progress=args.progress, **kw)
    wall = time.perf_counter() - start
    model = system.model(gamma=scene.get("Gamma0") is not None)
    print(f"scene: {scene['name']}")
    print(f"model: {model.description()}")
    print(f"method: {sol.stats['method']} ({sol.stats['chart']} chart), steps {sol.stats['steps']}, "
          f"rejected {sol.stats['rejected']}, nfev {sol.stats['nfev']}, time {wall:.3f} s")
    if not sol.success:
        print(f"FAILED: {sol.message}")
    E = system.energy(sol.omega, sol.Gamma)
    print(f"energy drift max |E - E0| = {np.max(np.abs(E - E[0])):.3e}")
    for name, F in scene.get("integrals", {}).items():
        vals = F(sol.omega, sol.Gamma)
        print(f"integral {name}: max drift {np.max(np.abs(vals - vals[0])):.3e}")
    D = system.constraints
    print(f"constraint defect max |pr_D-perp Omega| = {np.max(np.abs(D.complement().coordinates(sol.omega))):.3e}")
    if sol.Gamma is not None:
        print(f"sphere defect max ||Gamma| - 1| = {np.max(np.abs(np.linalg.norm(sol.Gamma, axis=-1) - 1)):.3e}")
    if sol.g is not None:
        m = sol.g.shape[-1]
        orth = np.max(np.abs(np.swapaxes(sol.g, -1, -2) @ sol.g - np.eye(m)))
        print(f"orthogonality defect max |g^T g - I| = {orth:.3e}")
    out.mkdir(parents=True, exist_ok=True)
    path = sol.save(out / "trajectory.npz")
    print(f"wrote {path}")
    fig = _figure(sol, out / "trajectory.png", scene["name"])
    if fig:
        print(f"wrote {fig}")
    return 0 if sol.success else 1


def _figure(sol, path: Path, title: str):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("(matplotlib not installed: no figure; pip install 'liesuslov[plot]')")
        return None
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    axes[0].plot(sol.t, sol.xi)
    axes[0].set_xlabel("t")
    axes[0].set_ylabel(r"$\xi$ (reduced coordinates of $\Omega$)")
    if sol.Gamma is not None:
        axes[1].plot(sol.t, sol.Gamma)
        axes[1].set_ylabel(r"$\Gamma$")
    axes[1].set_xlabel("t")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _load_scene(path):
    from .scene import load_scene

    return load_scene(path)


def main(argv=None) -> int:
    """Entry point of the ``liesuslov`` console script."""
    parser = argparse.ArgumentParser(prog="liesuslov", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="integrate a scene (default: the built-in n = 4 Klebsh–Tisserand body)")
    run.add_argument("scene", nargs="?", default=None, help="a scene TOML file")
    run.add_argument("--out", default="liesuslov-out", help="output folder (default: liesuslov-out)")
    run.add_argument("--samples", type=int, default=501, help="number of output times")
    run.add_argument("--progress", action="store_true", help="show a progress bar")
    args = parser.parse_args(argv)
    try:
        if args.command == "run":
            return _run(args)
    except (ValueError, TypeError, FileNotFoundError) as exc:
        print(f"liesuslov: error: {exc}", file=sys.stderr)
        return 2
    return 0
