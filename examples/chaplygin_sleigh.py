"""The Chaplygin sleigh: an Euler–Poincaré–Suslov system on se(2) built from its structure constants.

A rigid body slides on the plane on a knife edge at the contact point P; its centre of mass lies a
distance ``a`` ahead of P on the blade. In the body frame at P (x-axis along the blade) the velocity is
``xi = (omega, v_x, v_y)`` in the basis ``e_1`` (rotation), ``e_2``, ``e_3`` (translations) of se(2):
``[e_1, e_2] = e_3``, ``[e_1, e_3] = -e_2``, ``[e_2, e_3] = 0``. The kinetic energy
``1/2 m |v + omega x (a, 0)|^2 + 1/2 I_C omega^2`` gives the inertia

    K = [[I_C + m a^2, 0, m a], [0, m, 0], [m a, 0, m]]

(not diagonal: P is not the centre of mass), and the knife edge forbids sliding sideways:
``v_y = 0``, the annihilator of the covector ``(0, 0, 1)``. D = span{e_1, e_2} is not a subalgebra
(``[e_1, e_2] = e_3``): the constraint is nonholonomic.

With ``J = I_C + m a^2`` the reduced equations ``J omega' = -m a omega v``, ``v' = a omega^2`` conserve
``E = (J omega^2 + m v^2)/2`` and have the solution ``v = V tanh(lambda t + s0)``,
``omega = omega_0 cosh(s0) / cosh(lambda t + s0)`` (``V = sqrt(2E/m)``, ``lambda = a m V / J``): every sleigh
stops turning and ends moving in a straight line at speed ``V`` with the centre of mass ahead, heading
turned by ``(omega_0 cosh(s0)/lambda)(pi/2 - gd(s0))`` (``gd`` the Gudermannian).

The path is reconstructed on SE(2) in its 3×3 matrix representation (``g' = g xi^``).

Run: ``python examples/chaplygin_sleigh.py [--out DIR] [--quick]``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _common import command_line, save_figure  # examples/_common.py
from matplotlib.figure import Figure

import liesuslov as ls

NAME = "chaplygin_sleigh.png"

M, A_OFF, I_C = 1.0, 0.5, 0.2    # mass, offset of the centre of mass ahead of the blade, inertia about it


def se2_from_structure_constants() -> ls.LieAlgebra:
    """se(2) from ``C[i, j, k]`` (``[e_i, e_j] = sum_k C[i, j, k] e_k``), with its matrix representation."""
    C = np.zeros((3, 3, 3))
    C[0, 1, 2], C[1, 0, 2] = 1.0, -1.0     # [e_1, e_2] = e_3
    C[0, 2, 1], C[2, 0, 1] = -1.0, 1.0     # [e_1, e_3] = -e_2
    R = np.zeros((3, 3, 3))                # e_1 = rotation generator, e_2, e_3 = translations
    R[0, 0, 1], R[0, 1, 0] = -1.0, 1.0
    R[1, 0, 2] = 1.0
    R[2, 1, 2] = 1.0
    return ls.LieAlgebra(C, representation=R, name="se(2) from C")


def exact(xi0: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``omega(t)``, ``v(t)`` (shape (N, batch)) and the limit heading change (batch,) in closed form."""
    Jp = I_C + M * A_OFF ** 2
    w0, v0 = xi0[:, 0], xi0[:, 1]
    V = np.sqrt((Jp * w0 ** 2 + M * v0 ** 2) / M)
    lam = A_OFF * M * V / Jp
    s0 = np.arctanh(v0 / V)
    arg = lam * t[:, None] + s0
    gd0 = 2.0 * np.arctan(np.tanh(s0 / 2.0))
    return w0 * np.cosh(s0) / np.cosh(arg), V * np.tanh(arg), w0 * np.cosh(s0) / lam * (np.pi / 2 - gd0)


def main(out_dir=None, quick: bool = False) -> Path:
    """Integrate a batch of sleighs, print the checks, save the figure; return its path."""
    t_end, npts, rtol = (12.0, 200, 1e-8) if quick else (40.0, 2000, 1e-12)
    # a --quick run (the tests) never waits for the one-off compilation of the optional numba kernel
    backend = "numpy" if quick else "auto"
    alg = se2_from_structure_constants()
    ref = ls.se(2)
    dC = float(np.max(np.abs(alg.structure_constants - ref.structure_constants)))
    dR = float(np.max(np.abs(alg.representation - ref.representation)))
    K = np.array([[I_C + M * A_OFF ** 2, 0.0, M * A_OFF],
                  [0.0, M, 0.0],
                  [M * A_OFF, 0.0, M]])
    D = ls.Subspace.annihilator(alg, np.array([[0.0, 0.0, 1.0]]))   # no sideways slip at P: v_y = 0
    system = ls.SuslovSystem(ls.Inertia(alg, K), constraints=D)

    xi0 = np.array([[1.5, 0.3, 0.0], [-1.0, 0.6, 0.0], [2.5, -0.4, 0.0], [0.6, -0.8, 0.0], [-2.0, 0.1, 0.0]])
    t = np.linspace(0.0, t_end, npts)
    sol = ls.integrate(system, xi0, (0.0, t_end), reconstruct=True, method="rkmk45", rtol=rtol, atol=rtol * 1e-2,
                       t_eval=t, backend=backend)
    om, v, vy = sol.omega[..., 0], sol.omega[..., 1], sol.omega[..., 2]
    g = sol.g                                                     # (N, batch, 3, 3) in SE(2)
    pos = g[..., :2, 2]
    heading = np.unwrap(np.arctan2(g[..., 1, 0], g[..., 0, 0]), axis=0)
    w_ex, v_ex, turn = exact(xi0, t)
    E = 0.5 * np.einsum("...i,ij,...j->...", sol.omega, K, sol.omega)
    Rm = g[..., :2, :2]
    se2_defect = max(float(np.max(np.abs(np.swapaxes(Rm, -1, -2) @ Rm - np.eye(2)))),
                     float(np.max(np.abs(g[..., 2, :] - np.array([0.0, 0.0, 1.0])))))
    V = np.sqrt(2 * E[0] / M)

    print("Chaplygin sleigh on se(2) built from structure constants")
    print(f"  max |C - ls.se(2).C| = {dC:.0e}, max |R - ls.se(2).R| = {dR:.0e}; D = annihilator of (0, 0, 1): "
          f"dim {D.dim}, subalgebra: {D.is_subalgebra()} (nonholonomic); model: {sol.stats['form']} form")
    print(f"  {xi0.shape[0]} sleighs, t in [0, {t_end:g}]: max |omega(t_end)| = {np.max(np.abs(om[-1])):.1e}; "
          f"v(t_end) - V = {np.array2string(v[-1] - V, precision=1)}")
    print(f"  max |omega - exact| = {np.max(np.abs(om - w_ex)):.1e}, max |v - exact| = {np.max(np.abs(v - v_ex)):.1e}; "
          f"energy drift {np.max(np.abs(E - E[0])):.1e}; |v_y| = {np.max(np.abs(vy)):.0e}")
    print(f"  heading turned: integrated {np.array2string(heading[-1] - heading[0], precision=6)}")
    print(f"                  limit (exact) {np.array2string(turn, precision=6)}")
    print(f"  SE(2) structure defect max(|R^T R - I|, |last row - (0,0,1)|) = {se2_defect:.1e}; "
          f"{sol.stats['steps']} steps, {sol.stats['wall_time']:.2f} s")

    fig = Figure(figsize=(13, 9), layout="constrained")
    axs = fig.subplots(2, 2)
    ax = axs[0, 0]
    show = t <= 8.0                                              # the turning phase; then straight lines
    bars = [int(np.argmin(np.abs(t - tb))) for tb in np.linspace(0.0, min(4.0, t_end), 6)]
    for j in range(xi0.shape[0]):
        c = f"C{j}"
        ax.plot(pos[show, j, 0], pos[show, j, 1], color=c, lw=1.4,
                label=rf"$\omega_0$ = {xi0[j, 0]:g}, $v_0$ = {xi0[j, 1]:g}")
        com = pos[:, j] + A_OFF * np.stack([np.cos(heading[:, j]), np.sin(heading[:, j])], axis=-1)
        ax.plot(com[show, 0], com[show, 1], color=c, lw=0.6, ls=":")
        for k in bars:                                           # the blade P -> centre of mass
            ax.plot([pos[k, j, 0], com[k, 0]], [pos[k, j, 1], com[k, 1]], color=c, lw=2.5, solid_capstyle="round")
            ax.plot(*com[k], "o", color=c, ms=3)
    ax.set_aspect("equal")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_title("paths of the contact point for t ≤ 8 (dotted: centre of mass; bars: P → centre of mass, "
                 "t = 0, 0.8, ..., 4)", fontsize=9)
    ax.legend(fontsize=7, loc="best")

    ax = axs[0, 1]
    for j in range(xi0.shape[0]):
        ax.plot(t, om[:, j], color=f"C{j}", lw=1.4)
        ax.plot(t, v[:, j], color=f"C{j}", lw=1.4, ls="--")
        ax.plot(t[::40], w_ex[::40, j], "k.", ms=2.5)
        ax.plot(t[::40], v_ex[::40, j], "k.", ms=2.5)
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.set_xlim(0.0, min(t_end, 12.0))
    ax.set_xlabel("t")
    ax.set_title(r"$\omega(t)$ (solid) $\to 0$, $v(t)$ (dashed) $\to V$; dots: tanh/sech law", fontsize=10)

    ax = axs[1, 0]
    floor = 1e-17
    for j in range(xi0.shape[0]):
        ax.semilogy(t, np.maximum(np.abs(om[:, j]), floor), color=f"C{j}", lw=1.2)
        ax.semilogy(t, np.maximum(np.abs(heading[:, j] - heading[0, j] - turn[j]), floor), color=f"C{j}", ls="--",
                    lw=0.9)
    ax.set_xlabel("t")
    ax.set_title(r"$|\omega(t)|$ (solid) and distance of the heading from its limit (dashed)", fontsize=10)

    ax = axs[1, 1]
    ax.semilogy(t[1:], np.maximum(np.max(np.abs(om - w_ex), axis=1)[1:], floor),
                label=r"$|\omega - \omega_{\rm exact}|$")
    ax.semilogy(t[1:], np.maximum(np.max(np.abs(v - v_ex), axis=1)[1:], floor), label=r"$|v - v_{\rm exact}|$")
    ax.semilogy(t[1:], np.maximum(np.max(np.abs(E - E[0]), axis=1)[1:], floor), label="energy drift", lw=0.8)
    Rt = np.swapaxes(Rm, -1, -2) @ Rm - np.eye(2)
    ax.semilogy(t[1:], np.maximum(np.max(np.abs(Rt), axis=(1, 2, 3))[1:], floor), label=r"$|R^TR - I|$", lw=0.8)
    ax.set_xlabel("t")
    ax.set_title(f"RKMK (rkmk45, rtol = {rtol:g}) on SE(2), worst of the batch", fontsize=10)
    ax.legend(fontsize=8)
    fig.suptitle(f"Chaplygin sleigh (m = {M:g}, a = {A_OFF:g}, I_C = {I_C:g}): "
                 "every sleigh ends in straight-line motion, centre of mass first")
    return save_figure(fig, out_dir, NAME)


if __name__ == "__main__":
    command_line(main, __doc__)
