"""Lagrange case in SO(3) and SO(5) against the spherical pendulum it reduces to.

With ``I = diag(I_1, ..., I_1, I_n)``, ``V = B_n Gamma_n`` and the Fedorov–Kozlov constraints, the
``SO(n-1)`` momentum map ``Phi`` vanishes on every Suslov state and ``Phi^{-1}(0)/SO(n-1) = T*S^{n-1}``
carries the spherical pendulum of mass ``m = I_1 + I_n``: ``q = g e_n`` (the symmetry axis in space),
``dq/dt = g Omega e_n``. This needs the attitude g, i.e. the reconstruction.

For n = 3 and n = 5 the body is integrated with reconstruction (RKMK, DOP853 tableau) and mapped by
``ls.to_spherical_pendulum``; ``ls.integrate_pendulum`` integrates the pendulum independently from the
mapped initial point, and ``ls.analytic.SphericalPendulumMotion`` gives it by Jacobi elliptic functions
(``ls.check_lagrange_reduction`` packages the first comparison). The figure shows the two curves
``q(t)`` seen from above (projected on the horizontal plane of the invariant 3-space
``span{gamma, q0, v0}``) and their distance over time; ``|Phi|`` (``ls.momentum_map``) stays 0.

Run: ``python examples/lagrange_pendulum.py [--out DIR] [--quick]``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _common import command_line, save_figure  # examples/_common.py
from matplotlib.figure import Figure
from scipy.interpolate import CubicSpline

import liesuslov as ls

NAME = "lagrange_pendulum.png"

I1, IN, BN = 1.0, 2.0, 1.5      # mass tensor diag(I1, ..., I1, In), V = Bn Gamma_n


def initial_state(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``Omega0`` (a skew matrix in D: only Omega_in != 0) and a unit ``Gamma0`` for SO(n)."""
    u = np.array([0.45, -0.3, 0.2, 0.1])[: n - 1]        # Omega_in, i < n
    Om = np.zeros((n, n))
    Om[:-1, -1], Om[-1, :-1] = u, -u
    G = np.array([0.35, 0.2, -0.15, 0.1])[: n - 1]
    G = np.append(G, -np.sqrt(1.0 - np.sum(G ** 2)))      # the body starts below the horizontal
    return Om, G


def run(n: int, t_end: float, npts: int, rtol: float, backend: str = "auto") -> dict:
    """Integrate SO(n) and the pendulum; compare with each other and with the closed form.

    ``ls.check_lagrange_reduction(case, Om0, G0, t_span)`` packages the same comparison; it is spelled out
    here to show the pieces (and to choose the backend).
    """
    case = ls.cases.lagrange(n, I1=I1, In=IN, Bn=BN)
    system = case.system
    Om0, G0 = initial_state(n)
    t = np.linspace(0.0, t_end, npts)
    opts = dict(method="rkmk853", rtol=rtol, atol=rtol, t_eval=t, backend=backend)
    # the body, with reconstruction, mapped to the sphere: q = g e_n, v = g Omega e_n
    sus = ls.integrate(system, Om0, (0.0, t_end), Gamma0=G0, reconstruct=True, **opts)
    qs, vs = ls.to_spherical_pendulum(sus.g, sus.Omega)
    phi = np.linalg.norm(ls.momentum_map(sus.omega, system.inertia), axis=-1)   # the SO(n-1) momentum map
    # the spherical pendulum from the mapped initial point, integrated and in closed form
    gamma = G0                                             # g0 = identity: gamma = g0 Gamma0 = Gamma0
    q0, v0 = ls.to_spherical_pendulum(np.eye(n), Om0)
    pend = ls.SphericalPendulum(n, I1 + IN, BN, gamma)
    psol = ls.integrate_pendulum(pend, q0, v0, (0.0, t_end), **opts)
    exact = ls.analytic.SphericalPendulumMotion(q0, v0, gamma=gamma, mass=I1 + IN, B=BN)
    qa, _ = exact.state(t)
    E = system.energy(sus.omega, sus.Gamma)
    # measured height period: successive upward zeros of dz/dt, z = <gamma, q>
    sp = CubicSpline(t, vs @ gamma)
    r = sp.roots(extrapolate=False)
    up = r[sp(r, 1) > 0.0]
    # horizontal frame of span{gamma, q0, v0}
    e1 = q0 - (q0 @ gamma) * gamma
    e1 /= np.linalg.norm(e1)
    e2 = v0 - (v0 @ gamma) * gamma - (v0 @ e1) * e1
    e2 /= np.linalg.norm(e2)
    return {"n": n, "t": t, "q": qs, "qa": qa, "exact": exact, "frame": (e1, e2), "E": E,
            "T": float(exact.height_period), "T_meas": float(np.mean(np.diff(up))) if up.size > 1 else np.nan,
            "dq_exact": np.linalg.norm(qs - qa, axis=-1), "dq_pend": np.linalg.norm(qs - psol.q, axis=-1),
            "dv_pend": float(np.max(np.linalg.norm(vs - psol.v, axis=-1))), "phi": float(np.max(phi)),
            "mismatch": float(np.max(np.abs(E - pend.energy(qs, vs)))),
            "drift_s": float(np.max(np.abs(E - E[0]))), "drift_p": float(np.max(np.abs(psol.energy - psol.energy[0])))}


def main(out_dir=None, quick: bool = False) -> Path:
    """Run n = 3 and n = 5, print the checks, save the figure; return its path."""
    t_end, npts, rtol = (12.0, 300, 1e-8) if quick else (40.0, 2500, 1e-12)
    # Quick runs are short: the numpy stepper, so that they never wait for the one-off compilation of
    # the optional numba kernel (backend="auto" uses it when numba is installed).
    backend = "numpy" if quick else "auto"
    runs = [run(n, t_end, npts, rtol, backend) for n in (3, 5)]

    print(f"Lagrange case I = diag({I1:g}, ..., {I1:g}, {IN:g}), V = {BN:g} Gamma_n -> spherical pendulum, "
          f"m = {I1 + IN:g}")
    for r in runs:
        print(f"  SO({r['n']}): max |q_suslov - q_exact| {np.max(r['dq_exact']):.2e}, "
              f"max |q_suslov - q_pendulum(RKMK)| {np.max(r['dq_pend']):.2e}, max |v_s - v_p| {r['dv_pend']:.2e}")
        print(f"         max |Phi| = {r['phi']:.1e}; |E - H(q, v)| = {r['mismatch']:.1e}; "
              f"energy drift {r['drift_s']:.1e} (Suslov), {r['drift_p']:.1e} (pendulum)")
        print(f"         height period: closed form {r['T']:.10f}, measured {r['T_meas']:.10f}; precession per "
              f"period {float(r['exact'].precession):.6f} rad")

    fig = Figure(figsize=(13, 9), layout="constrained")
    axs = fig.subplots(2, 2, width_ratios=[1.0, 1.5])
    for row, r in zip(axs, runs, strict=True):
        q, (e1, e2) = r["q"], r["frame"]
        ax = row[0]
        th = np.linspace(0, 2 * np.pi, 200)
        ax.plot(np.cos(th), np.sin(th), color="0.8", lw=0.8)
        ax.plot(q @ e1, q @ e2, color="C0", lw=1.6, label=r"Suslov: $q = g\,e_n$ (RKMK)")
        ax.plot(r["qa"] @ e1, r["qa"] @ e2, color="C3", lw=0.9, ls="--", label="spherical pendulum (elliptic)")
        ax.plot(q[0] @ e1, q[0] @ e2, "ko", ms=4)
        ax.set_aspect("equal")
        ax.set_xlabel(r"$\langle q, e_1\rangle$")
        ax.set_ylabel(r"$\langle q, e_2\rangle$")
        ax.set_title(f"SO({r['n']}) → $S^{{{r['n'] - 1}}}$: q(t) seen along γ", fontsize=10)
        ax.legend(fontsize=8, loc="upper right")
        ax = row[1]
        t = r["t"]
        floor = 1e-17
        ax.semilogy(t[1:], np.maximum(r["dq_exact"][1:], floor), label=r"$|q_{\rm Suslov} - q_{\rm exact}|$")
        ax.semilogy(t[1:], np.maximum(r["dq_pend"][1:], floor),
                    label=r"$|q_{\rm Suslov} - q_{\rm pendulum}|$ (both RKMK)")
        ax.semilogy(t[1:], np.maximum(np.abs(r["E"][1:] - r["E"][0]), floor),
                    label="energy drift (Suslov)", lw=0.8)
        ax.set_xlabel("t")
        ax.set_title(f"SO({r['n']}): distance of the two curves (rtol = {rtol:g}); "
                     rf"max $|\Phi|$ = {r['phi']:.1g}", fontsize=10)
        ax.legend(fontsize=8, loc="lower right")
    fig.suptitle("Lagrange case = spherical pendulum after the SO(n-1) reduction")
    return save_figure(fig, out_dir, NAME)


if __name__ == "__main__":
    command_line(main, __doc__)
