"""Global error at equal rtol: liesuslov's adaptive methods against scipy's on the embedded ODE.

The table "What the tolerance means" of docs/numerics.md, reproduced::

    python benchmarks/accuracy_vs_scipy.py            # numpy solver (the docs' table)
    python benchmarks/accuracy_vs_scipy.py numba

Two scenes with reconstruction, t in [0, 20], atol = 1e-2 rtol: the free body I = (1, 2, 3) and the
Klebsh–Tisserand body in SO(4) (I = (1, 2, 3, 4), B = (4, 3, 2, 1)). scipy integrates the embedded ODE
``xi' = f(xi, g^T gamma)`` (the reference multiplier form ``SuslovSystem.rhs``, in the coordinates xi of D's
orthonormal basis), ``g' = g hat(xi B)``; the reference is scipy's DOP853 at rtol 1e-13, atol 1e-15. The error is
the largest entry
of ``|g(20) - g_ref(20)|`` and ``|Omega(20) - Omega_ref(20)|``; nfev counts field evaluations.
"""

from __future__ import annotations

import sys

import numpy as np
from scipy.integrate import solve_ivp

import liesuslov as ls

T = 20.0
PAIRS = (("rkmk45", "RK45"), ("rkmk853", "DOP853"))
RTOLS = (1e-6, 1e-8, 1e-10)


def scenes():
    """(label, system, Omega0, Gamma0)."""
    free = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0])), constraints="none")
    yield "free body I=(1,2,3), with g", free, free.algebra.hat([0.3, 1.0, 0.4]), None
    kt = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0, 4.0])),
                         potential=ls.QuadraticPotential([4.0, 3.0, 2.0, 1.0]))
    Omega0 = np.zeros((4, 4))
    Omega0[:3, 3] = [0.1, 0.2, 0.3]
    Omega0[3, :3] = -Omega0[:3, 3]
    yield "Klebsh–Tisserand SO(4), with g", kt, Omega0, np.array([0.0, 0.0, 0.6, 0.8])


def embedded(system, Gamma0):
    """The field of the embedded ODE y = (xi, vec g), with g(0) = I so that gamma = Gamma0."""
    n = system.n
    hat, basis = system.algebra.hat, system.constraints.basis

    def f(t, y):
        x, g = y[:-n * n] @ basis, y[-n * n:].reshape(n, n)
        xdot, _ = system.rhs(x, None if Gamma0 is None else g.T @ Gamma0)
        return np.concatenate([xdot @ basis.T, (g @ hat(x)).ravel()])
    return f


def error(Omega, g, ref, system):
    n = system.n
    Omega_ref = system.algebra.hat(ref[:-n * n] @ system.constraints.basis)
    return max(float(np.max(np.abs(g - ref[-n * n:].reshape(n, n)))), float(np.max(np.abs(Omega - Omega_ref))))


def main(backend: str = "numpy") -> None:
    print(f"| scene | method vs scipy | rtol | liesuslov error | nfev | scipy error | nfev | ratio |   ({backend})")
    print("|---|---|---|---|---|---|---|---|")
    for label, system, Omega0, Gamma0 in scenes():
        n = system.n
        f = embedded(system, Gamma0)
        y0 = np.concatenate([system.coordinates(Omega0) @ system.constraints.basis.T, np.eye(n).ravel()])
        ref = solve_ivp(f, (0.0, T), y0, method="DOP853", rtol=1e-13, atol=1e-15).y[:, -1]
        for meth, smeth in PAIRS:
            for rtol in RTOLS:
                sol = ls.integrate(system, Omega0, (0.0, T), Gamma0=Gamma0, reconstruct=True, method=meth, rtol=rtol,
                                   atol=1e-2 * rtol, t_eval=[T], backend=backend)
                err = error(sol.Omega[-1], sol.g[-1], ref, system)
                sc = solve_ivp(f, (0.0, T), y0, method=smeth, rtol=rtol, atol=1e-2 * rtol)
                y = sc.y[:, -1]
                serr = error(system.algebra.hat(y[:-n * n] @ system.constraints.basis), y[-n * n:].reshape(n, n), ref,
                             system)
                print(f"| {label} | `{meth}` / {smeth} | {rtol:.0e} | {err:.1e} | {sol.stats['nfev']} | {serr:.1e} | "
                      f"{sc.nfev} | {err / serr:.2f} |", flush=True)
                label = ""


if __name__ == "__main__":
    main(*sys.argv[1:2])
