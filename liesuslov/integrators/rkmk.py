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
``xi1 = xi + h sum b_j L_j`` and ``Theta = h sum b_j K_j``.

Layout (why a stage costs a fixed handful of numpy calls whatever the batch size): row 0 of one
stacked buffer ``Z`` holds ``(xi, 0)`` and row ``1 + j`` holds ``(L_j, K_j)``; the coefficient rows
``(1, h a_i0, …, h a_i,i-1)`` are rescaled once per step size, so ``(Xi_i, Theta_i)`` is *one*
vector-matrix product written into a preallocated row whose views the model and the chart read. The
chart's kernel (:meth:`liesuslov.integrators.charts.Chart.kernel`) fixes how an algebra element is
stored in a row — rotation vectors for so(3), the split ``(p, q)`` for so(4), algebra coordinates for
small so(n), r×r coordinates in a per-step basis for the Fedorov–Kozlov distribution at large n,
matrices otherwise — and does the chart's work on it (closed forms where they exist). For a batch the
rows are component-major (``xi`` as (k, B)), so that the model's and the chart's elementwise arithmetic
runs along the batch.
"""

from __future__ import annotations

import numpy as np

from .charts import Chart, body_vertical, make_chart
from .tableaux import ButcherTableau

__all__ = ["RKMKStepper"]


class RKMKStepper:
    """Advance ``(xi, G)`` by one RKMK step for a batch of ``B`` trajectories.

    Parameters
    ----------
    model : mechanics Model
        Provides ``k``, ``n``, ``has_gamma``, ``xi_dot(xi, Gamma)``, ``omega_matrix(xi)`` (linear in xi)
        and, optionally, ``fedorov_kozlov``.
    tableau : ButcherTableau
    chart : Chart, {"exp", "cayley"} or None
        None when ``mode == "none"``. A name builds the chart for ``model.n`` and the tableau's order.
    mode : {"g", "gamma", "none"}
    batch : int
        Number of trajectories B (flattened batch axes).

    Attributes
    ----------
    nfev : int
        Field evaluations so far (stage 0 is reused after an accepted FSAL step).
    theta_out : bool
        Whether :meth:`step` returns the increment ``Theta1`` as (B, m, m) matrices (default True);
        the time loop of :func:`~liesuslov.integrate` sets it False (it never reads Theta1) to save
        the dense assembly, which costs O(n² s) per step for the low-rank kernel.
    kernel : str or None
        Which chart kernel runs the group part ("so3", "so4", "coords", "lowrank", "dense").
    """

    def __init__(self, model, tableau: ButcherTableau, chart: Chart | str | None, mode: str, batch: int) -> None:
        self.model = model
        self.tab = tableau
        self.mode = mode
        self.B = B = int(batch)
        self.k = k = int(model.k)
        self.m = int(model.n) if mode != "none" else 0
        self.nfev = 0
        self.theta_out = True
        self._xi_dot = model.xi_dot
        self._has_gamma = bool(model.has_gamma) and mode != "none"
        s = tableau.A.shape[0]
        err_w = [np.asarray(e, dtype=float) for e in tableau.error_weights]
        # Error estimators that use the derivative at the new point need one more evaluation.
        s_eval = max([s] + [len(e) for e in err_w])
        self.s, self.s_eval = s, s_eval
        # FSAL: the last stage sits at the new point (its A row is b), so it is the next stage 0.
        self.fsal = s > 1 and bool(np.allclose(tableau.A[-1], tableau.b)) and tableau.c[-1] == 1.0
        if mode != "none":
            if chart is None or isinstance(chart, str):
                chart = make_chart(chart or "exp", self.m, skew=model.algebra.name.startswith("so("),
                                   order=tableau.order)
            self.kern = chart.kernel(model, B, s_eval, need_act=self._has_gamma)
            self.kernel = type(self.kern).__name__.strip("_").replace("Kernel", "").lower()
        else:
            self.kern, self.kernel = None, None
        self.chart = chart
        q = self.kern.q if self.kern is not None else 0
        self.nk = nk = B * k
        N = nk + B * q
        S = 1 + s_eval  # buffer rows: (xi, 0), then one per stage
        self.Z = Z = np.zeros((S, N))
        self._zin = [Z[: i + 1] for i in range(S)]  # stage i reads rows 0..i
        # xi part of a row: component-major (k, B) for a batch, seen as a (B, k) view: the model's
        # elementwise arithmetic on (B, k) arrays then runs along B (inner loops of length B, not k)
        self._xv = (lambda row: row.reshape(B, k)) if B == 1 else (lambda row: row.reshape(k, B).T)
        self._Lslot = [self._xv(Z[i, :nk]) for i in range(S)]
        self._Gslot = [self.kern.slot(Z[i, nk:]) for i in range(S)] if self.kern is not None else None
        # coefficient rows, scaled by h: stage i (1 <= i < s_eval) (1, h A[i, :i]); the step (1, h b); errors (0, h e)
        rows = len(range(1, s_eval)) + 1 + len(err_w)
        C1 = np.zeros((rows, S))
        Ca = np.zeros((rows, S))
        A = np.zeros((s_eval, s_eval))
        A[:s, :s] = tableau.A
        if s_eval > s:
            A[s, :s] = tableau.b  # the extra evaluation sits at the new point
        for r, i in enumerate(range(1, s_eval)):
            C1[r, 0] = 1.0
            Ca[r, 1: i + 1] = A[i, :i]
        C1[s_eval - 1, 0] = 1.0
        Ca[s_eval - 1, 1: s + 1] = tableau.b
        for r, e in enumerate(err_w):
            Ca[s_eval + r, 1: len(e) + 1] = e
        self._C1, self._Ca = C1, Ca
        self._Ch = np.zeros_like(Ca)
        self._h = None
        self._crow = [None] + [self._Ch[i - 1, : i + 1] for i in range(1, s_eval)]  # stage i
        self._cstep = self._Ch[s_eval - 1, : s + 1]
        self._cerr = self._Ch[s_eval:]
        self._n_err = len(err_w)
        # stage values (Xi_i, Theta_i), one preallocated row per stage, and their views
        self._zbuf = np.zeros((S, N))
        self._xi_v = [self._xv(self._zbuf[i, :nk]) for i in range(S)]
        self._th_v = [self._zbuf[i, nk:] for i in range(S)]
        self._first = None  # field value at the current point: stage 0 of the next step
        self._new = None  # the same at the point the last step reached, if it came for free

    def reset(self) -> None:
        """Forget cached stage data (call when the state is changed from outside)."""
        self._first = None
        self._new = None

    def gamma_of(self, G: np.ndarray | None, gamma: np.ndarray | None) -> np.ndarray | None:
        """The vertical in the body frame at the current point (None when the model has none)."""
        if not self.model.has_gamma or G is None:
            return None
        if self.mode == "g":
            return body_vertical(G, gamma)  # Gamma = g^T gamma
        return G

    def _rescale(self, h: float) -> None:
        np.multiply(self._Ca, h, out=self._Ch)
        self._Ch += self._C1
        self._h = h

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
            The group increment ``Theta`` (``G1 = G phi(Theta)``) as matrices; None in mode "none"
            or when :attr:`theta_out` is False.
        errs : list of (err_xi (B, k), err_Theta (B, ...) or None)
            One pair per error estimator of the tableau (DOP853 has two); empty unless asked.
            ``err_Theta`` is in the kernel's layout, scaled so that its squares summed over a
            trajectory are ``|err Theta|_F^2`` (for the dense kernel it is the (B, m, m) matrix).
        """
        if h != self._h:
            self._rescale(h)
        kern, f = self.kern, self._xi_dot
        has_gamma = self._has_gamma
        Lslot, Gslot, xi_v, th_v = self._Lslot, self._Gslot, self._xi_v, self._th_v
        Lslot[0][...] = xi  # row 0: (xi, 0)
        Gam0 = kern.begin(G, gamma if has_gamma else None, self.mode) if kern is not None else None
        if self._first is None:
            self._first = f(xi, Gam0)
            self.nfev += 1
        Lslot[1][...] = self._first
        if kern is not None:
            kern.first(kern.omega(0, xi), Gslot[1])
        last = self._first
        t = None
        for i in range(1, self.s):
            np.matmul(self._crow[i], self._zin[i], out=self._zbuf[i])
            Xi = xi_v[i]
            if kern is not None:
                t = kern.load(th_v[i])
                L = f(Xi, kern.act(t) if has_gamma else None)
                Lslot[i + 1][...] = L
                kern.dinv(t, kern.omega(i, Xi), Gslot[i + 1])
            else:
                L = f(Xi, None)
                Lslot[i + 1][...] = L
            last = L
        self.nfev += self.s - 1
        s = self.s
        if self.fsal:
            xi1 = xi_v[s - 1].copy()
            th1 = th_v[s - 1]
        else:
            z = self._cstep @ self._zin[s]
            xi1 = self._xv(z[: self.nk])
            th1 = z[self.nk:]
            if kern is not None:
                t = kern.load(th1)
        self._new = last if self.fsal else None
        if self.s_eval > s:  # an estimator that needs the field at the new point
            Gam1 = kern.act(t) if (kern is not None and has_gamma) else None
            L = f(xi1, Gam1)
            self.nfev += 1
            Lslot[s + 1][...] = L
            if kern is not None:
                kern.dinv(t, kern.omega(s, xi1), Gslot[s + 1])
            self._new = L
        errs = []
        if want_error:
            E = self._cerr @ self.Z
            for e in range(self._n_err):
                ex = self._xv(E[e, : self.nk])
                errs.append((ex, kern.error(E[e, self.nk:]) if kern is not None else None))
        if kern is None:
            return xi1, None, None, errs
        G1 = kern.advance(G, t) if self.mode == "g" else kern.act(t)
        Theta1 = kern.matrix(th1) if self.theta_out else None
        return xi1, G1, Theta1, errs

    def accept(self) -> None:
        """The last step was accepted: what it computed at the new point becomes stage 0."""
        self._first = self._new
        self._new = None
