"""The free rigid body's reconstruction phase against Montgomery's formula (1991).

The Euler top ``J = diag(1, 2, 3)`` (no constraint, no potential) with ``|m| = 1``: for momenta from
near the axis of the largest moment to near the axis of the smallest, ``ls.reconstruction_phase`` finds
the period of ``M(t)`` (first return, refined on the continuous extension) and the monodromy
``R = g(0)^-1 g(T)``, a rotation about ``M0`` by the angle ``Delta``. Montgomery's formula in our
conventions (``g^-1 g' = Omega``, body frame; derived in ``docs/reconstruction.md``):

    Delta = 2 E T / |m| - Lambda   (mod 2 pi),

``Lambda`` the solid angle on the left of the closed curve ``M/|M|``. The figure shows the measured
angle with the closed form (``ls.analytic.EulerTop``: ``T = 4 K(k) / lambda`` and ``Lambda`` by the
trapezoidal rule on the elliptic-function solution), the dynamic and geometric parts separately, and the
errors of the period and of the angle.

Run: ``python examples/montgomery_phase.py [--out DIR] [--quick]``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _common import command_line, save_figure  # examples/_common.py
from matplotlib.figure import Figure

import liesuslov as ls
from liesuslov.analytic.euler_top import EulerTop

NAME = "montgomery_phase.png"
J = np.array([1.0, 2.0, 3.0])


def wrap(a):
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


def main(out_dir=None, quick: bool = False) -> Path:
    # M0 = (sin a, 0, cos a): a in (0, a_sep) circulates about e3, a in (a_sep, pi/2) about e1
    a_sep = np.arctan(np.sqrt((1 / J[1] - 1 / J[2]) / (1 / J[0] - 1 / J[1])))
    K = 4 if quick else 14
    # a --quick run (the tests) never waits for the one-off compilation of the optional numba kernel
    backend = "numpy" if quick else "auto"
    a = np.concatenate([np.linspace(0.1, a_sep - 0.05, K), np.linspace(a_sep + 0.05, np.pi / 2 - 0.05, K)])
    M0 = np.stack([np.sin(a), np.zeros_like(a), np.cos(a)], axis=-1)
    w0 = M0 / J
    x0 = np.stack([-w0[:, 2], w0[:, 1], -w0[:, 0]], axis=-1)      # so(3) coordinates (-w3, w2, -w1)
    system = ls.SuslovSystem(ls.Inertia.from_principal_moments(J), constraints=ls.Subspace(ls.so(3), np.eye(3)))
    ph = ls.reconstruction_phase(system, x0, backend=backend)
    top = EulerTop(J, w0)
    dyn, geo = top.dynamic_phase(), top.geometric_phase()
    err_T = np.abs(ph.period - top.period) / top.period
    err_angle = np.abs(wrap(ph.angle - (dyn - geo)))
    print(f"{a.size} momenta on |m| = 1: max relative period error against 4K(k)/lambda {err_T.max():.2e}")
    err_dyn, err_geo = np.max(np.abs(ph.dynamic_phase - dyn)), np.max(np.abs(ph.geometric_phase - geo))
    print(f"max |angle - (2ET/|m| - Lambda)| (mod 2 pi) {err_angle.max():.2e}; dynamic part error "
          f"{err_dyn:.2e}, geometric part error {err_geo:.2e}")
    E = top.energy
    fig = Figure(figsize=(12, 4.2), layout="constrained")
    ax = fig.add_subplot(1, 3, 1)
    ax.plot(E, ph.angle, "o", label="angle of R about M₀ (integrated)")
    ax.plot(E, wrap(dyn - geo), "-", lw=0.8, label="2ET/|m| − Λ (closed form)")
    ax.axvline(0.5 / J[1], color="gray", ls=":", lw=0.8)
    ax.set_xlabel("energy E (|m| = 1)")
    ax.set_ylabel("rotation angle (rad)")
    ax.legend(fontsize=8)
    ax.set_title("Montgomery's phase")
    ax = fig.add_subplot(1, 3, 2)
    ax.plot(E, ph.dynamic_phase, "o", label="dynamic 2ET/|m|")
    ax.plot(E, ph.geometric_phase, "s", label="geometric Λ (solid angle)")
    ax.plot(E, dyn, "-", lw=0.8, color="k", label="closed forms")
    ax.plot(E, geo, "-", lw=0.8, color="k")
    ax.axvline(0.5 / J[1], color="gray", ls=":", lw=0.8)
    ax.set_xlabel("energy E")
    ax.legend(fontsize=8)
    ax.set_title("the two parts")
    ax = fig.add_subplot(1, 3, 3)
    ax.semilogy(E, np.maximum(err_T, 1e-17), "o", label="|T − 4K(k)/λ| / T")
    ax.semilogy(E, np.maximum(err_angle, 1e-17), "s", label="|angle − (2ET/|m| − Λ)|")
    ax.set_xlabel("energy E")
    ax.legend(fontsize=8)
    ax.set_title("errors (rkmk853, rtol 1e-10)")
    return save_figure(fig, out_dir, NAME)


if __name__ == "__main__":
    command_line(main, __doc__)
