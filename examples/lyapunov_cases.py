"""Largest Lyapunov exponents of the reduced flow for each case of the paper, against two non-integrable scenes.

``ls.lyapunov_exponent`` (Benettin: a companion trajectory at distance 1e-7 along a random tangent vector,
renormalised every 5 time units; each interval one ``integrate`` call on the batch of reference and
companion trajectories) over ``t = 200`` (rtol 1e-8) for two initial states of every scene. On the integrable cases
the separation grows at most polynomially on the invariant tori, so the running estimate decays like
``log t / t`` (dashed); Suslov's problem without potential (no invariant measure) tends to asymptotic
points, where it is not positive either. On ``V = B3 Gamma_3`` with ``J1 != J2`` (Ziglin) and on the
heavy top without constraint with a generic centre of mass the estimate levels off at a positive value.

Run: ``python examples/lyapunov_cases.py [--out DIR] [--quick]``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _common import command_line, save_figure  # examples/_common.py
from matplotlib.figure import Figure

import liesuslov as ls
from liesuslov.mechanics import cases

NAME = "lyapunov_cases.png"


def scenes():
    J = [1.0, 2.0, 3.0]
    I4 = np.array([1.0, 2.0, 3.0, 4.0])
    S4 = np.diag(I4) + 0.3 * (np.eye(4, k=1) + np.eye(4, k=-1))
    out = [
        ("Lagrange n=3", cases.lagrange3(1.5, 3.0, 1.0).system, True),
        ("Kharlamova n=3", cases.kharlamova3(J, 1.0, 0.5).system, True),
        ("Klebsh–Tisserand n=3", cases.klebsh_tisserand3(J, 1.0).system, True),
        ("gyroscopic, V=0, n=3", cases.gyroscopic3(J, 0.5).system, True),
        ("Suslov V=0 n=3", cases.suslov3([[2.0, 0.0, 0.5], [0.0, 3.0, 0.3], [0.5, 0.3, 4.0]]).system, False),
        ("Lagrange n=4", cases.lagrange(4, 1.0, 0.5, 2.0).system, True),
        ("Kharlamova n=4", cases.kharlamova(I4, [1.0, -0.7, 0.5]).system, True),
        ("Klebsh–Tisserand n=4", cases.klebsh_tisserand(I4, [4.0, 3.0, 2.0, 1.0]).system, True),
        ("Suslov V=0 n=4", cases.suslov_free(S4).system, False),
        ("V=B₃Γ₃, J₁≠J₂ (Ziglin)", ls.SuslovSystem(ls.Inertia.from_principal_moments(J),
                                                    potential=ls.LinearPotential([0.0, 0.0, 1.0])), True),
        ("heavy top, generic", ls.SuslovSystem(ls.Inertia.from_principal_moments(J), constraints="none",
                                               potential=ls.LinearPotential([1.0, 0.7, 0.4])), True),
    ]
    return out


def initial_states(system, rng, B: int):
    D = system.constraints
    xi = rng.uniform(0.4, 1.2, (B, D.dim)) * rng.choice([-1.0, 1.0], (B, D.dim))
    G = None
    if system.n is not None and system.is_so:
        G = rng.standard_normal((B, system.n))
        G /= np.linalg.norm(G, axis=-1, keepdims=True)
    return xi @ D.basis, G


def main(out_dir=None, quick: bool = False) -> Path:
    T = 15.0 if quick else 200.0
    # a --quick run (the tests) never waits for the one-off compilation of the optional numba kernel
    backend = "numpy" if quick else "auto"
    rng = np.random.default_rng(7)
    fig = Figure(figsize=(11, 6), layout="constrained")
    ax = fig.add_subplot()
    colors = [f"C{i % 10}" for i in range(20)]
    print(f"largest Lyapunov exponent over t = {T:g} (two initial states each); log t / t = {np.log(T) / T:.2e}")
    for k, (name, system, with_gamma) in enumerate(scenes()):
        omega, G = initial_states(system, rng, 2)
        res = ls.lyapunov_exponent(system, omega, (0.0, T), Gamma0=G if with_gamma else None, seed=k,
                                   return_history=True, method="rkmk853", rtol=1e-8,
                                   atol=1e-10, backend=backend)
        print(f"  {name:28s} {np.array2string(res.exponent, precision=4, floatmode='fixed')}   "
              f"spread over the second half {np.max(res.spread):.2e}")
        for j in range(2):
            ax.semilogx(res.times, res.history[:, j], color=colors[k], lw=1.0, ls="-" if k < 9 else "-",
                        label=name if j == 0 else None, alpha=0.9 if k >= 9 else 0.6)
    t = np.linspace(2.0, T, 200)
    ax.semilogx(t, np.log(t) / t, "k--", lw=1.2, label="log t / t")
    ax.axhline(0.0, color="gray", lw=0.6)
    ax.set_xlabel("t")
    ax.set_ylabel("running estimate λ(t)")
    ax.set_title("Largest Lyapunov exponent: integrable cases (→ 0) and non-integrable scenes (> 0)")
    ax.legend(fontsize=7, ncol=2)
    return save_figure(fig, out_dir, NAME)


if __name__ == "__main__":
    command_line(main, __doc__)
