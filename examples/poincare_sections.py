"""Poincaré sections of Suslov's body (n = 3) with ``V = B3 Gamma_3``: integrable (J1 = J2) beside not (J1 != J2).

Both scenes have the constraint ``w3 = 0`` and the potential ``V = Gamma_3``. On the left the Lagrange
case ``J = diag(1.5, 1.5, 3)`` (integrable: the extra integral ``F = <J w, Gamma>`` confines each
trajectory to an invariant torus, a closed curve of the section); on the right ``J = diag(1, 2, 3)``
(``J1 != J2``: not integrable by Ziglin's theorem, quoted in the paper): a chaotic sea around regular
islands. Each panel shows the crossings of ``Gamma_3 = 0`` (upwards) of
trajectories on one energy level, in the coordinates (azimuth of Gamma, angle of xi = (w2, -w1) in D);
all trajectories of a panel are one ``ls.poincare_section`` call. The integrals' drift at the crossings
and the largest Lyapunov exponent of a trajectory of each scene are printed.

Run: ``python examples/poincare_sections.py [--out DIR] [--quick]``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _common import command_line, save_figure  # examples/_common.py
from matplotlib.figure import Figure

import liesuslov as ls
from liesuslov.mechanics import cases
from liesuslov.research import gamma_crossing
from liesuslov.research.commands import same_energy_states, section_coordinates

NAME = "poincare_sections.png"
J = [1.0, 2.0, 3.0]


def scenes():
    lag = cases.lagrange3(1.5, 3.0, 1.0)
    chaos = ls.SuslovSystem(ls.Inertia.from_principal_moments(J), potential=ls.LinearPotential([0.0, 0.0, 1.0]))
    return [("Lagrange, J₁ = J₂ (integrable)", lag.system, lag),
            ("V = B₃Γ₃, J₁ ≠ J₂ (non-integrable)", chaos, None)]


def main(out_dir=None, quick: bool = False) -> Path:
    N, T = (4, 40.0) if quick else (8, 250.0)
    # a --quick run (the tests) never waits for the one-off compilation of the optional numba kernel
    backend = "numpy" if quick else "auto"
    fig = Figure(figsize=(11, 5), layout="constrained")
    for k, (title, system, case) in enumerate(scenes()):
        D = system.constraints
        omega0 = np.array([0.5, 0.3]) @ D.basis
        G0 = np.array([0.6, 0.0, 0.8])
        omega, Gamma = same_energy_states(system, omega0, G0, N, seed=1, scale=0.6)
        rec = ls.poincare_section(system, omega, (0.0, T), gamma_crossing(3), Gamma0=Gamma, direction=1,
                                  backend=backend)
        E = system.energy(omega, Gamma)
        drift = np.max(np.abs(system.energy(rec.omega, rec.Gamma) - E[rec.index]))
        line = f"{title}: {rec.t.size} crossings of {N} trajectories, energy drift at the crossings {drift:.2e}"
        if case is not None:
            F = case.integrals["F"]
            dF = np.max(np.abs(F(rec.omega, rec.Gamma) - F(omega, Gamma)[rec.index]))
            line += f", |F - F(0)| <= {dF:.2e}"
        lam = ls.lyapunov_exponent(system, omega[:4], (0.0, T / 2), Gamma0=Gamma[:4], seed=0, backend=backend)
        print(line)
        print(f"    largest Lyapunov exponents of 4 of them over t = {T / 2:g}: {np.array2string(lam, precision=3)}"
              f" (log t / t = {np.log(T / 2) / (T / 2):.2e})")
        x, y, xl, yl = section_coordinates(system, rec.omega, rec.Gamma)
        ax = fig.add_subplot(1, 2, k + 1)
        ax.scatter(x, y, c=rec.index, s=1.5, cmap="tab20", vmin=0, vmax=N - 1)
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.set_title(f"{title}\nΓ₃ = 0 upwards, E = {float(E[0]):.4g}")
        ax.set_xlim(-np.pi, np.pi)
        ax.set_ylim(-np.pi, np.pi)
    return save_figure(fig, out_dir, NAME)


if __name__ == "__main__":
    command_line(main, __doc__)
