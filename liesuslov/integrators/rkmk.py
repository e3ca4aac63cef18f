"""The numpy RKMK stepper: trial steps of a batch, each trajectory with its own step size — readable, the reference.

The state of a trajectory is ``(xi, G)`` (see :mod:`.problem`). Stage i (plan numbering, ``h`` the step):

    Xi_i = xi + sum_j (A[i, j] h) L_j,    Theta_i = sum_j (A[i, j] h) K_j,    Gamma_i = phi(-Theta_i) Gamma,
    L_i = f(Xi_i, Gamma_i),               K_i = dphi^{-1}_{-Theta_i}(Omega(Xi_i)),

then ``xi1 = xi + sum_j (b_j h) L_j``, ``Theta1 = sum_j (b_j h) K_j``, ``g1 = g phi(Theta1)`` or
``Gamma1 = phi(-Theta1) Gamma``; the embedded estimates are ``sum_j (err_j h) (L_j, K_j)`` and the
continuous extension ``xi(theta) = xi + sum_j (h b_j(theta)) L_j``, ``Theta(theta) = sum_j (h b_j(theta)) K_j``.

Layout: a trial step of B trajectories keeps one buffer ``Z`` (1 + S, k + q, B): row 0 holds ``(xi, 0)``,
row ``1 + j`` holds ``(L_j, K_j)``, every row component-major — one contiguous (B,) line per component —
so that the per-trajectory coefficient ``A[i, j] h`` (h a (B,) array) broadcasts along the batch and a
stage's argument is an elementwise sum over the rows above it, in a fixed order (j increasing, exact zero
coefficients skipped). The chart's kernel (:meth:`~.charts.Chart.kernel`) fixes what the q numbers of
the chart part are — rotation vectors for so(3), the pair (p, q) for so(4), coordinates for small so(n),
r×r coordinates in a per-step basis for Fedorov–Kozlov models, matrices otherwise — and does the chart's
work on them (closed forms where they exist).

Batch = alone, bitwise: a trajectory's numbers depend on its own state and step only. Every operation is
elementwise along the batch, a reduction along one trajectory's own contiguous numbers, or a stacked
product (``np.matmul`` / ``np.linalg.solve`` on (B, ·, ·) arrays: one product per matrix); nothing is a
BLAS product with the batch as a matrix dimension (its blocking, hence its rounding, changes with B). The
model is called with ``xi`` of shape (B, 1, k) and ``Gamma`` (B, 1, n), C-contiguous: the batch is a
leading axis, so a model that multiplies by a matrix (``xi @ W``) runs one product per trajectory too
(numpy's stacked product; a (B, k) operand would make it one BLAS product over the batch). One
trajectory is a batch of one, on the same code (the so(3)/so(4) kernels hold its numbers as Python
floats: the same IEEE operations, see :mod:`.charts`).

The compiled kernel (:mod:`.kernel`) runs the same plan, controller and norm (:mod:`.control`) per
trajectory without Python; this stepper is what the tests compare it against, and what runs user
callables (a custom potential, an event function).
"""

from __future__ import annotations

import numpy as np

from . import control
from .charts import Chart, body_vertical, domain_bound2, make_chart
from .plan import StagePlan, dense_weights

__all__ = ["RKMKStepper", "Step"]


def _terms(w: np.ndarray, coef: list) -> list[tuple[int, int]]:
    """The nonzero entries of a weight row, in order, as ``(j, c)``: stage j with the coefficient ``coef[c]``
    (appended to ``coef``)."""
    out = []
    for j, x in enumerate(w):
        if x != 0.0:
            out.append((j, len(coef)))
            coef.append(float(x))
    return out


class Step:
    """A trial step of a batch of B trajectories: what the error, the extension and the dense states read.

    Attributes
    ----------
    h : (B,)
        Signed step sizes.
    hc : (T, B)
        The stepper's nonzero coefficients (the plan's A, b, err) times h, for the whole step at once.
    xi, G, gamma : (B, k); (B, m, m), (B, n) or None; (B, n) or None
        The state at the start of the step (and the vertical in space).
    Z : (1 + S, k + q, B)
        The stage buffer (see the module docstring); rows past ``done`` are not evaluated.
    ctx : kernel context
        The chart kernel's per-step data (the vertical at the start, the low-rank basis).
    done : int
        Stages evaluated (the same for every trajectory of the step).
    xi1, G1 : (B, k); like G
        The state at the end of the step.
    ok : (B,) bool
        Every chart argument of the step was inside the chart's domain.
    err : tuple of two (B,) arrays, or None
        ``(s5, s3)``: scaled sums of squares of the estimates (see :mod:`.control`); None for fixed-step methods.
    """

    __slots__ = ("h", "hc", "xi", "G", "gamma", "Z", "ctx", "done", "xi1", "G1", "ok", "err")

    def take(self, rows: np.ndarray) -> Step:
        """The trajectories ``rows`` of this step (indices, possibly repeated), as a step of their own: copies."""
        sub = Step()
        sub.h, sub.hc, sub.Z, sub.done = self.h[rows], self.hc[:, rows], self.Z[:, :, rows], self.done
        sub.xi = self.xi[rows]
        sub.G = None if self.G is None else self.G[rows]
        sub.gamma = None if self.gamma is None else self.gamma[rows]
        sub.ctx = None if self.ctx is None else self.ctx.take(rows)
        sub.xi1 = self.xi1[rows]
        sub.G1 = None if self.G1 is None else self.G1[rows]
        sub.ok = self.ok[rows]
        sub.err = None if self.err is None else tuple(e[rows] for e in self.err)
        return sub


class RKMKStepper:
    """Trial steps of one method for a batch of trajectories, each with its own step size.

    The batch is whatever the arrays given carry (B = 1 included, on the same code). Field evaluations are
    counted by the caller (per trajectory, following the plan's new-point rule): a trial step evaluates
    ``plan.step_stages - 1`` stages besides stage 0 (the caller's ``f0``), :meth:`complete` the remaining
    ``plan.S - step.done``.

    Parameters
    ----------
    model : ModelProtocol
    plan : StagePlan
    chart : Chart, {"exp", "cayley"} or None
        None when ``mode == "none"``.
    mode : {"g", "gamma", "none"}
    kind : str, optional
        Force the chart's kernel ("so3", "so4", "coords", "lowrank", "dense").
    rtol, atol : float
        The tolerances of the error norm.

    Attributes
    ----------
    kernel : str or None
        The chart kernel in use.
    """

    def __init__(self, model, plan: StagePlan, chart: Chart | str | None, mode: str, kind: str | None = None,
                 rtol: float = 1e-8, atol: float = 1e-10) -> None:
        self.model, self.plan, self.mode = model, plan, mode
        self.rtol, self.atol = rtol, atol
        self.k = int(model.k)
        self._f = model.xi_dot
        self._has_gamma = bool(model.has_gamma) and mode != "none"
        if mode != "none":
            if chart is None or isinstance(chart, str):
                chart = make_chart(chart or "exp", int(model.n), skew=model.algebra.name.startswith("so("),
                                   order=plan.order)
            self.kern = chart.kernel(model, plan.S, need_act=self._has_gamma, kind=kind)
            self.kernel = type(self.kern).__name__.strip("_").replace("Kernel", "").lower()
        else:
            self.kern, self.kernel = None, None
        self.chart = chart
        self.q = self.kern.q if self.kern is not None else 0
        S = plan.S
        coef: list[float] = []
        self._A = [_terms(plan.A[i, :i], coef) for i in range(S)]  # stage i's nonzero coefficients
        self._b = _terms(plan.b, coef)
        self._err = [_terms(w, coef) for w in plan.err]
        self._coef = np.array(coef)[:, None]
        self._dense = [j for j in range(S) if np.any(plan.dense[j] != 0.0)]  # stages the extension reads
        self._domain_bound2 = None if chart is None else domain_bound2(chart.name)

    # ------------------------------------------------------------------ the field
    def vertical(self, G: np.ndarray | None, gamma: np.ndarray | None) -> np.ndarray | None:
        """The body vertical the model reads: ``G`` (mode "gamma"), ``g^T gamma`` (mode "g"), or None."""
        if not self._has_gamma:
            return None
        return G if self.mode == "gamma" else body_vertical(G, gamma)

    def _eval(self, X: np.ndarray, Gam: np.ndarray | None) -> np.ndarray:
        """The model at ``X`` (B, 1, k) C-contiguous and ``Gam`` (B, n) or None -> (B, k)."""
        G3 = None if Gam is None else np.ascontiguousarray(Gam).reshape(X.shape[0], 1, -1)
        return np.asarray(self._f(X, G3)).reshape(X.shape[0], self.k)

    def field(self, xi: np.ndarray, G, gamma) -> np.ndarray:
        """The field at the points ``(xi (B, k), G)``: (B, k), one evaluation per trajectory."""
        X = np.ascontiguousarray(xi).reshape(xi.shape[0], 1, self.k)
        return self._eval(X, self.vertical(G, gamma))

    # ------------------------------------------------------------------ stages
    @staticmethod
    def _sum(step: Step, terms, base: bool) -> np.ndarray:
        """``Z[0] + sum_j (w_j h) Z[1 + j]`` (``base``) or the sum alone, over ``terms`` (see :func:`_terms`),
        in order: (k + q, B), elementwise along the batch."""
        Z, hc = step.Z, step.hc
        acc = Z[0] if base else None
        for j, c in terms:
            term = hc[c] * Z[1 + j]
            acc = term if acc is None else acc + term
        return np.zeros_like(Z[0]) if acc is None else acc

    def _stage(self, step: Step, i: int, vertical: np.ndarray | None = None) -> np.ndarray:
        """Evaluate stage i >= 1 from the rows above it; returns its argument (k + q, B) and clears ``step.ok``
        where the chart argument is out of the chart's domain. ``vertical`` (B, n), if
        given, is the body vertical the field reads (else ``phi(-Theta_i) Gamma``)."""
        k, kern, ctx = self.k, self.kern, step.ctx
        z = self._sum(step, self._A[i], base=True)
        B = z.shape[1]
        X = np.ascontiguousarray(z[:k].T).reshape(B, 1, k)  # the model's input (see the module docstring)
        row = step.Z[1 + i]
        if kern is None:
            row[:k] = self._eval(X, None).T
            return z
        t = kern.load(ctx, z[k:])
        if vertical is None and self._has_gamma:
            vertical = kern.act(ctx, t)
        row[:k] = self._eval(X, vertical).T
        kern.dinv(ctx, t, kern.omega(ctx, z[:k], X), row[k:])
        self._check_domain(step, t)
        return z

    def _check_domain(self, step: Step, t) -> None:
        """Clear ``step.ok`` where the chart argument is beyond the chart's domain (:func:`.charts.domain_bound2`:
        for the exponential a rotation angle of pi; for Cayley its numerical limit). A NaN argument is not: the
        field broke down, and the step's non-finite end says so."""
        beyond = self.kern.domain_norm2(t) >= self._domain_bound2
        if beyond is True or beyond is False:  # one trajectory (float lanes)
            step.ok[0] &= not beyond
        else:
            step.ok &= ~beyond

    def trial(self, h: np.ndarray, xi: np.ndarray, G, gamma, f0: np.ndarray) -> Step:
        """One trial step of each trajectory; the state is not modified.

        Parameters
        ----------
        h : (B,)
            Signed step sizes (one per trajectory; 0 gives a harmless step nobody reads).
        xi : (B, k)
        G : (B, m, m), (B, n) or None
            The attitude (mode "g"), the vertical (mode "gamma"), or None.
        gamma : (B, n) or None
            The vertical in space (mode "g" with a vertical).
        f0 : (B, k)
            The field at the start (stage 0: the caller evaluates or reuses it).

        Returns
        -------
        Step
            With ``xi1``, ``G1``, ``ok`` and ``err`` (see :class:`Step`).
        """
        plan, kern, k = self.plan, self.kern, self.k
        B = xi.shape[0]
        step = Step()
        step.h = np.asarray(h, dtype=float)
        step.hc = self._coef * step.h  # (A[i, j] h) for every coefficient of the step: one product
        step.xi, step.G, step.gamma = xi, G, gamma
        step.Z = Z = np.empty((1 + plan.S, k + self.q, B))  # a row is read only once its stage is evaluated
        Z[0, :k] = xi.T
        Z[0, k:] = 0.0
        Z[1, :k] = f0.T
        step.ok = np.ones(B, dtype=bool)
        step.ctx = None
        if kern is not None:
            step.ctx = kern.begin(G, gamma if self._has_gamma else None, self.mode)
            X = np.ascontiguousarray(xi).reshape(B, 1, k)
            kern.first(kern.omega(step.ctx, Z[0, :k], X), Z[1, k:])
        s = plan.s
        z = None
        for i in range(1, plan.step_stages):
            z = self._stage(step, i)
        step.done = plan.step_stages
        if plan.fsal:  # stage s - 1 sits at the new point: stage s is a copy
            Z[1 + s] = Z[s]
            step.done = s + 1
            z1 = z
        else:
            z1 = self._sum(step, self._b, base=True)
        step.xi1 = np.ascontiguousarray(z1[:k].T)
        step.G1 = None
        if kern is not None:
            t1 = kern.load(step.ctx, z1[k:])
            self._check_domain(step, t1)
            step.G1 = kern.advance(step.ctx, G, t1) if self.mode == "g" else kern.act(step.ctx, t1)
        step.err = self._error(step) if plan.adaptive else None
        return step

    def _error(self, step: Step) -> tuple[np.ndarray, np.ndarray]:
        """Scaled sums of squares of the estimates in the state (see :mod:`.control`), one per trajectory."""
        k, kern = self.k, self.kern
        B = step.xi.shape[0]
        sums = []
        sc = control.scale(step.xi, step.xi1, self.rtol, self.atol)
        scG = None if kern is None else control.scale(step.G, step.G1, self.rtol, self.atol)
        for terms in self._err:
            e = self._sum(step, terms, base=False)
            s = np.sum((np.ascontiguousarray(e[:k].T) / sc) ** 2, axis=-1)
            if kern is not None:
                E = kern.matrix(step.ctx, e[k:])  # (B, m, m): the chart estimate, carried to the state
                eg = np.matmul(step.G1, E) if self.mode == "g" else np.matmul(E, step.G1[:, :, None])[:, :, 0]
                s = s + np.sum(((eg / scG) ** 2).reshape(B, -1), axis=-1)
            sums.append(s)
        return sums[0], sums[-1]

    # ------------------------------------------------------------------ the continuous extension
    def complete(self, step: Step) -> None:
        """Evaluate the stages the continuous extension needs that the trial step did not (after acceptance).

        Stage s, the field at the new point, reads the vertical of the step's end state (``g1^T gamma`` in
        mode g), as the next step's stage 0 would: the next step reuses it (the new-point rule), and a
        vertical carried by the chart (``phi(-Theta) g^T gamma``) would differ in the last bits — asking for
        output times would change the trajectory."""
        s = self.plan.s
        for i in range(step.done, self.plan.S):
            self._stage(step, i, self.vertical(step.G1, step.gamma) if i == s and self._has_gamma else None)
        step.done = self.plan.S

    def dense(self, step: Step, theta: np.ndarray, rows: np.ndarray):
        """States inside the step (after :meth:`complete`): trajectory ``rows[i]`` at ``t + theta[i] h``.

        Parameters
        ----------
        step : Step
        theta : (M,)
        rows : (M,) int
            Trajectories of ``step`` (repeats allowed: several times in one step).

        Returns
        -------
        xi : (M, k)
        G : (M, m, m), (M, n) or None
            ``g phi(Theta(theta))`` or ``phi(-Theta(theta)) Gamma``.
        """
        W = dense_weights(self.plan.dense, np.asarray(theta, dtype=float))  # (M, S)
        Z, h = step.Z[:, :, rows], step.h[rows]
        z = Z[0]
        for j in self._dense:
            z = z + (h * W[:, j]) * Z[1 + j]
        xi_t = np.ascontiguousarray(z[: self.k].T)
        if self.kern is None:
            return xi_t, None
        ctx = step.ctx.take(rows)
        t = self.kern.load(ctx, z[self.k:])
        return xi_t, (self.kern.advance(ctx, step.G[rows], t) if self.mode == "g" else self.kern.act(ctx, t))

    def new_point_field(self, step: Step) -> np.ndarray | None:
        """The field at the new point if the step evaluated it (stage s), (B, k); else None (the new-point rule)."""
        s = self.plan.s
        if step.done <= s:
            return None
        return np.ascontiguousarray(step.Z[1 + s, : self.k].T)
