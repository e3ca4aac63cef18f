"""One Runge–Kutta–Munthe-Kaas stepper for every tableau and chart, over a batch.

The state is ``(xi, G)``: reduced coordinates ``xi`` in the constraint subspace D (a vector space,
advanced by the classical RK formulas — the abelian factor of the product group) and a group part
``G`` advanced by RKMK in a chart ``phi``:

* ``"g"``: the attitude ``g`` (..., m, m), ``g1 = g0 phi(Theta)``; the vertical is read off it,
  ``Gamma = g^T gamma`` with ``gamma = g0 Gamma0`` constant (never integrated twice);
* ``"gamma"``: only the vertical Gamma (..., n), ``Gamma1 = phi(-Theta) Gamma0`` (exact on the sphere);
* ``"none"``: no group part (V = 0 and neither Gamma nor g asked for): plain RK on xi.

Stage i (``h`` common to the batch):
``Xi_i = xi + h sum_j a_ij L_j``, ``Theta_i = h sum_j a_ij K_j``, ``Gamma_i = phi(-Theta_i) Gamma``,
``L_i = f(Xi_i, Gamma_i)``, ``K_i = dphi^{-1}_{-Theta_i}(Omega(Xi_i))``; then
``xi1 = xi + h sum b_j L_j`` and ``Theta = h sum b_j K_j``. Both stage sums come from one
matrix–vector product over a stacked buffer, so a stage costs a fixed handful of numpy calls
whatever the batch size.
"""

from __future__ import annotations

import numpy as np

from .charts import Chart
from .tableaux import ButcherTableau

__all__ = ["RKMKStepper"]


class RKMKStepper:
    """Advance ``(xi, G)`` by one RKMK step for a batch of ``B`` trajectories.

    Parameters
    ----------
    model : mechanics Model
        Provides ``k``, ``n``, ``has_gamma``, ``xi_dot(xi, Gamma)``, ``omega_matrix(xi)``.
    tableau : ButcherTableau
    chart : Chart or None
        None when ``mode == "none"``.
    mode : {"g", "gamma", "none"}
    batch : int
        Number of trajectories B (flattened batch axes).
    """

    def __init__(self, model, tableau: ButcherTableau, chart: Chart | None, mode: str, batch: int) -> None:
        self.model = model
        self.tab = tableau
        self.chart = chart
        self.mode = mode
        self.B = batch
        self.k = model.k
        self.m = model.n if mode != "none" else 0
        self.nfev = 0
        s = tableau.A.shape[0]
        self.err_weights = [np.asarray(e) for e in tableau.error_weights]
        # Error estimators that use the derivative at the new point need one more evaluation.
        self.s_eval = max([s] + [len(e) for e in self.err_weights])
        self.nk = batch * self.k
        self.ng = batch * self.m * self.m
        self.Z = np.zeros((self.s_eval, self.nk + self.ng))
        self.A_rows = tableau.a_rows
        self.b = np.ascontiguousarray(tableau.b)
        # FSAL: the last stage sits at the new point (its A row is b), so it is the next stage 0.
        self.fsal = s > 1 and bool(np.allclose(tableau.A[-1], tableau.b)) and tableau.c[-1] == 1.0
        self._first = None  # (L, Omega) at the current point: stage 0 of the next step
        self._new = None  # the same at the point the last step reached, if it came for free

    def reset(self) -> None:
        """Forget cached stage data (call when the state is changed from outside)."""
        self._first = None
        self._new = None

    # ------------------------------------------------------------------ stages
    def _eval(self, i: int, Xi: np.ndarray, Theta: np.ndarray | None, Gam0: np.ndarray | None):
        """Evaluate stage i at (Xi, Theta); store L_i and K_i in row i of the buffer.

        Returns the raw pair (L_i, Omega(Xi)), which is stage-0 data when Xi, Theta is a step's end.
        """
        Gam = Gam0
        if Theta is not None and Gam0 is not None:
            Gam = self.chart.phi_vec(-Theta, Gam0)
        L = self.model.xi_dot(Xi, Gam)
        self.nfev += 1
        row = self.Z[i]
        row[: self.nk] = L.reshape(-1)
        Om = None
        if self.mode != "none":
            Om = self.model.omega_matrix(Xi)
            K = Om if Theta is None else self.chart.dinv(Theta, Om)
            row[self.nk:] = K.reshape(-1)
        return L, Om

    def gamma_of(self, G: np.ndarray | None, gamma: np.ndarray | None) -> np.ndarray | None:
        """The vertical in the body frame at the current point (None when the model has none)."""
        if not self.model.has_gamma or G is None:
            return None
        if self.mode == "g":
            return np.einsum("bji,bj->bi", G, gamma)  # Gamma = g^T gamma
        return G

    # ------------------------------------------------------------------ the step
    def step(self, h: float, xi: np.ndarray, G: np.ndarray | None, gamma: np.ndarray | None,
             want_error: bool = False):
        """One step of size h (negative for backward integration); the state is not modified.

        Parameters
        ----------
        h : float
        xi : (B, k)
        G : (B, m, m) attitude, (B, n) vertical, or None (see ``mode``)
        gamma : (B, n) or None
            The vertical in space (mode "g" with a vertical only).
        want_error : bool
            Also return the embedded error estimates.

        Returns
        -------
        xi1 : (B, k)
        G1 : like G
        Theta1 : (B, m, m) or None
            The chart coordinates of the group increment.
        errs : list of (err_xi (B, k), err_Theta (B, m, m) or None)
            One pair per error estimator of the tableau (DOP853 has two); empty unless asked.
        """
        B, k, m, nk = self.B, self.k, self.m, self.nk
        Z = self.Z
        Gam0 = self.gamma_of(G, gamma)
        if self._first is None:
            self._first = self._eval(0, xi, None, Gam0)
        else:
            L0, Om0 = self._first
            Z[0, :nk] = L0.reshape(-1)
            if Om0 is not None:
                Z[0, nk:] = Om0.reshape(-1)
        last = self._first
        s = len(self.A_rows)
        group = self.mode != "none"
        Theta = None
        for i in range(1, s):
            z = self.A_rows[i] @ Z[:i]
            Xi = xi + h * z[:nk].reshape(B, k)
            if group:
                Theta = h * z[nk:].reshape(B, m, m)
            last = self._eval(i, Xi, Theta, Gam0)
        if self.fsal:
            xi1, Theta1 = Xi, Theta
        else:
            z = self.b @ Z[:s]
            xi1 = xi + h * z[:nk].reshape(B, k)
            Theta1 = h * z[nk:].reshape(B, m, m) if group else None
        self._new = last if self.fsal else None
        if self.s_eval > s:
            self._new = self._eval(s, xi1, Theta1, Gam0)
        errs = [self._combine(e, h) for e in self.err_weights] if want_error else []
        if not group:
            G1 = None
        elif self.mode == "g":
            G1 = G @ self.chart.phi(Theta1)
        else:
            G1 = self.chart.phi_vec(-Theta1, G)
        return xi1, G1, Theta1, errs

    def accept(self) -> None:
        """The last step was accepted: what it computed at the new point becomes stage 0."""
        self._first = self._new
        self._new = None

    def _combine(self, e: np.ndarray, h: float):
        z = e @ self.Z[: len(e)]
        ex = h * z[: self.nk].reshape(self.B, self.k)
        eg = h * z[self.nk:].reshape(self.B, self.m, self.m) if self.mode != "none" else None
        return ex, eg
