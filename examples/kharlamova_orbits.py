"""Kharlamova case in SO(5): a periodic and a near-asymptotic orbit, with the roots of the quartic P4.

With ``V = sum_{i<n} B_i Gamma_i`` and the Fedorov–Kozlov constraints, ``omega_1 = c_1 Omega_1n``
(``c_i = (I_i + I_n)/B_i``) obeys ``(d omega_1/dt)^2 = P4(omega_1)`` with ``Gamma_n^2 = P4(omega_1)``:
``omega_1`` oscillates between two adjacent real roots of P4 with period
``T = 2 int d omega_1 / sqrt(P4)``. When the upper or lower root is double the motion is asymptotic to
an equilibrium (``T = inf``); close to it the orbit lingers near the double root and the period
grows like ``log(1/distance)``.

Two orbits are integrated with RKMK (DOP853 tableau, adaptive) and compared with the closed form of
``ls.analytic.KharlamovaMotion``: ``omega_1(t)`` against the roots of P4, the points
``(omega_1, Gamma_n^2)`` on the graph of P4, the period measured from the integration (successive
upward zeros of ``Gamma_n``) against the analytic one, and the distance to the closed-form state.

Run: ``python examples/kharlamova_orbits.py [--out DIR] [--quick]``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _common import command_line, save_figure  # examples/_common.py
from matplotlib.figure import Figure
from scipy.interpolate import CubicSpline

import liesuslov as ls

NAME = "kharlamova_orbits.png"

I = np.array([1.0, 2.0, 3.0, 4.0, 5.0])   # diagonal mass tensor, n = 5
B = np.array([1.0, -0.5, 0.7, 0.9])       # V = sum_{i<5} B_i Gamma_i
C = (I[:-1] + I[-1]) / B                  # c_i of the coordinates (4.6)


def periodic_orbit() -> tuple[np.ndarray, np.ndarray]:
    """A generic initial state ``(u, Gamma)``: u_i = Omega_i5, Gamma a unit vector."""
    u = np.array([0.3, -0.2, 0.1, 0.25])
    G = np.array([0.3, 0.4, -0.2, 0.1, 0.0])
    G[-1] = np.sqrt(1.0 - np.sum(G ** 2))
    return u, G


def near_asymptotic_orbit(eta: float = 1e-5) -> tuple[np.ndarray, np.ndarray]:
    """A state ``eta`` away from the orbit asymptotic to an unstable equilibrium.

    Equilibria have ``Gamma_5 = 0`` and ``<Gamma', u> = 0`` (``Gamma' = (Gamma_1..Gamma_4)``); the
    exact solution ``u = u* + x/c``, ``Gamma_i = Gamma*_i - u*_i x - x^2/(2 c_i)``, ``Gamma_5^2 = P(x)``
    through it has a double root of P at ``x = 0``, a minimum of P when
    ``sum_i Gamma*_i / c_i > |u*|^2``. Its point at ``x = 0.3`` lies on the asymptotic orbit;
    shifting ``u_1`` by ``eta`` gives a periodic orbit of long period.
    """
    Gs = np.array([0.5, -0.5, 0.5, 0.5])
    us = np.array([0.1, 0.1, 0.0, 0.0])
    us = us - Gs * (us @ Gs)            # <Gamma*, u*> = 0
    x = 0.3
    u = us + x / C
    G = Gs - us * x - x * x / (2.0 * C)
    G = np.append(G, np.sqrt(1.0 - np.sum(G ** 2)))
    u[0] += eta
    return u, G


def upward_zeros(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Times where the sampled ``y`` crosses zero upwards (cubic-spline interpolation)."""
    sp = CubicSpline(t, y)
    r = sp.roots(extrapolate=False)
    return r[sp(r, 1) > 0.0]


def run_orbit(case: ls.Case, u0: np.ndarray, G0: np.ndarray, periods: float, npts: int, rtol: float,
              backend: str = "auto") -> dict:
    """Integrate one orbit over ``periods`` analytic periods and compare it with the closed form."""
    alg = case.system.algebra
    idx = [alg.index(i, 4) for i in range(4)]   # positions of Omega_i5 among the so(5) coordinates
    mot = ls.analytic.KharlamovaMotion(u0, G0, I, B)
    T = float(mot.period)
    t = np.linspace(0.0, periods * T, npts)
    x0 = np.zeros(alg.dim)
    x0[idx] = u0
    sol = ls.integrate(case.system, x0, (0.0, t[-1]), Gamma0=G0, method="rkmk853", rtol=rtol, atol=rtol * 1e-2,
                       t_eval=t, backend=backend)
    u, G = sol.omega[:, idx], sol.Gamma
    ua, Ga = mot.state(t)
    err = np.linalg.norm(u - ua, axis=-1) + np.linalg.norm(G - Ga, axis=-1)
    ints = case.evaluate(sol.omega, G)
    drift = max(float(np.max(np.abs(v - v[0]))) for v in ints.values())
    z = upward_zeros(t, G[:, -1])
    T_meas = float(np.mean(np.diff(z))) if z.size >= 2 else float("nan")
    roots = mot.quartic_roots
    real = np.sort(roots.real[np.abs(roots.imag) <= 1e-6 * np.max(np.abs(roots))])
    return {"t": t, "w1": C[0] * u[:, 0], "Gn": G[:, -1], "err": err, "T": T, "T_meas": T_meas,
            "zeros": z, "drift": drift, "kind": str(mot.kind), "bracket": mot.bracket, "roots": real,
            "quartic": mot.quartic, "steps": sol.stats["steps"], "wall": sol.stats["wall_time"]}


def main(out_dir=None, quick: bool = False) -> Path:
    """Integrate both orbits, print the checks, save the figure; return its path."""
    case = ls.cases.kharlamova(I=I, B=B)
    npts, rtol = (600, 1e-8) if quick else (4000, 1e-12)
    # Quick runs are a few hundred steps: the numpy stepper, so that they never wait for the one-off
    # compilation of the optional numba kernel (backend="auto" uses it when numba is installed).
    backend = "numpy" if quick else "auto"
    orbits = {"periodic": run_orbit(case, *periodic_orbit(), 2.3, npts, rtol, backend),
              "near-asymptotic": run_orbit(case, *near_asymptotic_orbit(), 2.3, npts, rtol, backend)}

    print(f"Kharlamova case in SO(5): I = {I.tolist()}, B = {B.tolist()}")
    for name, r in orbits.items():
        lo, hi = r["bracket"]
        print(f"  {name:16s} ({r['kind']}): omega_1 in [{lo:.6f}, {hi:.6f}], real roots of P4 "
              f"{np.array2string(r['roots'], precision=6)}")
        print(f"  {'':16s} period: analytic {r['T']:.10f}, measured {r['T_meas']:.10f} "
              f"(|diff| {abs(r['T'] - r['T_meas']):.1e}, from {r['zeros'].size} upward zeros of Gamma_5)")
        print(f"  {'':16s} max |state - closed form| {np.max(r['err']):.2e}; integral drift {r['drift']:.2e}; "
              f"{r['steps']} steps, {r['wall']:.2f} s")

    fig = Figure(figsize=(12, 8), layout="constrained")
    axs = fig.subplots(2, 2)
    colors = {"periodic": "C0", "near-asymptotic": "C3"}
    for ax, (name, r) in zip(axs[0], orbits.items(), strict=True):
        ax.plot(r["t"], r["w1"], color=colors[name], lw=1.4, label=r"$\omega_1(t)$ (RKMK)")
        lo, hi = r["bracket"]
        for k, root in enumerate(r["roots"]):
            end = np.isclose(root, lo, rtol=0, atol=1e-6) or np.isclose(root, hi, rtol=0, atol=1e-6)
            ax.axhline(root, color="k", ls="--" if end else ":", lw=0.9,
                       label="roots of $P_4$ (bracketing: dashed)" if k == 0 else None)
        for z in r["zeros"]:
            ax.axvline(z, color="0.7", lw=0.6)
        close = np.diff(r["roots"])
        if close.size and np.min(close) < 0.05 * (hi - lo):
            j = int(np.argmin(close))
            ax.annotate(f"nearly double root: {r['roots'][j]:.4f}, {r['roots'][j + 1]:.4f}",
                        (r["t"][-1] * 0.5, r["roots"][j + 1]), xytext=(0, 25), textcoords="offset points",
                        ha="center", fontsize=8, arrowprops={"arrowstyle": "->", "lw": 0.7})
        ax.set_title(f"{name}: T = {r['T']:.6f} (analytic), {r['T_meas']:.6f} (measured)", fontsize=10)
        ax.set_xlabel("t")
        ax.set_ylabel(r"$\omega_1 = c_1\,\Omega_{15}$")
        ax.legend(loc="best", fontsize=8)
        ax.text(0.01, 0.01, "grey: upward zeros of $\\Gamma_5$", transform=ax.transAxes, fontsize=8, color="0.4")

    ax = axs[1, 0]
    for name, r in orbits.items():
        lo, hi = r["bracket"]
        pad = 0.15 * (hi - lo)
        w = np.linspace(lo - pad, hi + pad, 400)
        ax.plot(w, np.polyval(r["quartic"], w), color=colors[name], lw=1.0, label=f"$P_4$, {name}")
        ax.plot(r["w1"][::7], r["Gn"][::7] ** 2, "o", ms=2.5, color=colors[name], alpha=0.6,
                label=r"$(\omega_1, \Gamma_5^2)$ along the integration")
        ax.plot(r["roots"], np.zeros_like(r["roots"]), "kx", ms=7)
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_ylim(-0.15, None)
    ax.set_xlabel(r"$\omega_1$")
    ax.set_ylabel(r"$P_4(\omega_1) = \Gamma_5^2$")
    ax.set_title(r"the quartic: $\dot\omega_1^2 = P_4(\omega_1)$ (x: real roots)")
    ax.legend(fontsize=7, loc="upper left")

    ax = axs[1, 1]
    for name, r in orbits.items():
        ax.semilogy(r["t"][1:], np.maximum(r["err"][1:], 1e-17), color=colors[name], lw=1.0, label=name)
    ax.set_xlabel("t")
    ax.set_ylabel(r"$|u - u_{\rm exact}| + |\Gamma - \Gamma_{\rm exact}|$")
    ax.set_title(f"RKMK (rkmk853, rtol = {rtol:g}) against the elliptic closed form")
    ax.legend(fontsize=8, loc="upper left")
    ax.text(0.02, 0.03, "near the saddle errors grow like its instability (the orbit passes it once per period)",
            transform=ax.transAxes, fontsize=8, color="0.3")
    fig.suptitle("Kharlamova case, SO(5): periodic and near-asymptotic motions")
    return save_figure(fig, out_dir, NAME)


if __name__ == "__main__":
    command_line(main, __doc__)
