"""Independent references for the integrator tests: scipy's DOP853 on the embedded ODE (omega, vec g)."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp


def embedded_reference(system, omega0, T, t_eval, Gamma0=None, rtol=1e-13, atol=1e-15):
    """``(omega (M, d), g (M, n, n))`` at ``t_eval`` from ``solve_ivp(method="DOP853")`` on the embedded ODE.

    The state is the coordinates of Omega and the n×n entries of g (g' = g Omega, Gamma = g^T gamma); only
    the model's field is shared with the library, none of its integrators, charts or group maps.
    """
    model = system.model(gamma=True if Gamma0 is not None else None)
    n = model.n
    gamma = None if Gamma0 is None else np.asarray(Gamma0, float)

    def rhs(t, y):
        x = y[:-n * n]
        g = y[-n * n:].reshape(n, n)
        xi = model.xi_from_coords(x[None])
        G = None if gamma is None else (g.T @ gamma)[None]
        dx = model.omega_coords(model.xi_dot(xi, G))[0]
        return np.concatenate([dx, (g @ model.omega_matrix(xi)[0]).ravel()])

    y0 = np.concatenate([np.asarray(omega0, float), np.eye(n).ravel()])
    r = solve_ivp(rhs, (0.0, T), y0, method="DOP853", rtol=rtol, atol=atol, t_eval=t_eval)
    return r.y[:-n * n].T, r.y[-n * n:].T.reshape(-1, n, n)
