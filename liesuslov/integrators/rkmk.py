"""The numpy RKMK stepper: one trajectory's step on a :class:`~.plan.StagePlan`, readable, the reference.

The state is ``(xi, G)`` (see :mod:`.problem`). Stage i (plan numbering, ``h`` the step):

    Xi_i = xi + h sum_j A[i, j] L_j,      Theta_i = h sum_j A[i, j] K_j,      Gamma_i = phi(-Theta_i) Gamma,
    L_i = f(Xi_i, Gamma_i),               K_i = dphi^{-1}_{-Theta_i}(Omega(Xi_i)),

then ``xi1 = xi + h sum_j b_j L_j``, ``Theta1 = h sum_j b_j K_j``, ``g1 = g phi(Theta1)`` or
``Gamma1 = phi(-Theta1) Gamma``; the embedded estimates are ``h sum_j err_j (L_j, K_j)`` and the continuous
extension ``xi(theta) = xi + h sum_j b_j(theta) L_j``, ``Theta(theta) = h sum_j b_j(theta) K_j``.

Layout: row 0 of one buffer ``Z`` holds ``(xi, 0)``, row ``1 + j`` holds ``(L_j, K_j)``; a stage's
argument is one product of the coefficient row ``(1, h A[i, :i])`` with the rows above it. The chart's
kernel (:meth:`~.charts.Chart.kernel`) fixes how an algebra element is stored in a row — rotation vectors
for so(3), the pair (p, q) for so(4), coordinates for small so(n), r×r coordinates in a per-step basis for
Fedorov–Kozlov models, matrices otherwise — and does the chart's work on it (closed forms where they exist).

The compiled kernel (:mod:`.kernel`) runs the same plan, controller and norm (:mod:`.control`) per
trajectory without Python; this stepper is what the tests compare it against, and what runs user
callables (a custom potential, an event function).
"""

from __future__ import annotations

import math

import numpy as np

from . import control
from .charts import Chart, body_vertical, make_chart
from .plan import StagePlan, dense_weights

__all__ = ["RKMKStepper"]


class RKMKStepper:
    """Steps of one method for a batch of ``B`` trajectories sharing one step size (the solver uses B = 1).

    Parameters
    ----------
    model : ModelProtocol
    plan : StagePlan
    chart : Chart, {"exp", "cayley"} or None
        None when ``mode == "none"``.
    mode : {"g", "gamma", "none"}
    batch : int
    kind : str, optional
        Force the chart's kernel ("so3", "so4", "coords", "lowrank", "dense").

    Attributes
    ----------
    nfev : int
        Field evaluations (one batched call counts once), following the plan's new-point rule.
    kernel : str or None
        The chart kernel in use.
    """

    def __init__(self, model, plan: StagePlan, chart: Chart | str | None, mode: str, batch: int = 1,
                 kind: str | None = None, rtol: float = 1e-8, atol: float = 1e-10) -> None:
        self.model, self.plan, self.mode = model, plan, mode
        self.rtol, self.atol = rtol, atol
        self.B = B = int(batch)
        self.k = k = int(model.k)
        self.m = int(model.n) if mode != "none" else 0
        self.nfev = 0
        self._f = model.xi_dot
        self._has_gamma = bool(model.has_gamma) and mode != "none"
        S = plan.S
        if mode != "none":
            if chart is None or isinstance(chart, str):
                chart = make_chart(chart or "exp", self.m, skew=model.algebra.name.startswith("so("),
                                   order=plan.order)
            self.kern = chart.kernel(model, B, S, need_act=self._has_gamma, kind=kind)
            self.kernel = type(self.kern).__name__.strip("_").replace("Kernel", "").lower()
        else:
            self.kern, self.kernel = None, None
        self.chart = chart
        q = self.kern.q if self.kern is not None else 0
        self.nk = nk = B * k
        N = nk + B * q
        self.Z = Z = np.zeros((1 + S, N))
        self._xv = (lambda row: row.reshape(B, k)) if B == 1 else (lambda row: row.reshape(k, B).T)
        self._L = [self._xv(Z[1 + j, :nk]) for j in range(S)]
        self._K = [self.kern.slot(Z[1 + j, nk:]) for j in range(S)] if self.kern is not None else None
        self._zbuf = np.zeros((S, N))  # stage arguments (Xi_i, Theta_i)
        self._C = np.zeros((S, 1 + S))  # coefficient rows (1, h A[i, :i]) for the current h
        self._h = None
        self._first = None  # the field at the current point (stage 0 of the next step)
        self.done = 0  # stages evaluated in the current step

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget the cached field value (the state was changed from outside)."""
        self._first = None

    def vertical(self, G: np.ndarray | None, gamma: np.ndarray | None) -> np.ndarray | None:
        """The body vertical at the current point: ``G`` (mode "gamma"), ``g^T gamma`` (mode "g"), or None."""
        if not self._has_gamma:
            return None
        return G if self.mode == "gamma" else body_vertical(G, gamma)

    def field(self, xi: np.ndarray, G, gamma) -> np.ndarray:
        """The field at the current point (stage 0; evaluated once and kept until the state moves)."""
        if self._first is None:
            self._first = self._f(xi, self.vertical(G, gamma))
            self.nfev += 1
        return self._first

    # ------------------------------------------------------------------ stages
    def _stage(self, i: int) -> bool:
        """Evaluate stage i >= 1 from the rows above it; False when its chart argument is out of the domain."""
        Zi = self._zbuf[i]
        np.matmul(self._C[i, : i + 1], self.Z[: i + 1], out=Zi)
        Xi = self._xv(Zi[: self.nk])
        kern = self.kern
        if kern is None:
            self._L[i][...] = self._f(Xi, None)
            self.nfev += 1
            return True
        flat = Zi[self.nk:]
        t = kern.load(flat)
        self._L[i][...] = self._f(Xi, kern.act(t) if self._has_gamma else None)
        self.nfev += 1
        kern.dinv(t, kern.omega(i, Xi), self._K[i])
        return self._in_domain(flat)

    def _in_domain(self, flat: np.ndarray) -> bool:
        """``|Theta|_F / sqrt 2 < pi`` for the exponential (a bound on the largest rotation angle; the
        exponential's dexp⁻¹ has its first pole at angle 2 pi and the closed forms lose accuracy past pi)."""
        if self.chart.name != "exp":
            return True
        e = self.kern.error(flat).ravel()
        return bool(e @ e < 2.0 * math.pi ** 2)  # NaN: False

    def _combine(self, w: np.ndarray, h: float, base: float = 1.0) -> np.ndarray:
        """``base * row0 + h sum_j w_j row_{1+j}``: (S,) weights -> one row (xi part and chart part)."""
        c = np.empty(1 + self.plan.S)
        c[0] = base
        c[1:] = h * w
        return c @ self.Z

    def trial(self, h: float, xi: np.ndarray, G, gamma) -> tuple:
        """One trial step of size h (negative backward); the state is not modified.

        Returns
        -------
        xi1 : (B, k)
        G1 : like G, or None
        err : (2,) or (B, ...) tuple ``(s5, s3)`` of scaled sums of squares (see :mod:`.control`), or None for
            fixed-step methods
        in_domain : bool
            Every chart argument of the step was inside the chart's domain.
        """
        plan, kern = self.plan, self.kern
        if h != self._h:
            self._C[:] = 0.0
            self._C[:, 0] = 1.0
            self._C[:, 1:] = h * plan.A
            self._h = h
        self.Z[0, : self.nk] = xi.reshape(-1) if self.B == 1 else xi.T.reshape(-1)
        self.Z[0, self.nk:] = 0.0
        if kern is not None:
            kern.begin(G, gamma if self._has_gamma else None, self.mode)
        self._L[0][...] = self.field(xi, G, gamma)
        if kern is not None:
            kern.first(kern.omega(0, xi), self._K[0])
        ok = True
        s = plan.s
        for i in range(1, plan.step_stages):
            ok = self._stage(i) and ok
        self.done = plan.step_stages
        if plan.fsal:  # stage s - 1 sits at the new point: stage s is a copy
            self.Z[1 + s] = self.Z[s]
            self._zbuf[s] = self._zbuf[s - 1]
            self.done = s + 1
            z1 = self._zbuf[s - 1]
        else:
            z1 = self._combine(plan.b, h)
        xi1 = self._xv(z1[: self.nk]).copy()
        G1 = None
        if kern is not None:
            flat1 = z1[self.nk:].copy()
            ok = ok and self._in_domain(flat1)
            t1 = kern.load(flat1)
            G1 = kern.advance(G, t1) if self.mode == "g" else kern.act(t1)
            self._flat1 = flat1
        err = None
        if plan.adaptive:
            err = self._error(h, xi, xi1, G, G1)
        return xi1, G1, err, ok

    def _error(self, h, xi, xi1, G, G1):
        """Scaled sums of squares of the estimates in the state (see :mod:`.control`)."""
        sums = []
        sc = control.scale(xi, xi1, self.rtol, self.atol)
        scG = None if self.kern is None else control.scale(G, G1, self.rtol, self.atol)
        for w in self.plan.err:
            e = self._combine(w, h, base=0.0)
            s = np.sum((self._xv(e[: self.nk]) / sc) ** 2, axis=-1)
            if self.kern is not None:
                E = self.kern.matrix(e[self.nk:])  # (B, m, m): the chart estimate, carried to the state
                eg = np.matmul(G1, E) if self.mode == "g" else np.matmul(E, G1[..., None])[..., 0]
                s = s + np.sum((eg / scG) ** 2, axis=tuple(range(1, eg.ndim)))
            sums.append(s)
        return sums[0], (sums[1] if len(sums) > 1 else sums[0])

    def complete(self) -> bool:
        """Evaluate the stages the continuous extension needs that the trial step did not (after acceptance)."""
        ok = True
        for i in range(self.done, self.plan.S):
            ok = self._stage(i) and ok
        self.done = self.plan.S
        return ok

    def dense(self, theta, xi: np.ndarray, G, h: float):
        """The state at ``t + theta h`` inside the last trial step (after :meth:`complete`).

        Returns ``(xi (B, k), G like G)`` with ``G = g phi(Theta(theta))`` or ``phi(-Theta(theta)) Gamma``.
        """
        z = self._combine(dense_weights(self.plan.dense, float(theta)), h)
        xi_t = self._xv(z[: self.nk]).copy()
        if self.kern is None:
            return xi_t, None
        t = self.kern.load(z[self.nk:].copy())
        return xi_t, (self.kern.advance(G, t) if self.mode == "g" else self.kern.act(t))

    def accept(self) -> None:
        """The last trial step was accepted: stage 0 of the next step reuses stage s if it was evaluated."""
        s = self.plan.s
        self._first = self._L[s].copy() if self.done > s else None
