"""Coordinate charts of the group near the identity: the exponential and the Cayley map.

A chart is a field of the method, not a new integrator (Lielab's design): the RKMK stepper asks it
for ``phi(Theta)`` (the group increment), ``phi(Theta) v`` on vectors, and the inverse derivative
``dphi^{-1}`` that turns the left-trivialised velocity Omega into ``dTheta/dt``.

Side of the action: the attitude obeys ``g^{-1} dg/dt = Omega`` and a step writes
``g = g0 phi(Theta)`` (right multiplication), so ``dTheta/dt = dphi^{-1}_{-Theta}(Omega)``
— for the exponential ``Omega + 1/2 [Theta, Omega] + 1/12 [Theta, [Theta, Omega]] + …``; with the
other sign of the odd terms RKMK4 silently drops to order 2. The vertical in the body frame moves
by the inverse: ``Gamma = phi(Theta)^T Gamma0 = phi(-Theta) Gamma0`` for orthogonal groups.

What is computed (the method; every kernel below computes exactly this, to rounding):

* exp: ``phi = exp``; ``dexp^{-1}`` exact on so(3), the series truncated at ``ad^{p-2}`` otherwise
  (:func:`liesuslov.groups.dexpinv_terms`), p the order of the tableau;
* Cayley: ``cay(X) = (I - X/2)^{-1} (I + X/2)`` and the exact ``(I + Theta/2) Omega (I - Theta/2)``.

Kernels: how the stage values live in the stepper's buffer
---------------------------------------------------------
The RKMK stepper keeps every stage's ``K_i`` in one row of a stacked buffer, so that each stage sum
``Theta_i = h sum_j a_ij K_j`` is one matrix-vector product. A :class:`Chart` hands the stepper a
*kernel* that fixes the layout of an algebra element in that row (``q`` numbers per trajectory) and
does the chart's work on it. It picks the smallest exact one for the scene:

* ``"so3"`` (n = 3): the rotation vector ``w`` (q = 3), closed forms by components — Rodrigues, the
  exact ``dexp^{-1}``, the Cayley maps — as Python floats for a single trajectory (no numpy call in
  the chart at all) and as contiguous 1-D arrays for a batch;
* ``"so4"`` (n = 4): so(4) = so(3) ⊕ so(3) (:func:`liesuslov.groups.so4_split`), the pair ``(p, q)``
  (q = 6): ``exp X = exp P exp Q`` with two Rodrigues formulas, the truncated ``dexp^{-1}`` as a
  polynomial on each factor, a closed-form Cayley transform, all by components;
* ``"coords"`` (exponential chart on so(n), 5 <= n <= :data:`COORDS_MAX_N`): the d coordinates
  (q = d); the truncated ``dexp^{-1}`` as powers of the d×d matrix ``ad_Theta`` (one matmul to build it
  from the structure constants, one matrix-vector product per power) instead of matrix brackets;
* ``"lowrank"`` (Fedorov–Kozlov models, n >= :data:`LOWRANK_MIN_N`): an element of D is
  ``u ∧ e_n`` (rank 2), so within one step every stage's ``Theta_i`` and ``K_i`` lies in
  ``so(span{e_n, u_0, …, u_{s-1}})``. With an orthonormal basis ``Q`` (n × r, r <= s + 1) of that span,
  built stage by stage by Gram–Schmidt, they are ``Q M Q^T`` with M skew r × r and
  ``phi(Q M Q^T) = I + Q (phi(M) - I) Q^T``: a stage costs O(n r + r^3) and the attitude update
  ``g (I + Q (phi(M) - I) Q^T)`` O(n² r) — no n×n exponential;
* ``"dense"``: (B, m, m) matrices for every other case (so(n) with skew-symmetric brackets and
  closed forms where :mod:`liesuslov.groups` has them; general matrix groups).

Every kernel agrees with the dense one to rounding (``tests/test_integrators.py`` steps both side by
side: states, increments, error estimates, nfev). Layouts for a batch are component-major, so that
elementwise arithmetic runs along the batch (contiguous rows of length B) rather than along tiny
trailing axes; a single trajectory runs the so(3)/so(4) formulas on Python floats.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import groups
from ..groups import (
    _cayley_coefficients,
    _dexpinv_so3_poly,
    _dexpinv_so3_series,
    _eye,
    _rodrigues,
    _rodrigues_dexp3,
    _so3_lin_c,
    _so3_mat,
    _so4_cayley_coefficients,
    _so4_dcayinv_c,
    _so4_dexpinv_c,
    _so4_exp_apply_c,
    _so4_exp_coefficients,
    _so4_exp_mat_c,
    _so4_lin_apply_c,
    _so4_mat_c,
    _solve,
    _stack,
)

__all__ = ["Chart", "make_chart", "CHARTS", "KERNELS", "LOWRANK_MIN_N", "COORDS_MAX_N",
           "body_vertical"]

CHARTS = ("exp", "cayley")
KERNELS = ("so3", "so4", "coords", "lowrank", "dense")

#: Fedorov–Kozlov models from this n on use the low-rank kernel (below it the dense n×n work is as cheap).
LOWRANK_MIN_N = 16
#: The exponential chart on so(n), 5 <= n <= COORDS_MAX_N, runs dexp⁻¹ in coordinates (``"coords"`` kernel).
COORDS_MAX_N = 8

# The dense and component kernels precompute Omega(xi) as one matmul with a (k, m*m) basis when it has at
# most this many entries; beyond, they call model.omega_matrix at each stage.
_OMEGA_BASIS_MAX = 1 << 22

_SQRT2 = math.sqrt(2.0)


@dataclass(frozen=True)
class Chart:
    """A chart for m×m representation matrices and a method of order ``order``.

    Attributes
    ----------
    name : {"exp", "cayley"}
    m : int
        Matrix size.
    skew : bool
        True on so(n) (closed forms, orthogonal output); False for general matrix groups.
    order : int
        Order p of the RK method; the exponential's dexp^{-1} series keeps the terms up to
        ``ad^{p-2}`` (sufficient for order p, Munthe-Kaas 1999; Hairer–Lubich–Wanner IV.8).
    kind : {"so3", "so4", "coords", "lowrank", "dense"} or None
        Force the stepper's kernel (for tests and comparisons); None picks the smallest exact one.

    Notes
    -----
    :meth:`phi`, :meth:`phi_vec` and :meth:`dinv` are the reference maps on dense matrices;
    :meth:`kernel` gives the stepper's fast implementation of the same maps.
    """

    name: str
    m: int
    skew: bool
    order: int
    kind: str | None = None

    @property
    def terms(self) -> int:
        """Number of dexp⁻¹ series terms (``dexpinv_terms(order)``)."""
        return groups.dexpinv_terms(self.order)

    def phi(self, X: np.ndarray) -> np.ndarray:
        """The map algebra -> group, (..., m, m) -> (..., m, m)."""
        if self.name == "exp":
            return groups.expm_skew(X) if self.skew else groups.expm(X)
        return groups.cayley_skew(X) if self.skew else groups.cayley(X)

    def phi_vec(self, X: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``phi(X) v``: (..., m, m), (..., m) -> (..., m)."""
        if self.name == "exp":
            if self.skew:
                return groups.expm_skew_apply(X, v)
            return (groups.expm(X) @ v[..., None])[..., 0]
        return groups.cayley_skew_apply(X, v) if self.skew else groups.cayley_apply(X, v)

    def dinv(self, Theta: np.ndarray, A: np.ndarray) -> np.ndarray:
        """``dphi^{-1}_{-Theta}(A)`` (right-trivialised): exact for Cayley and the so(3) exponential."""
        if self.name == "cayley":
            if self.skew and self.m == 3:
                return groups.dcayinv_skew3(Theta, A, side="right")
            return groups.dcayinv(Theta, A, side="right")
        if self.skew and self.m == 3:
            return groups.dexpinv_skew3(Theta, A, side="right")
        return groups.dexpinv(Theta, A, self.terms, side="right", skew=self.skew)

    def kernel(self, model, batch: int, slots: int, *, need_act: bool, kind: str | None = None):
        """The stepper's kernel for ``model`` and a batch of ``batch`` trajectories.

        Parameters
        ----------
        model : mechanics Model
            Its ``omega_matrix`` (linear in xi) and, for the low-rank kernel, ``fedorov_kozlov``.
        batch : int
        slots : int
            Number of stage evaluations per step (the low-rank basis has ``slots + 1`` columns).
        need_act : bool
            Whether stages need ``phi(-Theta_i) Gamma0`` (the model has a vertical).
        kind : {"so3", "so4", "coords", "lowrank", "dense"}, optional
            Force a kernel; default :attr:`kind`, else the smallest exact one (:meth:`default_kernel`).
        """
        kind = kind or self.kind or self.default_kernel(model, batch)
        if kind not in KERNELS:
            raise ValueError(f"kind must be one of {KERNELS}, got {kind!r}")
        if kind in ("so3", "so4") and not (self.skew and self.m == int(kind[2])):
            raise ValueError(f"the {kind!r} kernel needs so({kind[2]}), the chart is for {self.m}×{self.m} matrices")
        if kind == "coords" and not (self.skew and _on_so(model, self.m)):
            raise ValueError(f"the 'coords' kernel needs so(n), the model is on {getattr(model, 'algebra', None)}")
        if kind == "lowrank" and not (self.skew and getattr(model, "fedorov_kozlov", False)):
            raise ValueError("the 'lowrank' kernel needs a Fedorov–Kozlov model (Omega = u ∧ e_n)")
        cls = {"so3": _So3Kernel, "so4": _So4Kernel, "coords": _CoordsKernel, "lowrank": _LowRankKernel,
               "dense": _DenseKernel}[kind]
        return cls(self, model, int(batch), int(slots), bool(need_act))

    def default_kernel(self, model, batch: int = 1) -> str:
        """The kernel :meth:`kernel` picks for ``model``: the smallest exact one.

        The numpy solver steps one trajectory at a time (batches run compiled), so the choice depends on
        the scene only: the so(3) / so(4) closed forms, the low-rank Fedorov–Kozlov kernel from
        :data:`LOWRANK_MIN_N`, coordinates for the exponential on small so(n), matrices otherwise.
        ``batch`` is accepted for compatibility and ignored.
        """
        if self.skew and self.m in (3, 4):
            return f"so{self.m}"
        if self.skew and self.m >= LOWRANK_MIN_N and getattr(model, "fedorov_kozlov", False):
            return "lowrank"
        if self.skew and self.name == "exp" and self.m <= COORDS_MAX_N and _on_so(model, self.m):
            return "coords"
        return "dense"


def make_chart(name: str, m: int, *, skew: bool, order: int, kind: str | None = None) -> Chart:
    """Build the chart ``name`` for m×m representation matrices.

    Parameters
    ----------
    name : {"exp", "cayley"}
    m : int
        Matrix size.
    skew : bool
        True on so(n) (closed forms, orthogonal output); False for general matrix groups.
    order : int
        Order p of the RK method; the exponential's dexp^{-1} series keeps the terms up to
        ``ad^{p-2}`` (sufficient for order p, Munthe-Kaas 1999; Hairer–Lubich–Wanner IV.8).
    kind : {"so3", "so4", "coords", "lowrank", "dense"}, optional
        Force the stepper's kernel (see :class:`Chart`).
    """
    if name not in CHARTS:
        raise ValueError(f"chart must be one of {CHARTS}, got {name!r}")
    if kind is not None and kind not in KERNELS:
        raise ValueError(f"kind must be one of {KERNELS}, got {kind!r}")
    return Chart(name, int(m), bool(skew), int(order), kind)


def _on_so(model, m: int) -> bool:
    alg = getattr(model, "algebra", None)
    return alg is not None and getattr(alg, "name", None) == f"so({m})"


def _nan_if_singular(shape: tuple[int, ...], f, *args) -> np.ndarray:
    """``f(*args)``, or NaNs of ``shape`` where a linear solve inside meets an exactly singular matrix
    (``I - X/2`` of a diverged run, |X| ~ 1e49): the time loop then stops with status -1 and the time,
    as for any non-finite state, instead of raising from inside a step."""
    try:
        return f(*args)
    except np.linalg.LinAlgError:
        return np.full(shape, np.nan)


def _omega_basis(model, m: int) -> np.ndarray | None:
    """``W`` (k, m*m) with ``omega_matrix(xi) = (xi @ W).reshape(m, m)`` (Omega is linear in xi), or None if large."""
    k = int(model.k)
    if k * m * m > _OMEGA_BASIS_MAX:
        return None
    return np.ascontiguousarray(np.asarray(model.omega_matrix(np.eye(k)), dtype=float).reshape(k, m * m))


def body_vertical(G: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """``Gamma = g^T gamma`` for a batch: (B, m, m), (B, m) -> (B, m).

    One matmul for a single trajectory; for a batch, elementwise products summed over j
    (``Gamma_i = sum_j g_ji gamma_j``), cheaper than numpy's stacked tiny matrix products.
    """
    if G.shape[0] == 1:
        return np.matmul(gamma[:, None, :], G)[:, 0, :]
    return (G * gamma[:, :, None]).sum(axis=1)


def _vertical_components(G: np.ndarray, gamma: np.ndarray | None, mode: str, single: bool):
    """``(Gamma0 (B, n) or None, its components)`` at the start of a step (component kernels).

    Components are Python floats for one trajectory, contiguous (B,) rows for a batch; the batch
    array is the (B, n) view of the stacked rows (column-major, so the model's arithmetic runs along B).
    """
    if mode == "gamma":
        Gam0 = G
    elif gamma is None:
        return None, None
    elif single:
        Gam0 = np.matmul(gamma[:, None, :], G)[:, 0, :]
    else:
        m = G.shape[-1]
        rows = [G[:, 0, i] * gamma[:, 0] for i in range(m)]  # Gamma_i = sum_j g_ji gamma_j, along B
        for j in range(1, m):
            gj = gamma[:, j]
            for i in range(m):
                rows[i] += G[:, j, i] * gj
        V = np.stack(rows)
        return V.T, tuple(V)
    if single:
        return Gam0, tuple(Gam0.ravel().tolist())
    return Gam0, tuple(np.ascontiguousarray(Gam0.T))


# ====================================================================================== kernels
class _Kernel:
    """Protocol of a kernel (the stepper calls only these; ``t`` is what :meth:`load` returns).

    * ``q``: numbers per trajectory in a buffer row; ``slot(flat)`` a writable view of a row's part.
    * ``begin(G, gamma, mode)``: once per step, before stage 0; returns the body vertical ``Gam0``
      (B, n) — ``g^T gamma`` in mode "g", G itself in mode "gamma" — or None (no vertical).
    * ``omega(i, Xi)``: Omega at stage i; ``first(om, slot)``: store ``K_0 = Omega_0``.
    * ``load(flat)``: the stage value ``Theta_i`` from its flat part of a stage sum.
    * ``act(t)``: ``phi(-Theta) Gam0``, (B, n); ``dinv(t, om, slot)``: store ``K_i``.
    * ``advance(G, t)``: ``G phi(Theta)`` (B, m, m) for the attitude.
    * ``error(flat)``: (B, …) whose squares summed per trajectory are ``|E|_F^2`` of the error increment.
    * ``matrix(flat)``: the increment as (B, m, m) matrices.
    """

    q = 0


class _DenseKernel(_Kernel):
    """(B, m, m) matrices: the reference maps of :class:`Chart`, with one matmul for Omega(xi)."""

    def __init__(self, chart: Chart, model, B: int, slots: int, need_act: bool) -> None:
        m = chart.m
        self.chart, self.B, self.m, self.q = chart, B, m, m * m
        self.shape = (B, m, m)
        self.exp = chart.name == "exp"
        self.skew = chart.skew
        self.terms = chart.terms
        self.R = _omega_basis(model, m)
        self.omega_matrix = model.omega_matrix
        self.gam0 = None

    def slot(self, flat: np.ndarray) -> np.ndarray:
        return flat.reshape(self.shape)

    def begin(self, G: np.ndarray, gamma: np.ndarray | None, mode: str) -> np.ndarray | None:
        self.gam0 = G if mode == "gamma" else (None if gamma is None else body_vertical(G, gamma))
        return self.gam0

    def omega(self, i: int, Xi: np.ndarray):
        if self.R is None:
            return self.omega_matrix(Xi)
        return (Xi @ self.R).reshape(self.shape)

    def first(self, om, slot: np.ndarray) -> None:
        slot[...] = om

    def load(self, flat: np.ndarray):
        return flat.reshape(self.shape)

    def _phi(self, T: np.ndarray) -> np.ndarray:
        return self.chart.phi(T) if self.exp else _nan_if_singular(T.shape, self.chart.phi, T)

    def act(self, T: np.ndarray) -> np.ndarray:
        v = self.gam0
        if self.skew and self.exp and self.m > 4:
            # phi(-T) v = phi(T)^T v (orthogonal): a row vector times phi(T), no negated copy
            return np.matmul(v[:, None, :], self._phi(T))[:, 0, :]
        if self.exp:
            return self.chart.phi_vec(-T, v)
        # cay(-T) v = (I + T/2)^{-1} (v - T v / 2): one solve with a vector right-hand side
        H = 0.5 * T
        rhs = v - np.matmul(H, v[:, :, None])[:, :, 0]
        return _nan_if_singular(rhs.shape + (1,), _solve, _eye(self.m) + H, rhs[:, :, None])[:, :, 0]

    def dinv(self, T: np.ndarray, om: np.ndarray, slot: np.ndarray) -> None:
        if self.exp:
            if self.skew and self.m == 3:
                slot[...] = groups.dexpinv_skew3(T, om, side="right")
            else:
                slot[...] = groups.dexpinv(T, om, self.terms, side="right", skew=self.skew)
        else:
            # (I + T/2) A (I - T/2) = M - M T / 2 with M = A + T A / 2 (two products)
            M = om + 0.5 * np.matmul(T, om)
            slot[...] = M - 0.5 * np.matmul(M, T)

    def advance(self, G, T):
        return np.matmul(G, self._phi(T))

    def error(self, flat: np.ndarray) -> np.ndarray:
        return flat.reshape(self.shape)

    def matrix(self, flat: np.ndarray) -> np.ndarray:
        return flat.reshape(self.shape).copy()


class _CoordsKernel(_Kernel):
    """so(n) elements as their d coordinates; ``dexp^{-1}`` by powers of the d×d matrix ``ad_Theta``.

    The truncated series ``sum_k (B_k/k!) ad^k_Theta Omega`` (right side) costs one matmul to build
    ``ad_Theta = theta @ C`` from the structure constants and one matrix-vector product per power,
    instead of three matrix operations per bracket; Theta is assembled as a matrix (one matmul) only
    for the exponential itself. For small n (d³ flops per stage, n <= :data:`COORDS_MAX_N`).
    """

    def __init__(self, chart: Chart, model, B: int, slots: int, need_act: bool) -> None:
        from ..algebra import so

        m = chart.m
        alg = so(m)
        d = alg.dim
        self.chart, self.B, self.m, self.d, self.q = chart, B, m, d, d
        self.single = B == 1
        self.exp = chart.name == "exp"
        idx = alg._rows * m + alg._cols  # coordinate of E_ij = entry (i, j), i < j
        self.idx = idx
        self.R = np.ascontiguousarray(_omega_basis(model, m)[:, idx])  # (k, d)
        self.E = np.ascontiguousarray(alg.representation.reshape(d, m * m))  # hat: theta @ E
        # ad_theta[k, j] = sum_i theta_i C[i, j, k]: one matmul with C transposed to (i, k, j)
        self.C = np.ascontiguousarray(alg.structure_constants.transpose(0, 2, 1).reshape(d, d * d))
        terms = groups.bernoulli_coefficients(chart.terms)
        self.K = max(k for k, _ in terms)  # highest power of ad needed
        coef = np.zeros(self.K + 1)
        for k, c in terms:
            coef[k] = -c if k == 1 else c  # right side: the odd term changes sign
        self.coef = coef
        self.pw = np.zeros((self.K + 1, d)) if self.single else np.zeros((B, self.K + 1, d))
        self.shape = (B, m, m)
        self.gam0 = None

    def slot(self, flat: np.ndarray) -> np.ndarray:
        return flat.reshape(self.B, self.d)

    def begin(self, G: np.ndarray, gamma: np.ndarray | None, mode: str) -> np.ndarray | None:
        self.gam0 = G if mode == "gamma" else (None if gamma is None else body_vertical(G, gamma))
        return self.gam0

    def omega(self, i: int, Xi: np.ndarray):
        return Xi @ self.R

    def first(self, om, slot: np.ndarray) -> None:
        slot[...] = om

    def load(self, flat: np.ndarray):
        th = flat.reshape(self.B, self.d)
        return th, (th @ self.E).reshape(self.shape)

    def _phi(self, T: np.ndarray) -> np.ndarray:
        return self.chart.phi(T) if self.exp else _nan_if_singular(T.shape, self.chart.phi, T)

    def act(self, t) -> np.ndarray:
        T, v = t[1], self.gam0
        if self.exp:  # phi(-T) v = phi(T)^T v: a row vector times phi(T)
            return np.matmul(v[:, None, :], self._phi(T))[:, 0, :]
        H = 0.5 * T
        rhs = v - np.matmul(H, v[:, :, None])[:, :, 0]
        return _nan_if_singular(rhs.shape + (1,), _solve, _eye(self.m) + H, rhs[:, :, None])[:, :, 0]

    def dinv(self, t, om, slot: np.ndarray) -> None:
        th, T = t
        if not self.exp:  # (I + T/2) A (I - T/2) on matrices, back to coordinates
            A = (om @ self.E).reshape(self.shape)
            M = A + 0.5 * np.matmul(T, A)
            slot[...] = (M - 0.5 * np.matmul(M, T)).reshape(self.B, -1)[:, self.idx]
            return
        if self.single:  # powers ad^k omega as the rows of pw, then one product with the coefficients
            ad = (th[0] @ self.C).reshape(self.d, self.d)
            pw = self.pw
            pw[0] = om[0]
            for k in range(1, self.K + 1):
                np.matmul(ad, pw[k - 1], out=pw[k])
            np.matmul(self.coef, pw, out=slot[0])
            return
        ad = (th @ self.C).reshape(self.B, self.d, self.d)
        pw = self.pw
        pw[:, 0] = om
        for k in range(1, self.K + 1):
            np.matmul(ad, pw[:, k - 1, :, None], out=pw[:, k, :, None])
        np.matmul(self.coef, pw, out=slot)

    def advance(self, G: np.ndarray, t) -> np.ndarray:
        return np.matmul(G, self._phi(t[1]))

    def error(self, flat: np.ndarray) -> np.ndarray:
        return _SQRT2 * flat.reshape(self.B, self.d)  # |X|_F² = 2 |x|²

    def matrix(self, flat: np.ndarray) -> np.ndarray:
        return (flat.reshape(self.B, self.d) @ self.E).reshape(self.shape)


class _ComponentKernel(_Kernel):
    """Kernels that hold each stage value as ``q`` components, component-major (rows of length B).

    ``R`` (k, q) maps reduced coordinates to the components. A single trajectory (B = 1) runs the
    chart on Python floats; a batch on contiguous 1-D arrays.
    """

    def _setup(self, chart: Chart, R: np.ndarray, B: int, need_act: bool) -> None:
        self.R = np.ascontiguousarray(R)
        self.RT = np.ascontiguousarray(self.R.T)
        self.B, self.single = B, B == 1
        self.exp = chart.name == "exp"
        self.need_act = need_act
        self.v = None

    def slot(self, flat: np.ndarray) -> np.ndarray:
        return flat if self.single else flat.reshape(self.q, self.B)

    def begin(self, G: np.ndarray, gamma: np.ndarray | None, mode: str) -> np.ndarray | None:
        Gam0, self.v = _vertical_components(G, gamma, mode, self.single)
        return Gam0

    def omega(self, i: int, Xi: np.ndarray):
        if self.single:
            return (Xi @ self.R).ravel().tolist()
        return np.matmul(self.RT, Xi.T)  # (q, B), contiguous rows

    def first(self, om, slot: np.ndarray) -> None:
        slot[...] = om


class _So3Kernel(_ComponentKernel):
    """so(3): rotation vectors ``w``, closed forms by components."""

    q = 3

    def __init__(self, chart: Chart, model, B: int, slots: int, need_act: bool) -> None:
        # w = (X21, X02, X10) of each basis element
        self._setup(chart, _omega_basis(model, 3)[:, [7, 2, 3]], B, need_act)

    def load(self, flat: np.ndarray):
        w = tuple(flat.tolist()) if self.single else tuple(flat.reshape(3, self.B))
        t2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
        if not self.exp:
            co = _cayley_coefficients(t2)  # (c, a, b): cay = c I + a hat w + b w w^T
        elif self.need_act:
            co = _rodrigues_dexp3(t2)  # (c, a, b) of Rodrigues and the dexp⁻¹ coefficient, one sin and cos
        else:
            co = (None, None, None, groups._dexp3_coefficient(t2))
        return w, t2, co

    def act(self, t) -> np.ndarray:
        w, _, (c, a, b) = t[0], t[1], t[2][:3]
        vals = _so3_lin_c(c, -a, b, w, self.v)  # phi(-Theta) v = c v - a w × v + b (w·v) w
        return np.array([vals]) if self.single else np.stack(vals).T  # (B, n) view of (n, B) rows

    def dinv(self, t, om, slot: np.ndarray) -> None:
        w, t2, co = t
        if self.exp:  # right side: a + ½ θ × a + c(θ) θ × (θ × a), exact
            vals = _so3_lin_c(1.0 - co[3] * t2, 0.5, co[3], w, tuple(om))
        else:  # (I + Θ/2) Ω (I − Θ/2) = a + ½ θ × a + ¼ (θ·a) θ
            vals = _so3_lin_c(1.0, 0.5, 0.25, w, tuple(om))
        if self.single:
            slot[:] = vals
        else:
            slot[0], slot[1], slot[2] = vals

    def advance(self, G: np.ndarray, t) -> np.ndarray:
        w, t2, co = t
        coef = co[:3] if co[0] is not None else _rodrigues(t2)
        return np.matmul(G, _so3_mat(*coef, w, (self.B,)))

    def error(self, flat: np.ndarray) -> np.ndarray:
        return _SQRT2 * flat.reshape(3, self.B).T  # |hat w|_F² = 2 |w|²

    def matrix(self, flat: np.ndarray) -> np.ndarray:
        w0, w1, w2 = flat.reshape(3, self.B)
        z = np.zeros(self.B)
        return np.stack((z, -w2, w1, w2, z, -w0, -w1, w0, z), -1).reshape(self.B, 3, 3)


class _So4Kernel(_ComponentKernel):
    """so(4) = so(3) ⊕ so(3): the pair ``(p, q)`` (component-major), closed forms by components."""

    q = 6

    def __init__(self, chart: Chart, model, B: int, slots: int, need_act: bool) -> None:
        W = _omega_basis(model, 4)
        # flat matrix -> (p, q): p = ½ (X01 + X23, X02 − X13, X03 + X12), q = ½ (X01 − X23, X02 + X13, X03 − X12)
        T = np.zeros((16, 6))
        for col, (i, j, sgn) in enumerate(((1, 11, 1), (2, 7, -1), (3, 6, 1), (1, 11, -1), (2, 7, 1), (3, 6, -1))):
            T[i, col], T[j, col] = 0.5, 0.5 * sgn
        self._setup(chart, W @ T, B, need_act)
        self.half, self.poly = _dexpinv_so3_series(chart.terms)

    def load(self, flat: np.ndarray):
        c = flat.tolist() if self.single else tuple(flat.reshape(6, self.B))
        return (c[0], c[1], c[2]), (c[3], c[4], c[5])

    def act(self, t) -> np.ndarray:
        p, q = t
        if self.exp:
            vals = _so4_exp_apply_c(_so4_exp_coefficients(p, q), p, q, self.v, -1.0)
        else:
            vals = _so4_lin_apply_c(_so4_cayley_coefficients(p, q), p, q, self.v, -1.0)
        return np.array([vals]) if self.single else np.stack(vals).T  # (B, n) view of (n, B) rows

    def dinv(self, t, om, slot: np.ndarray) -> None:
        p, q = t
        ap, aq = (om[0], om[1], om[2]), (om[3], om[4], om[5])
        p0, p1, p2 = p
        q0, q1, q2 = q
        a2 = p0 * p0 + p1 * p1 + p2 * p2
        b2 = q0 * q0 + q1 * q1 + q2 * q2
        if self.exp:  # the truncated series on each factor
            cp = _dexpinv_so3_poly(4.0 * a2, self.poly)
            cq = _dexpinv_so3_poly(4.0 * b2, self.poly)
            vals = _so4_dexpinv_c(self.half, cp, cq, a2, b2, p, q, ap, aq)
        else:  # exact: (I + Θ/2) Ω (I − Θ/2)
            vals = _so4_dcayinv_c(a2, b2, p, q, ap, aq)
        if self.single:
            slot[:] = vals
        else:
            for j in range(6):
                slot[j] = vals[j]

    def advance(self, G: np.ndarray, t) -> np.ndarray:
        p, q = t
        if self.exp:
            M = _so4_exp_mat_c(_so4_exp_coefficients(p, q), p, q)
        else:
            M = _so4_mat_c(_so4_cayley_coefficients(p, q), p, q)
        return np.matmul(G, _stack(M, (4, 4), (self.B,)))

    def error(self, flat: np.ndarray) -> np.ndarray:
        return 2.0 * flat.reshape(6, self.B).T  # |X|_F² = 4 (|p|² + |q|²)

    def matrix(self, flat: np.ndarray) -> np.ndarray:
        c = flat.reshape(6, self.B)
        return _stack(_so4_mat_c((0.0, 1.0, 1.0, 0.0), tuple(c[:3]), tuple(c[3:])), (4, 4), (self.B,))


class _LowRankKernel(_Kernel):
    """Fedorov–Kozlov models: stage values ``Q M Q^T`` in a per-step orthonormal basis ``Q`` (see the module docstring).

    ``Q`` (B, n, r), r = slots + 1: column 0 is ``e_n``, column ``i + 1`` the part of stage i's
    ``u = (xi, 0)`` orthogonal to the previous columns (classical Gram–Schmidt, twice; a ``u`` already in
    the span to rounding adds a zero column, which the zero rows and columns of every M ignore). With
    ``u = Q c``: ``Omega = u ∧ e_n = Q (c ∧ e_0) Q^T``. Brackets, dexp⁻¹ and dcay⁻¹ act on the r×r
    coordinates M (``[Q A Q^T, Q B Q^T] = Q [A, B] Q^T``), ``phi(Q M Q^T) = I + Q (phi(M) - I) Q^T``,
    and ``|Q E Q^T|_F = |E|_F``.
    """

    def __init__(self, chart: Chart, model, B: int, slots: int, need_act: bool) -> None:
        n = int(model.n)
        r = slots + 1
        self.chart, self.B, self.n, self.r, self.q = chart, B, n, r, r * r
        self.single = B == 1
        self.exp = chart.name == "exp"
        self.terms = chart.terms
        self.Q = np.zeros((B, n, r))
        self.Q[:, n - 1, 0] = 1.0
        self.Qu = self.Q[:, : n - 1, :]  # the u-part (rows 0..n-2) of the columns
        self.Q1, self.Qu1 = self.Q[0], self.Qu[0]  # one trajectory: 2-D views, 2-D products
        self.M1 = np.zeros((1, r, r))  # Omega's coordinates (only row and column 0 are ever nonzero)
        self.cols = 1
        self.shape = (B, r, r)
        self.gam0 = None

    def slot(self, flat: np.ndarray) -> np.ndarray:
        return flat.reshape(self.shape)

    def begin(self, G: np.ndarray, gamma: np.ndarray | None, mode: str) -> np.ndarray | None:
        self.Q[:, : self.n - 1, 1:] = 0.0
        self.cols = 1
        self.gam0 = G if mode == "gamma" else (None if gamma is None else body_vertical(G, gamma))
        return self.gam0

    def omega(self, i: int, Xi: np.ndarray):
        j = self.cols
        self.cols = j + 1
        if self.single:
            return self._omega1(Xi[0], j)
        Qu = self.Qu
        c = np.matmul(Xi[:, None, :], Qu)[:, 0, :]  # (B, r): Q^T u
        w = Xi - np.matmul(Qu, c[:, :, None])[:, :, 0]
        rho1 = np.sqrt(np.einsum("bi,bi->b", w, w))
        c2 = np.matmul(w[:, None, :], Qu)[:, 0, :]  # second pass (Kahan: twice is enough)
        w = w - np.matmul(Qu, c2[:, :, None])[:, :, 0]
        c += c2
        rho = np.sqrt(np.einsum("bi,bi->b", w, w))
        # a second pass that removes more than half means u was in the span to rounding: no new direction
        keep = rho > 0.5 * rho1
        c[:, j] = np.where(keep, rho, 0.0)
        Qu[:, :, j] = w * np.where(keep, 1.0 / np.where(keep, rho, 1.0), 0.0)[:, None]
        M = np.zeros(self.shape)
        M[:, :, 0] = c
        M[:, 0, :] = -c
        return M

    def _omega1(self, u: np.ndarray, j: int) -> np.ndarray:
        """:meth:`omega` for one trajectory (2-D products, scalar tests)."""
        Qu = self.Qu1
        if j == 1:  # empty basis: u itself is the new direction
            c = np.zeros(self.r)
            w, rho1 = u, math.sqrt(u @ u)
        else:
            c = u @ Qu
            w = u - Qu @ c
            rho1 = math.sqrt(w @ w)
            c2 = w @ Qu
            w = w - Qu @ c2
            c += c2
        rho = math.sqrt(w @ w)
        if rho > 0.5 * rho1:  # as in the batch path; j == 1 keeps any u != 0
            c[j] = rho
            Qu[:, j] = w / rho
        M = self.M1
        M[0, :, 0] = c
        M[0, 0, :] = -c
        return M

    def first(self, om, slot: np.ndarray) -> None:
        slot[...] = om

    def load(self, flat: np.ndarray):
        return flat.reshape(self.shape)

    def _phi(self, M: np.ndarray) -> np.ndarray:
        return groups.expm_skew(M) if self.exp else _nan_if_singular(M.shape, groups.cayley_skew, M)

    def act(self, M: np.ndarray) -> np.ndarray:
        ra = self.cols  # Theta_i lies in the span of the columns built so far
        if self.single:
            Qa, g0 = self.Q1[:, :ra], self.gam0[0]
            y = g0 @ Qa  # Q^T Gamma0
            z = y @ self._phi(M[0, :ra, :ra]) - y  # (phi(-M) - I) Q^T Gamma0, as a row: phi(-M) = phi(M)^T
            return (g0 + Qa @ z)[None, :]
        Qa = self.Q[:, :, :ra]
        E = self._phi(M[:, :ra, :ra])
        y = np.matmul(self.gam0[:, None, :], Qa)  # (B, 1, ra)
        z = np.matmul(y, E) - y
        return self.gam0 + np.matmul(z, np.swapaxes(Qa, -1, -2))[:, 0, :]

    def dinv(self, M: np.ndarray, om: np.ndarray, slot: np.ndarray) -> None:
        if self.exp:
            slot[...] = groups.dexpinv(M, om, self.terms, side="right", skew=True)
        else:
            P = om + 0.5 * np.matmul(M, om)
            slot[...] = P - 0.5 * np.matmul(P, M)

    def advance(self, G: np.ndarray, M: np.ndarray) -> np.ndarray:
        ra = self.cols
        if self.single:
            Qa, g = self.Q1[:, :ra], G[0]
            F = self._phi(M[0, :ra, :ra]) - _eye(ra)
            return (g + ((g @ Qa) @ F) @ Qa.T)[None]
        Qa = self.Q[:, :, :ra]
        F = self._phi(M[:, :ra, :ra]) - _eye(ra)
        return G + np.matmul(np.matmul(np.matmul(G, Qa), F), np.swapaxes(Qa, -1, -2))

    def error(self, flat: np.ndarray) -> np.ndarray:
        return flat.reshape(self.shape)

    def matrix(self, flat: np.ndarray) -> np.ndarray:
        Qa = self.Q
        return np.matmul(np.matmul(Qa, flat.reshape(self.shape)), np.swapaxes(Qa, -1, -2))
