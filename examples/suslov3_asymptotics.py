"""Suslov's problem in SO(3) (V = 0, a = e3 not an eigenvector of J): motion toward w_- and w_+.

The constraint ``w_3 = 0`` keeps the angular velocity in a plane; the energy ``<J w, w>/2`` makes it run
along an ellipse there, and since ``e3`` is not an eigenvector of J there is no invariant measure:
every trajectory leaves the point ``w_-`` (as ``t -> -inf``) and tends to the opposite point ``w_+``
(as ``t -> +inf``) at the rate ``exp(-kappa |t|)`` — a tanh law along the ellipse
(``ls.analytic.Suslov3Free``; the points from ``ls.analytic.suslov3_asymptotic_points``).

A batch of initial conditions around one energy ellipse is integrated forward and backward in one
vectorised call each (RKMK, adaptive DOP853 tableau) and compared with the explicit solution.

Run: ``python examples/suslov3_asymptotics.py [--out DIR] [--quick]``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _common import command_line, save_figure  # examples/_common.py
from matplotlib.figure import Figure

import liesuslov as ls

NAME = "suslov3_asymptotics.png"

J = np.array([[2.0, 0.0, 0.3],
              [0.0, 3.0, 0.4],
              [0.3, 0.4, 4.0]])   # inertia acting on w = (-Omega_23, Omega_13, -Omega_12); J13, J23 != 0
H = 16.0                           # energy of every trajectory (the rate kappa grows like sqrt(H))


def w_of(x: np.ndarray) -> np.ndarray:
    """so(3) coordinates ``(Omega_12, Omega_13, Omega_23)`` to ``w = (-Omega_23, Omega_13, -Omega_12)``."""
    return np.stack([-x[..., 2], x[..., 1], -x[..., 0]], axis=-1)


def x_of(w: np.ndarray) -> np.ndarray:
    """The inverse of :func:`w_of`."""
    return np.stack([-w[..., 2], w[..., 1], -w[..., 0]], axis=-1)


def _ellipse_map(h: float) -> np.ndarray:
    """``C = sqrt(2h) J_D^{-1/2}``: maps the unit circle onto the energy ellipse in the plane w_3 = 0."""
    lam, V = np.linalg.eigh(J[:2, :2])
    return np.sqrt(2.0 * h) * (V @ np.diag(lam ** -0.5) @ V.T)


def ellipse(h: float, angles: np.ndarray) -> np.ndarray:
    """Points ``w = (w1, w2, 0)`` with ``<J w, w>/2 = h`` at the given angles (of ``C^{-1} w``)."""
    e = np.stack([np.cos(angles), np.sin(angles)], axis=-1)
    w = e @ _ellipse_map(h).T
    return np.concatenate([w, np.zeros(w.shape[:-1] + (1,))], axis=-1)


def main(out_dir=None, quick: bool = False) -> Path:
    """Integrate the batch both ways, print the checks, save the figure; return its path."""
    t_end, npts, rtol = (10.0, 200, 1e-8) if quick else (45.0, 1500, 1e-12)
    # Quick runs are a few hundred steps: the numpy stepper, so that they never wait for the one-off
    # compilation of the optional numba kernel (backend="auto" uses it when numba is installed).
    backend = "numpy" if quick else "auto"
    case = ls.cases.suslov3(J)
    w_plus, w_minus = ls.analytic.suslov3_asymptotic_points(J, H)
    b = J[:2, 2]
    e_plus = np.linalg.solve(_ellipse_map(H), w_plus[:2])
    angles = np.arctan2(e_plus[1], e_plus[0]) + np.linspace(0.0, 2 * np.pi, 12, endpoint=False) + 0.13
    w0 = ellipse(H, angles)
    exact = ls.analytic.Suslov3Free(w0, J)

    t_f = np.linspace(0.0, t_end, npts)
    t_b = -t_f
    opts = dict(method="rkmk853", rtol=rtol, atol=rtol * 1e-2, backend=backend)
    fwd = ls.integrate(case.system, x_of(w0), (0.0, t_end), t_eval=t_f, **opts)
    bwd = ls.integrate(case.system, x_of(w0), (0.0, -t_end), t_eval=t_b, **opts)
    wf, wb = w_of(fwd.omega), w_of(bwd.omega)
    err = max(np.max(np.abs(wf - exact.omega(t_f))), np.max(np.abs(wb - exact.omega(t_b))))
    E = case.evaluate(np.concatenate([fwd.omega, bwd.omega]))["energy"]
    drift = float(np.max(np.abs(E - H)))
    constraint = float(np.max(np.abs(np.concatenate([fwd.omega, bwd.omega])[..., 0])))
    d_plus = np.linalg.norm(wf - w_plus, axis=-1)     # (N, batch)
    d_minus = np.linalg.norm(wb - w_minus, axis=-1)
    kappa = float(exact.rate[0])
    # fitted rate: slope of log distance over the second half (before the rounding floor)
    k = 0
    sel = (t_f > 0.3 * t_end) & (d_plus[:, k] > 1e-11)
    rate_f = -np.polyfit(t_f[sel], np.log(d_plus[sel, k]), 1)[0]
    sel = (t_f > 0.3 * t_end) & (d_minus[:, k] > 1e-11)
    rate_b = -np.polyfit(t_f[sel], np.log(d_minus[sel, k]), 1)[0]

    print(f"Suslov's problem, SO(3), V = 0, J = {J.tolist()} (a = e3 not an eigenvector)")
    print(f"  energy h = {H}: w_+ = {np.array2string(w_plus, precision=6)}, w_- = -w_+ ; rate kappa = {kappa:.8f}")
    print(f"  {w0.shape[0]} trajectories: max |w(+{t_end:g}) - w_+| = {np.max(d_plus[-1]):.1e}, "
          f"max |w(-{t_end:g}) - w_-| = {np.max(d_minus[-1]):.1e}")
    print(f"  decay rate fitted on trajectory 0: forward {rate_f:.6f}, backward {rate_b:.6f} (analytic {kappa:.6f})")
    print(f"  max |w - w_exact| = {err:.1e}; energy drift {drift:.1e}; constraint |w_3| = {constraint:.0e}; "
          f"steps {fwd.stats['steps']} + {bwd.stats['steps']}, {fwd.stats['wall_time'] + bwd.stats['wall_time']:.2f} s")

    fig = Figure(figsize=(13, 9), layout="constrained")
    axs = fig.subplots(2, 2)
    ax = axs[0, 0]
    ring = ellipse(H, np.linspace(0, 2 * np.pi, 300))
    ax.plot(ring[:, 0], ring[:, 1], color="0.6", lw=1.5, label="energy ellipse")
    s = np.linspace(-1.3, 1.3, 2) * np.linalg.norm(w_plus)
    nb = np.array([b[1], -b[0]]) / np.linalg.norm(b)            # the line <b, w> = 0 (fixed points)
    ax.plot(s * nb[0], s * nb[1], color="0.5", ls=":", lw=0.8, label=r"$\langle b, w\rangle = 0$ (fixed points)")
    wq = ellipse(H, np.linspace(0, 2 * np.pi, 40, endpoint=False))[:, :2]
    JD = J[:2, :2]
    dw = (wq @ b)[:, None] / np.linalg.det(JD) * (wq @ JD) @ np.array([[0.0, 1.0], [-1.0, 0.0]])  # R J_D w
    ax.quiver(wq[:, 0], wq[:, 1], dw[:, 0], dw[:, 1], color="C0", angles="xy", scale_units="xy",
              scale=np.max(np.linalg.norm(dw, axis=-1)) / 0.9, width=0.004, label=r"$\dot w$ (the flow)")
    ax.plot(w0[:, 0], w0[:, 1], "ko", ms=3.5, label="initial points")
    ax.plot(*w_plus[:2], "*", color="C0", ms=16, mec="k", label=r"$w_+$ (t → +∞)")
    ax.plot(*w_minus[:2], "*", color="C3", ms=16, mec="k", label=r"$w_-$ (t → −∞)")
    ax.set_aspect("equal")
    ax.set_xlabel(r"$w_1$")
    ax.set_ylabel(r"$w_2$")
    ax.set_title("the constraint plane w₃ = 0: the flow on the energy ellipse", fontsize=10)
    ax.legend(fontsize=7, loc="center")

    ax = axs[0, 1]
    Cinv = np.linalg.inv(_ellipse_map(H))
    tt = np.concatenate([t_b[::-1], t_f[1:]])
    ww = np.concatenate([wb[::-1], wf[1:]])
    wa = exact.omega(tt)

    def angle(w):                                               # angle on the ellipse, 0 at w_+, ±pi at w_-
        e = w[..., :2] @ Cinv.T
        return np.angle((e[..., 0] + 1j * e[..., 1]) * np.exp(-1j * np.arctan2(e_plus[1], e_plus[0])))
    psi, psi_a = angle(ww), angle(wa)
    for j in range(w0.shape[0]):
        ax.plot(tt, psi[:, j], color=f"C{j % 10}", lw=1.4)
        ax.plot(tt[::15], psi_a[::15, j], "k.", ms=2.5, label="explicit solution (tanh law)" if j == 0 else None)
    ax.set_yticks([-np.pi, -np.pi / 2, 0, np.pi / 2, np.pi], [r"$-\pi$ (w₋)", r"$-\pi/2$", r"0 (w₊)", r"$\pi/2$",
                                                             r"$\pi$ (w₋)"])
    ax.set_xlabel("t")
    ax.set_ylabel("angle on the ellipse from w₊")
    ax.set_title(f"{w0.shape[0]} trajectories (one batch, forward and backward): w₋ → w₊", fontsize=10)
    ax.legend(fontsize=8, loc="upper right")

    ax = axs[1, 0]
    floor = 1e-17
    for j in range(w0.shape[0]):
        ax.semilogy(t_f, np.maximum(d_plus[:, j], floor), color="C0", lw=0.8,
                    label=r"$|w(t) - w_+|$, t > 0" if j == 0 else None)
        ax.semilogy(t_f, np.maximum(d_minus[:, j], floor), color="C3", lw=0.8, ls="--",
                    label=r"$|w(-t) - w_-|$" if j == 0 else None)
    ax.semilogy(t_f, 2 * np.linalg.norm(w_plus) * np.exp(-kappa * t_f), "k:", lw=1.2,
                label=rf"$\propto e^{{-\kappa t}}$, $\kappa$ = {kappa:.4f}")
    ax.set_ylim(1e-16, 10)
    ax.set_xlabel("|t|")
    ax.set_title(f"exponential approach: fitted rate {rate_f:.4f} (forward), {rate_b:.4f} (backward)", fontsize=10)
    ax.legend(fontsize=8)

    ax = axs[1, 1]
    ef = np.max(np.linalg.norm(wf - exact.omega(t_f), axis=-1), axis=-1)
    eb = np.max(np.linalg.norm(wb - exact.omega(t_b), axis=-1), axis=-1)
    Ef = np.max(np.abs(E[: npts] - H), axis=-1)
    ax.semilogy(t_f[1:], np.maximum(ef[1:], floor), label="|w - w_exact|, forward (worst of batch)")
    ax.semilogy(t_f[1:], np.maximum(eb[1:], floor), label="|w - w_exact|, backward")
    ax.semilogy(t_f[1:], np.maximum(Ef[1:], floor), label="energy drift, forward", lw=0.8)
    ax.set_xlabel("|t|")
    ax.set_title(f"RKMK (rkmk853, rtol = {rtol:g}) against the explicit solution", fontsize=10)
    ax.legend(fontsize=8)
    fig.suptitle("Suslov's problem (n = 3, V = 0): asymptotic motion on the energy ellipse")
    return save_figure(fig, out_dir, NAME)


if __name__ == "__main__":
    command_line(main, __doc__)
