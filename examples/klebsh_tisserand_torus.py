"""Klebsh–Tisserand case in SO(4): a trajectory winding on its invariant torus, in t and in tau.

With ``V = 1/2 sum_i B_i Gamma_i^2`` (``B_i > B_4``) the integrals
``F_i = (B_i - B_4) Gamma_i^2 + (I_i + I_4) Omega_i4^2`` fix, in each plane ``(Omega_i4, Gamma_i)``, an
ellipse with angle ``phi_i``; when ``sum_i F_i / (B_i - B_4) < 1`` (the two-tori condition) ``Gamma_4``
never vanishes and the angles are linear, ``phi_i = phi_i^0 + omega_i tau``, in the new time
``d tau = Gamma_4 dt`` with ``omega_i = sqrt((B_i - B_4)/(I_i + I_4))`` — but not in t.

The body is integrated with reconstruction (attitude g in SO(4), ``Gamma = g^T gamma``) by RKMK with
the DOP853 tableau and compared with ``ls.analytic.KlebshTisserandMotion`` (closed form in tau, the
quadrature ``t(tau)`` inverted); ``tau`` is also computed from the integration itself (the integral of
``Gamma_4``) and checked against the closed form.

Run: ``python examples/klebsh_tisserand_torus.py [--out DIR] [--quick]``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _common import command_line, save_figure  # examples/_common.py
from matplotlib.figure import Figure
from scipy.interpolate import CubicSpline

import liesuslov as ls

NAME = "klebsh_tisserand_torus.png"

I = np.array([1.0, 2.0, 3.0, 4.0])   # diagonal mass tensor
B = np.array([4.0, 3.0, 2.0, 1.0])   # B_i > B_4
U0 = np.array([0.3, -0.2, 0.25])     # Omega_14, Omega_24, Omega_34 at t = 0
G0 = np.array([0.3, 0.25, -0.2, 0.0])
G0[-1] = np.sqrt(1.0 - np.sum(G0 ** 2))


def main(out_dir=None, quick: bool = False) -> Path:
    """Integrate, compare with the closed form, print the checks, save the figure; return its path."""
    t_end, npts, rtol = (15.0, 400, 1e-8) if quick else (60.0, 3000, 1e-11)
    # Quick runs are a few hundred steps: the numpy stepper, so that they never wait for the one-off
    # compilation of the optional numba kernel (backend="auto" uses it when numba is installed).
    backend = "numpy" if quick else "auto"
    case = ls.cases.klebsh_tisserand(I=I, B=B)
    alg = case.system.algebra
    idx = [alg.index(i, 3) for i in range(3)]   # positions of Omega_i4 among the so(4) coordinates
    x0 = np.zeros(alg.dim)
    x0[idx] = U0

    mot = ls.analytic.KlebshTisserandMotion(U0, G0, I, B)
    c0, phi0 = ls.analytic.klebsh_tisserand_angles(U0, G0, I, B)
    w = mot.frequencies
    two_tori = bool(ls.analytic.klebsh_tisserand_two_tori(c0, B))

    t = np.linspace(0.0, t_end, npts)
    sol = ls.integrate(case.system, x0, (0.0, t_end), Gamma0=G0, reconstruct=True, method="rkmk853",
                       rtol=rtol, atol=rtol * 1e-2, t_eval=t, backend=backend)
    u, G, g = sol.omega[:, idx], sol.Gamma, sol.g
    c, phi = ls.analytic.klebsh_tisserand_angles(u, G, I, B)
    phi = np.unwrap(phi, axis=0)

    tau_exact = mot.tau(t)
    tau_num = CubicSpline(t, G[:, -1]).antiderivative()(t)      # tau = int Gamma_4 dt along the integration
    ua, Ga = mot.state(t)
    err = np.linalg.norm(u - ua, axis=-1) + np.linalg.norm(G - Ga, axis=-1)
    ints = case.evaluate(sol.omega, G)
    drift = {k: float(np.max(np.abs(v - v[0]))) for k, v in ints.items()}
    ortho = np.max(np.abs(np.swapaxes(g, -1, -2) @ g - np.eye(4)), axis=(-2, -1))
    lin_tau = phi - (phi0 + np.outer(tau_exact, w))               # 0 on the torus: linear in tau
    lin_t = phi - (phi0 + np.outer(t, w))                         # not linear in t

    print(f"Klebsh–Tisserand case in SO(4): I = {I.tolist()}, B = {B.tolist()}")
    print(f"  integrals c = F_i = {np.array2string(c0, precision=6)}; sum c_i/(B_i - B_4) = "
          f"{1.0 - float(mot.margin):.4f} < 1: two tori {two_tori} (Gamma_4 >= sqrt(delta) = "
          f"{np.sqrt(float(mot.margin)):.4f}; min along the integration {np.min(G[:, -1]):.4f})")
    print(f"  energy E = {float(mot.energy):.12f} = (B_4 + sum F_i)/2; frequencies omega_i = "
          f"{np.array2string(w, precision=6)}")
    print(f"  max |state - closed form| = {np.max(err):.2e};  max |tau_integrated - tau_exact| = "
          f"{np.max(np.abs(tau_num - tau_exact)):.2e}")
    print(f"  angles: max |phi - (phi0 + omega tau)| = {np.max(np.abs(lin_tau)):.2e}, "
          f"max |phi - (phi0 + omega t)| = {np.max(np.abs(lin_t)):.2f} (not linear in t)")
    print("  drift of the integrals: " + ", ".join(f"{k} {v:.1e}" for k, v in drift.items()))
    print(f"  max |g^T g - I| = {np.max(ortho):.1e}; {sol.stats['steps']} steps, {sol.stats['nfev']} field "
          f"evaluations, {sol.stats['wall_time']:.2f} s")

    fig = Figure(figsize=(15, 8.5), layout="constrained")
    gs = fig.add_gridspec(2, 3)

    ax = fig.add_subplot(gs[0, 0], projection="3d")
    R, r = 2.0, 0.8
    a, b = np.meshgrid(np.linspace(0, 2 * np.pi, 50), np.linspace(0, 2 * np.pi, 25))
    ax.plot_surface((R + r * np.cos(b)) * np.cos(a), (R + r * np.cos(b)) * np.sin(a), r * np.sin(b),
                    color="0.85", alpha=0.25, linewidth=0)
    p1, p2 = phi[:, 0], phi[:, 1]
    ax.scatter((R + r * np.cos(p2)) * np.cos(p1), (R + r * np.cos(p2)) * np.sin(p1), r * np.sin(p2), c=t,
               cmap="viridis", s=2)
    ax.set_title(r"$(\varphi_1, \varphi_2)$ on a torus (colour: t)", fontsize=10)
    ax.set_axis_off()
    ax.set_box_aspect((1, 1, 0.4))

    ax = fig.add_subplot(gs[0, 1])
    ax.scatter(np.mod(phi[:, 0], 2 * np.pi), np.mod(phi[:, 1], 2 * np.pi), c=t, cmap="viridis", s=2)
    ax.set_xlabel(r"$\varphi_1$ mod $2\pi$")
    ax.set_ylabel(r"$\varphi_2$ mod $2\pi$")
    ax.set_title(r"flat torus: straight windings of slope $\omega_2/\omega_1$" f" = {w[1] / w[0]:.4f}",
                 fontsize=10)

    ax = fig.add_subplot(gs[0, 2])
    ax.plot(t, G[:, -1], label=r"$\Gamma_4(t)$")
    ax.axhline(np.sqrt(float(mot.margin)), color="k", ls="--", lw=0.8, label=r"$\sqrt{\delta}$ (lower bound)")
    ax.plot(t, tau_exact / t_end, label=r"$\tau(t)/t_{\rm end}$ (closed form)")
    ax.plot(t[::max(1, npts // 40)], tau_num[::max(1, npts // 40)] / t_end, "k.", ms=3,
            label=r"$\int\Gamma_4\,dt$ (integration)")
    ax.set_xlabel("t")
    ax.set_title(r"the new time $d\tau = \Gamma_4\,dt$ ($\Gamma_4$ keeps its sign)", fontsize=10)
    ax.legend(fontsize=8)

    ax = fig.add_subplot(gs[1, 0])
    for i in range(3):
        ax.plot(t, phi[:, i] - phi0[i], color=f"C{i}", label=rf"$\varphi_{i + 1}$")
        ax.plot(t, w[i] * t, color=f"C{i}", ls=":", lw=0.8)
    ax.set_xlabel("t")
    ax.set_ylabel(r"$\varphi_i - \varphi_i^0$ (unwrapped)")
    ax.set_title(r"angles in t: not linear (dotted: $\omega_i t$)", fontsize=10)
    ax.legend(fontsize=8)

    ax = fig.add_subplot(gs[1, 1])
    step = max(1, npts // 60)
    for i in range(3):
        ax.plot(tau_exact, w[i] * tau_exact, color=f"C{i}", lw=0.9, label=rf"$\omega_{i + 1}\tau$ (closed form)")
        ax.plot(tau_num[::step], phi[::step, i] - phi0[i], "o", color=f"C{i}", ms=3, mfc="none")
    ax.set_xlabel(r"$\tau$ (integrated from the numerical $\Gamma_4$)")
    ax.set_ylabel(r"$\varphi_i - \varphi_i^0$")
    ax.set_title(r"angles in $\tau$: straight lines (o: RKMK)", fontsize=10)
    ax.legend(fontsize=8)

    ax = fig.add_subplot(gs[1, 2])
    floor = 1e-17
    ax.semilogy(t[1:], np.maximum(err[1:], floor), label="|state - closed form|")
    ax.semilogy(t[1:], np.maximum(np.max(np.abs(lin_tau[1:]), axis=-1), floor),
                label=r"$\max_i|\varphi_i - \varphi_i^0 - \omega_i\tau|$")
    Fs = np.stack([ints[f"F_{i + 1}"] for i in range(3)], axis=-1)
    ax.semilogy(t[1:], np.maximum(np.max(np.abs(Fs[1:] - Fs[0]), axis=-1), floor), label=r"$\max_i|\Delta F_i|$")
    ax.semilogy(t[1:], np.maximum(ortho[1:], floor), label=r"$|g^Tg - I|$")
    ax.set_xlabel("t")
    ax.set_title(f"RKMK (rkmk853, rtol = {rtol:g}) with reconstruction", fontsize=10)
    ax.legend(fontsize=8)
    fig.suptitle(f"Klebsh–Tisserand case, SO(4): motion on an invariant torus "
                 rf"($\omega$ = {np.array2string(w, precision=3)} in $\tau$)")
    return save_figure(fig, out_dir, NAME)


if __name__ == "__main__":
    command_line(main, __doc__)
