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
The RKMK stepper (:mod:`.rkmk`) advances a batch of trajectories, each with its own step size, and keeps
every stage's ``K_i`` in one row of a stacked buffer, component-major: a row's chart part has shape
(q, B), one contiguous row of length B per component, so that the stage sums
``Theta_i = sum_j (a_ij h) K_j`` — h a (B,) array — are elementwise along the batch. A :class:`Chart`
hands the stepper a *kernel* that fixes what the q numbers per trajectory are and does the chart's work
on them. It picks the smallest exact one for the scene:

* ``"so3"`` (n = 3): the rotation vector ``w`` (q = 3), closed forms by components — Rodrigues, the
  exact ``dexp^{-1}``, the Cayley maps — on (B,) arrays;
* ``"so4"`` (n = 4): so(4) = so(3) ⊕ so(3) (:func:`liesuslov.groups.so4_split`), the pair ``(p, q)``
  (q = 6): ``exp X = exp P exp Q`` with two Rodrigues formulas, the truncated ``dexp^{-1}`` as a
  polynomial on each factor, a closed-form Cayley transform, all by components;
* ``"coords"`` (exponential chart on so(n), 5 <= n <= :data:`COORDS_MAX_N`): the d coordinates
  (q = d); the truncated ``dexp^{-1}`` as powers of the d×d matrix ``ad_Theta`` (one product to build it
  from the structure constants, one matrix-vector product per power) instead of matrix brackets;
* ``"lowrank"`` (Fedorov–Kozlov models, n >= :data:`LOWRANK_MIN_N`): an element of D is
  ``u ∧ e_n`` (rank 2), so within one step every stage's ``Theta_i`` and ``K_i`` lies in
  ``so(span{e_n, u_0, …, u_{s-1}})``. With an orthonormal basis ``Q`` (n × r, r <= s + 1) of that span,
  built stage by stage by Gram–Schmidt, they are ``Q M Q^T`` with M skew r × r and
  ``phi(Q M Q^T) = I + Q (phi(M) - I) Q^T``: a stage costs O(n r + r^3) and the attitude update
  ``g (I + Q (phi(M) - I) Q^T)`` O(n² r) — no n×n exponential;
* ``"dense"``: m×m matrices for every other case (so(n) with skew-symmetric brackets and closed forms
  for m = 3, 4; general matrix groups).

Every kernel agrees with the dense one to rounding (``tests/test_integrators.py`` steps both side by
side: states, increments, error estimates, nfev).

A trajectory's numbers do not depend on its batch mates or on B (one trajectory is a batch of one, on
the same code): every operation here is elementwise along the batch, a reduction along one
trajectory's own contiguous numbers, or a stacked product ``np.matmul`` / ``np.linalg.solve`` on
(B, ·, ·) arrays, which numpy evaluates matrix by matrix. Nothing multiplies across the batch (a BLAS
product with the batch as a matrix dimension blocks, and so rounds, differently with B), and every
choice — a Taylor branch, a Padé degree, a scaling exponent — is made per trajectory from its own
numbers (:mod:`liesuslov.groups` takes some of them from the whole batch, for speed: its batch paths
are not used here).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import groups
from ..groups import (
    _DEXP3_TAYLOR,
    _PADE_THETA,
    _SINC_TAYLOR,
    _cayley_coefficients,
    _dexp3_series,
    _dexpinv_so3_poly,
    _dexpinv_so3_series,
    _eye,
    _pade_uv,
    _so3_lin_c,
    _so3_mat,
    _so4_cayley_coefficients,
    _so4_dcayinv_c,
    _so4_dexpinv_c,
    _so4_exp_apply_c,
    _so4_exp_mat_c,
    _so4_lin_apply_c,
    _so4_mat_c,
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

# The dense and component kernels precompute Omega(xi) as a product with a (k, m*m) basis when it has at
# most this many entries; beyond, they call model.omega_matrix at each stage.
_OMEGA_BASIS_MAX = 1 << 22


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

    def kernel(self, model, slots: int, *, need_act: bool, kind: str | None = None):
        """The stepper's kernel for ``model`` (any batch: the arrays it is given carry the batch).

        Parameters
        ----------
        model : mechanics Model
            Its ``omega_matrix`` (linear in xi) and, for the low-rank kernel, ``fedorov_kozlov``.
        slots : int
            Number of stage evaluations per step (the low-rank basis has ``slots + 1`` columns).
        need_act : bool
            Whether stages need ``phi(-Theta_i) Gamma0`` (the model has a vertical).
        kind : {"so3", "so4", "coords", "lowrank", "dense"}, optional
            Force a kernel; default :attr:`kind`, else the smallest exact one (:meth:`default_kernel`).
        """
        kind = kind or self.kind or self.default_kernel(model)
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
        return cls(self, model, int(slots), bool(need_act))

    def default_kernel(self, model) -> str:
        """The kernel :meth:`kernel` picks for ``model``: the smallest exact one.

        The choice depends on the scene only (never on the batch size): the so(3) / so(4) closed forms,
        the low-rank Fedorov–Kozlov kernel from :data:`LOWRANK_MIN_N`, coordinates for the exponential on
        small so(n), matrices otherwise.
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


def _omega_basis(model, m: int) -> np.ndarray | None:
    """``W`` (k, m*m) with ``omega_matrix(xi) = (xi @ W).reshape(m, m)`` (Omega is linear in xi), or None if large."""
    k = int(model.k)
    if k * m * m > _OMEGA_BASIS_MAX:
        return None
    return np.ascontiguousarray(np.asarray(model.omega_matrix(np.eye(k)), dtype=float).reshape(k, m * m))


def body_vertical(G: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """``Gamma = g^T gamma`` for a batch: (B, m, m), (B, m) -> (B, m), one stacked product (per matrix)."""
    return np.matmul(gamma[:, None, :], G)[:, 0, :]


# ====================================================================================== maps, element by element
# What the kernels below compute on a stack of B elements, with nothing shared between the elements:
# branches are chosen per element (np.where, a masked assignment), products are stacked (np.matmul on
# (B, ·, ·) arrays runs one product per matrix), and a reduction runs along one element's own numbers.
#
# The so(3) / so(4) component kernels hold a stage value as ``q`` *lanes*: (B,) arrays for a batch, Python
# floats for a batch of one (numpy spends ~1 µs per call on a 1-element array, a float operation ~50 ns).
# The formulas are written once for both: Python's float arithmetic and numpy's elementwise arithmetic
# are the same IEEE operations (+, −, ×, ÷, sqrt, correctly rounded, never fused), a branch is ``if`` on
# a float where it is np.where on an array, and sin / cos go through numpy in both cases — so a
# trajectory gets the same bits alone as in any batch.
def _lanes(flat: np.ndarray) -> tuple:
    """The components of (q, B) rows: q floats for B = 1, else the q (B,) rows."""
    return tuple(flat[:, 0].tolist()) if flat.shape[1] == 1 else tuple(flat)


def _sincos(x):
    """``(sin x, cos x)``: numpy's for a float too (``math`` may differ from numpy's loop in the last bit)."""
    if isinstance(x, float):
        a = np.array((x,))
        return np.sin(a).item(), np.cos(a).item()
    return np.sin(x), np.cos(x)


def _half_angle(t2):
    """``(x, sin x, cos x, s)`` with ``x = θ/2`` and ``s = sin x / x`` for each θ² of ``t2`` (lanes).

    ``s`` is its Taylor polynomial ``1 − x²/6 + x⁴/120`` below ``x = _SINC_TAYLOR`` (only to avoid 0/0 at
    rest: sin x / x has no cancellation) — the formulas of :func:`liesuslov.groups._rodrigues`.
    """
    x2 = 0.25 * t2
    x = math.sqrt(x2) if isinstance(x2, float) else np.sqrt(x2)
    sx, cx = _sincos(x)
    taylor = 1.0 - x2 * (1.0 / 6.0 - x2 / 120.0)
    if isinstance(x, float):
        return x, sx, cx, (taylor if x < _SINC_TAYLOR else sx / x)
    return x, sx, cx, np.divide(sx, x, out=taylor, where=~(x < _SINC_TAYLOR))


def _rodrigues_each(t2):
    """``(cos θ, sin θ/θ, (1 − cos θ)/θ²)`` for each θ² (lanes), accurate to rounding for every θ >= 0."""
    _, _, cx, s = _half_angle(t2)
    b = 0.5 * s * s
    return 1.0 - b * t2, s * cx, b


def _dexp3_each(t2, half: tuple | None = None):
    """``(1 − (θ/2) cot(θ/2)) / θ²`` (the exact so(3) dexp⁻¹ coefficient) for each θ² (lanes; ``half``: its
    :func:`_half_angle`, if at hand): the series below ``θ = _DEXP3_TAYLOR`` (the closed form cancels
    there), the closed form above."""
    if isinstance(t2, float):
        if t2 < _DEXP3_TAYLOR**2:
            return _dexp3_series(t2)
        x, sx, cx = half[:3] if half is not None else _half_angle(t2)[:3]
        return (1.0 - x * cx / sx) / t2
    c = _dexp3_series(t2)
    big = t2 >= _DEXP3_TAYLOR**2
    if big.any():  # the batch decides which elements are computed here, never their values
        if half is None:
            x = 0.5 * np.sqrt(t2[big])
            sx, cx = np.sin(x), np.cos(x)
        else:
            x, sx, cx = half[0][big], half[1][big], half[2][big]
        c[big] = (1.0 - x * cx / sx) / t2[big]
    return c


def _so3_exp_each(t2):
    """Rodrigues' three coefficients and the dexp⁻¹ coefficient (lanes), from one sine and one cosine of θ/2."""
    half = _half_angle(t2)
    cx, s = half[2], half[3]
    b = 0.5 * s * s
    return 1.0 - b * t2, s * cx, b, _dexp3_each(t2, half)


def _cos_sinc_each(t2) -> tuple:
    """``(cos θ, sin θ/θ)`` for each θ² (lanes): the so(4) exponential's factors ``exp P = cos|p| I + sinc|p| P``."""
    _, _, cx, s = _half_angle(t2)
    return 1.0 - 0.5 * s * s * t2, s * cx


def _rows_out(vals: tuple) -> np.ndarray:
    """(B, n) C-contiguous from n lanes (the model's input)."""
    return np.array([vals]) if isinstance(vals[0], float) else np.stack(vals, axis=-1)


def domain_bound2(chart: str) -> float:
    """The chart's domain as a bound on ``|Theta|_F²`` (of the block :func:`domain_block` says): ``2 pi²`` for the
    exponential (a rotation angle below pi: dexp⁻¹ has its first pole at 2 pi, and the closed forms lose accuracy
    past pi), ``2 L²`` for the Cayley map, ``L = 1/sqrt(eps)`` its numerical limit
    (:data:`liesuslov.groups.cayley._CAYLEY_LIMIT`). The compiled kernel tests ``|Theta|_F² / 2`` against the
    halves of the same numbers."""
    return 2.0 * (math.pi ** 2 if chart == "exp" else groups._CAYLEY_LIMIT ** 2)


def domain_block(algebra, m: int, skew: bool) -> int:
    """The size of the leading block of an algebra element (m×m) whose norm the chart's domain bounds: ``m``, or
    ``m - 1`` for an affine algebra (every element's last row zero, as se(n)'s): its translations, in the last
    column, do not enter the eigenvalues of ``ad_Theta`` (those of the leading block's, and 0), so they do not
    bring dexp⁻¹'s poles nearer; counting them rejected the steps of a fast-moving body (5x the steps)."""
    if skew or m < 2:
        return m
    rep = np.asarray(algebra.representation)
    return m - 1 if rep.shape[-2:] == (m, m) and not np.any(rep[:, -1, :]) else m


def _sq3(w: tuple):
    return w[0] * w[0] + w[1] * w[1] + w[2] * w[2]


def _matrices(entries: tuple, m: int) -> np.ndarray:
    """(B, m, m), C-contiguous, from the m*m entries (row-major), each a lane."""
    return _stack(entries, (m, m), (1,))


def _vee3(T: np.ndarray) -> tuple:
    """``w = (T21, T02, T10)`` of (B, 3, 3)."""
    return T[:, 2, 1], T[:, 0, 2], T[:, 1, 0]


def _hat3(w: tuple) -> np.ndarray:
    """(B, 3, 3) skew matrices from the lanes of w."""
    w0, w1, w2 = w
    z = 0.0 if isinstance(w0, float) else np.zeros_like(w0)
    return _matrices((z, -w2, w1, w2, z, -w0, -w1, w0, z), 3)


def _so4_pq(T: np.ndarray) -> tuple[tuple, tuple]:
    """The components of ``(p, q)`` (:func:`liesuslov.groups.so4_split`) of (B, 4, 4) skew matrices."""
    x01, x02, x03, x12, x13, x23 = T[:, 0, 1], T[:, 0, 2], T[:, 0, 3], T[:, 1, 2], T[:, 1, 3], T[:, 2, 3]
    return ((0.5 * (x01 + x23), 0.5 * (x02 - x13), 0.5 * (x03 + x12)),
            (0.5 * (x01 - x23), 0.5 * (x02 + x13), 0.5 * (x03 - x12)))


def _solve_each(A: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``A⁻¹ R`` for (B, m, m), (B, m, p): one LU solve per matrix, NaN for an exactly singular one.

    ``np.linalg.solve`` raises for the whole stack when one matrix is singular (``I − X/2`` of a diverged
    step, |X| ~ 1e49, or a NaN): the stack is then solved matrix by matrix (the same LAPACK call, so the
    same numbers), and the time loop fails that trajectory alone, with its time.
    """
    try:
        return np.linalg.solve(A, R)
    except np.linalg.LinAlgError:
        out = np.full(np.broadcast_shapes(A.shape[:-2], R.shape[:-2]) + R.shape[-2:], np.nan)
        A, R = np.broadcast_to(A, out.shape[:-2] + A.shape[-2:]), np.broadcast_to(R, out.shape)
        for b in range(out.shape[0]):
            try:
                out[b] = np.linalg.solve(A[b:b + 1], R[b:b + 1])[0]
            except np.linalg.LinAlgError:
                pass
        return out


_PADE_DEGREES = tuple(m for m, _ in _PADE_THETA)
_PADE_BOUNDS = np.array([theta for _, theta in _PADE_THETA[:-1]])  # degrees 3, 5, 7, 9 without scaling
_PADE_THETA13 = _PADE_THETA[-1][1]


def _expm_each(X: np.ndarray, nrm: np.ndarray) -> np.ndarray:
    """``exp`` of each matrix of X (B, m, m): scaling and squaring with diagonal Padé approximants (Higham 2005).

    As :func:`liesuslov.groups.expm`, except that the Padé degree, like the scaling exponent, is chosen per
    matrix from its own norm bound ``nrm`` (B,) — a consistent operator norm (the 1-norm; the 2-norm for
    normal matrices) — and not from the largest in the batch.
    """
    out = np.empty_like(X)
    deg = np.searchsorted(_PADE_BOUNDS, nrm)  # smallest degree whose bound holds; 4: degree 13 and scaling
    for d in np.unique(deg):
        rows = np.flatnonzero(deg == d)
        Xd = X if rows.size == X.shape[0] else X[rows]
        if d < 4:
            U, V = _pade_uv(Xd, _PADE_DEGREES[d])
            out[rows] = _solve_each(V - U, V + U)
            continue
        # frexp: nrm/θ13 = f 2^e with f in [0.5, 1), e = ceil(log2) (no warning on 0, inf or NaN)
        s = np.maximum(np.frexp(nrm[rows] / _PADE_THETA13)[1], 0)
        U, V = _pade_uv(Xd * np.ldexp(1.0, -s)[:, None, None], 13)
        R = _solve_each(V - U, V + U)
        for j in range(int(s.max())):
            R = np.where((s > j)[:, None, None], R @ R, R)
        out[rows] = R
    return out


def _one_norm(X: np.ndarray) -> np.ndarray:
    """The 1-norm (largest column sum of |X|) of each matrix, summed row after row."""
    col = np.abs(X[:, 0, :])
    for i in range(1, X.shape[1]):
        col = col + np.abs(X[:, i, :])
    return col.max(axis=-1)


def _expm_skew_each(T: np.ndarray) -> np.ndarray:
    """``exp`` of skew (B, m, m): Rodrigues (m = 3), two Rodrigues factors (m = 4), Padé (m >= 5), per matrix."""
    m = T.shape[-1]
    if m == 3:
        w = _vee3(T)
        return _so3_mat(*_rodrigues_each(_sq3(w)), w, (T.shape[0],))
    if m == 4:
        p, q = _so4_pq(T)
        return _matrices(_so4_exp_mat_c(_cos_sinc_each(_sq3(p)) + _cos_sinc_each(_sq3(q)), p, q), 4)
    X = np.ascontiguousarray(T)
    return _expm_each(X, np.sqrt(0.5 * np.sum(X * X, axis=(-2, -1))))  # |X|_2 <= |X|_F / sqrt 2 (skew)


def _cayley_each(T: np.ndarray, skew: bool) -> np.ndarray:
    """``cay(T) = (I − T/2)⁻¹ (I + T/2)`` of each matrix: closed forms on so(3), so(4), else one solve each.

    On so(n), n >= 5, a matrix with ``|T| > 100`` (a diverging step) is put back on SO(n) by the polar
    factor of its SVD, as :func:`liesuslov.groups.cayley_skew` does — here matrix by matrix.
    """
    m = T.shape[-1]
    if skew and m == 3:
        w = _vee3(T)
        return _so3_mat(*_cayley_coefficients(_sq3(w)), w, (T.shape[0],))
    if skew and m == 4:
        p, q = _so4_pq(T)
        return _matrices(_so4_mat_c(_so4_cayley_coefficients(p, q), p, q), 4)
    H = 0.5 * T
    C = _solve_each(_eye(m) - H, _eye(m) + H)
    if skew:
        big = (np.abs(T).max(axis=(-2, -1)) > groups._CAYLEY_POLISH) & np.isfinite(C).all(axis=(-2, -1))
        if big.any():
            U, _, Vt = np.linalg.svd(C[big])
            C[big] = U @ Vt
    return C


class _RowMap:
    """``y_c = sum_j R[j, c] x_j`` on lanes x (k of them) -> q lanes.

    A fixed-order sum of elementwise products per output component, the zero coefficients skipped and the
    ±1 ones not multiplied (exact either way): Omega(xi) is a sparse signed permutation of xi in most
    scenes. A matrix product here would take the batch as a BLAS dimension and round with B.
    """

    def __init__(self, R: np.ndarray) -> None:
        self.terms = [[(j, float(R[j, c])) for j in range(R.shape[0]) if R[j, c] != 0.0] for c in range(R.shape[1])]

    def __call__(self, x: tuple) -> tuple:
        out = []
        for terms in self.terms:
            acc = None
            for j, r in terms:
                term = x[j] if r == 1.0 else (-x[j] if r == -1.0 else r * x[j])
                acc = term if acc is None else acc + term
            out.append((0.0 if isinstance(x[0], float) else np.zeros_like(x[0])) if acc is None else acc)
        return tuple(out)


# ====================================================================================== kernels
class _Context:
    """What a kernel keeps through one trial step of a batch (and its extension and dense states).

    Attributes
    ----------
    gam0 : (B, n) or None
        The body vertical at the start of the step (C-contiguous).
    V : (n, B) or None
        The same, component-major (component kernels).
    Q : (B, n, r) or None
        The low-rank basis built so far, and ``cols`` its number of columns (the same for every trajectory).
    """

    __slots__ = ("gam0", "V", "Q", "cols")

    def __init__(self, gam0=None, V=None, Q=None, cols=0) -> None:
        self.gam0, self.V, self.Q, self.cols = gam0, V, Q, cols

    def take(self, rows: np.ndarray) -> _Context:
        """The context of the trajectories ``rows`` (indices, possibly repeated): copies."""
        return _Context(None if self.gam0 is None else self.gam0[rows],
                        None if self.V is None else self.V[:, rows],
                        None if self.Q is None else self.Q[rows], self.cols)


def _start_vertical(G: np.ndarray, gamma: np.ndarray | None, mode: str) -> np.ndarray | None:
    """The body vertical at the start of a step: G itself (mode "gamma"), ``g^T gamma`` (mode "g"), or None."""
    if mode == "gamma":
        return np.ascontiguousarray(G)
    return None if gamma is None else body_vertical(G, gamma)


class _Kernel:
    """Protocol of a kernel (the stepper calls only these; ``ctx`` is what :meth:`begin` returns, ``t``
    what :meth:`load` returns). B is the batch of the arrays given; rows ``(q, B)`` are component-major.

    * ``q``: numbers per trajectory in a row.
    * ``begin(G, gamma, mode) -> ctx``: once per step, before stage 0 (the body vertical, the basis).
    * ``omega(ctx, Xi, X) -> om``: Omega at a stage, from its xi part as rows ``Xi`` (k, B) or as the
      contiguous ``X`` (B, 1, k) the model is given; ``first(om, out)``: write ``K_0 = Omega_0`` to a row.
    * ``load(ctx, flat) -> t``: the stage value ``Theta_i`` from its (q, B) part of a stage sum;
      ``domain_norm2(t)``: ``|Theta|_F²`` (of the leading block, :func:`domain_block`), which the stepper
      compares with the chart's :func:`domain_bound2`; (B,) (a float for float lanes).
    * ``act(ctx, t)``: ``phi(-Theta) Gamma0``, (B, n) C-contiguous (the model's input).
    * ``dinv(ctx, t, om, out)``: write ``K_i = dphi^{-1}_{-Theta_i}(Omega_i)`` to a row (q, B).
    * ``advance(ctx, G, t)``: ``G phi(Theta)``, (B, m, m), for the attitude.
    * ``matrix(ctx, flat)``: the increment as (B, m, m) matrices (the error estimate carried to the state).
    """

    q = 0


class _MatrixKernel(_Kernel):
    """Shared by the kernels whose stage values are matrices: the chart's maps on (B, m, m) stacks."""

    def _phi(self, T: np.ndarray) -> np.ndarray:
        if self.exp:
            return _expm_skew_each(T) if self.skew else _expm_each(T, _one_norm(T))
        return _cayley_each(T, self.skew)

    def _act_matrix(self, T: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``phi(-T) v``, (B, m, m), (B, m) -> (B, m)."""
        if self.skew:  # phi(-T) = phi(T)^T (orthogonal): a row vector times phi(T)
            return np.matmul(v[:, None, :], self._phi(T))[:, 0, :]
        if self.exp:
            return np.matmul(_expm_each(-T, _one_norm(T)), v[:, :, None])[:, :, 0]
        H = 0.5 * T  # cay(-T) v = (I + T/2)⁻¹ (v − T v / 2): one solve with a vector right-hand side
        rhs = v - np.matmul(H, v[:, :, None])[:, :, 0]
        return _solve_each(_eye(self.m) + H, rhs[:, :, None])[:, :, 0]

    @staticmethod
    def _norm2(X: np.ndarray) -> np.ndarray:
        """Sum of squares of each matrix of a C-contiguous stack (along its own numbers)."""
        return np.sum((X * X).reshape(X.shape[0], -1), axis=-1)


class _DenseKernel(_MatrixKernel):
    """m×m matrices (q = m*m, row-major); Omega(xi) by one stacked product with the basis."""

    def __init__(self, chart: Chart, model, slots: int, need_act: bool) -> None:
        m = chart.m
        self.chart, self.m, self.q = chart, m, m * m
        self.exp, self.skew, self.terms = chart.name == "exp", chart.skew, chart.terms
        self.R = _omega_basis(model, m)
        self.omega_matrix = model.omega_matrix
        self.dom = domain_block(model.algebra, m, self.skew)

    def begin(self, G, gamma, mode) -> _Context:
        return _Context(gam0=_start_vertical(G, gamma, mode))

    def omega(self, ctx, Xi, X) -> np.ndarray:
        if self.R is None:
            return np.ascontiguousarray(self.omega_matrix(X)[:, 0])
        return np.matmul(X, self.R).reshape(-1, self.m, self.m)

    def first(self, om, out) -> None:
        out[...] = om.reshape(-1, self.q).T

    def load(self, ctx, flat) -> np.ndarray:
        return np.ascontiguousarray(flat.T).reshape(-1, self.m, self.m)

    def domain_norm2(self, T) -> np.ndarray:
        return self._norm2(T if self.dom == self.m else np.ascontiguousarray(T[:, :self.dom, :self.dom]))

    def act(self, ctx, T) -> np.ndarray:
        return self._act_matrix(T, ctx.gam0)

    def dinv(self, ctx, T, om, out) -> None:
        if not self.exp:  # (I + T/2) A (I - T/2) = M - M T / 2 with M = A + T A / 2 (two products)
            M = om + 0.5 * np.matmul(T, om)
            K = M - 0.5 * np.matmul(M, T)
        elif self.skew and self.m == 3:  # exact: a + ½ θ × a + c(θ) θ × (θ × a) on the vectors
            w = _vee3(T)
            t2 = _sq3(w)
            c = _dexp3_each(t2)
            K = _hat3(_so3_lin_c(1.0 - c * t2, 0.5, c, w, _vee3(om)))
        else:
            K = groups.dexpinv(T, om, self.terms, side="right", skew=self.skew)
        out[...] = K.reshape(-1, self.q).T

    def advance(self, ctx, G, T) -> np.ndarray:
        return np.matmul(G, self._phi(T))

    def matrix(self, ctx, flat) -> np.ndarray:
        return self.load(ctx, flat)


class _CoordsKernel(_MatrixKernel):
    """so(n) elements as their d coordinates; ``dexp^{-1}`` by powers of the d×d matrix ``ad_Theta``.

    The truncated series ``sum_k (B_k/k!) ad^k_Theta Omega`` (right side) costs one product to build
    ``ad_Theta = theta @ C`` from the structure constants and one matrix-vector product per power,
    instead of three matrix operations per bracket; Theta is assembled as a matrix (one product) only
    for the exponential itself. For small n (d³ flops per stage, n <= :data:`COORDS_MAX_N`).
    """

    def __init__(self, chart: Chart, model, slots: int, need_act: bool) -> None:
        from ..algebra import so

        m = chart.m
        alg = so(m)
        d = alg.dim
        self.chart, self.m, self.d, self.q = chart, m, d, d
        self.exp, self.skew = chart.name == "exp", True
        idx = alg._rows * m + alg._cols  # coordinate of E_ij = entry (i, j), i < j
        self.idx = idx
        self.R = np.ascontiguousarray(_omega_basis(model, m)[:, idx])  # (k, d)
        self.E = np.ascontiguousarray(alg.representation.reshape(d, m * m))  # hat: theta @ E
        # ad_theta[k, j] = sum_i theta_i C[i, j, k]: one product with C transposed to (i, k, j)
        self.C = np.ascontiguousarray(alg.structure_constants.transpose(0, 2, 1).reshape(d, d * d))
        terms = groups.bernoulli_coefficients(chart.terms)
        self.coef = [(k, -c if k == 1 else c) for k, c in terms]  # right side: the odd term changes sign
        self.K = max(k for k, _ in terms)  # highest power of ad needed

    def begin(self, G, gamma, mode) -> _Context:
        return _Context(gam0=_start_vertical(G, gamma, mode))

    def omega(self, ctx, Xi, X) -> np.ndarray:
        return np.matmul(X, self.R)[:, 0, :]

    def first(self, om, out) -> None:
        out[...] = om.T

    def load(self, ctx, flat):
        th = np.ascontiguousarray(flat.T)
        return th, np.matmul(th[:, None, :], self.E).reshape(-1, self.m, self.m)

    def domain_norm2(self, t) -> np.ndarray:
        return 2.0 * np.sum(t[0] * t[0], axis=-1)  # |X|_F² = 2 |x|²

    def act(self, ctx, t) -> np.ndarray:
        return self._act_matrix(t[1], ctx.gam0)

    def dinv(self, ctx, t, om, out) -> None:
        th, T = t
        if not self.exp:  # (I + T/2) A (I - T/2) on matrices, back to coordinates
            A = np.matmul(om[:, None, :], self.E).reshape(T.shape)
            M = A + 0.5 * np.matmul(T, A)
            out[...] = (M - 0.5 * np.matmul(M, T)).reshape(-1, self.m * self.m)[:, self.idx].T
            return
        ad = np.matmul(th[:, None, :], self.C).reshape(-1, self.d, self.d)
        powers = [om]  # ad^k omega, k = 0 … K, one stacked matrix-vector product each
        for _ in range(self.K):
            powers.append(np.matmul(ad, powers[-1][:, :, None])[:, :, 0])
        K = powers[0]
        for k, c in self.coef[1:]:  # coef[0] is (0, 1.0)
            K = K + c * powers[k]
        out[...] = K.T

    def advance(self, ctx, G, t) -> np.ndarray:
        return np.matmul(G, self._phi(t[1]))

    def matrix(self, ctx, flat) -> np.ndarray:
        return self.load(ctx, flat)[1]


class _ComponentKernel(_Kernel):
    """Kernels that hold each stage value as ``q`` components, each a lane (a (B,) row, or a float for
    B = 1; see the maps above); ``R`` (k, q) maps reduced coordinates to the components."""

    def _setup(self, chart: Chart, R: np.ndarray, need_act: bool) -> None:
        self.omega_rows = _RowMap(R)
        self.exp = chart.name == "exp"
        self.need_act = need_act

    def begin(self, G, gamma, mode) -> _Context:
        Gam0 = _start_vertical(G, gamma, mode)
        return _Context(V=None if Gam0 is None else np.ascontiguousarray(Gam0.T))

    def omega(self, ctx, Xi, X) -> tuple:
        return self.omega_rows(_lanes(Xi))

    def first(self, om, out) -> None:
        for c, x in enumerate(om):
            out[c] = x

    def advance(self, ctx, G, t) -> np.ndarray:
        """``G phi(Theta)`` row by row: row i is ``g_i phi(Theta) = phi(Theta)^T g_i = phi(-Theta) g_i`` (phi
        orthogonal), the map :meth:`act` applies to the vertical — by components, on lanes, with no 3×3 or
        4×4 product per trajectory (numpy's stacked products cost ~100 ns per matrix)."""
        m = G.shape[-1]
        if G.shape[0] == 1:
            rows = [tuple(r) for r in G.reshape(m, m).tolist()]
        else:
            GT = np.ascontiguousarray(G.transpose(1, 2, 0))  # (m, m, B): row i, component j, along the batch
            rows = [tuple(GT[i]) for i in range(m)]
        apply = self._inverse_map(t)
        return _matrices(tuple(x for row in rows for x in apply(row)), m)


class _So3Kernel(_ComponentKernel):
    """so(3): rotation vectors ``w``, closed forms by components."""

    q = 3

    def __init__(self, chart: Chart, model, slots: int, need_act: bool) -> None:
        # w = (X21, X02, X10) of each basis element
        self._setup(chart, _omega_basis(model, 3)[:, [7, 2, 3]], need_act)

    def load(self, ctx, flat):
        w = _lanes(flat)
        t2 = _sq3(w)
        if not self.exp:
            co = _cayley_coefficients(t2)  # (c, a, b): cay = c I + a hat w + b w w^T
        elif self.need_act:
            co = _so3_exp_each(t2)  # Rodrigues' (c, a, b) and the dexp⁻¹ coefficient, one sin and cos
        else:
            co = (None, None, None, _dexp3_each(t2))
        return w, t2, co

    def domain_norm2(self, t) -> np.ndarray:
        return 2.0 * t[1]  # |hat w|_F² = 2 |w|²

    def _inverse_map(self, t):
        """``v -> phi(-Theta) v = c v - a w × v + b (w·v) w`` on lanes, from Theta's coefficients."""
        w, t2, co = t
        c, a, b = co[:3] if co[0] is not None else _rodrigues_each(t2)
        return lambda v: _so3_lin_c(c, -a, b, w, v)

    def act(self, ctx, t) -> np.ndarray:
        return _rows_out(self._inverse_map(t)(_lanes(ctx.V)))

    def dinv(self, ctx, t, om, out) -> None:
        w, t2, co = t
        if self.exp:  # right side: a + ½ θ × a + c(θ) θ × (θ × a), exact
            vals = _so3_lin_c(1.0 - co[3] * t2, 0.5, co[3], w, om)
        else:  # (I + Θ/2) Ω (I − Θ/2) = a + ½ θ × a + ¼ (θ·a) θ
            vals = _so3_lin_c(1.0, 0.5, 0.25, w, om)
        out[0], out[1], out[2] = vals

    def matrix(self, ctx, flat) -> np.ndarray:
        return _hat3(_lanes(flat))


class _So4Kernel(_ComponentKernel):
    """so(4) = so(3) ⊕ so(3): the pair ``(p, q)`` (component-major), closed forms by components."""

    q = 6

    def __init__(self, chart: Chart, model, slots: int, need_act: bool) -> None:
        W = _omega_basis(model, 4)
        # flat matrix -> (p, q): p = ½ (X01 + X23, X02 − X13, X03 + X12), q = ½ (X01 − X23, X02 + X13, X03 − X12)
        T = np.zeros((16, 6))
        for col, (i, j, sgn) in enumerate(((1, 11, 1), (2, 7, -1), (3, 6, 1), (1, 11, -1), (2, 7, 1), (3, 6, -1))):
            T[i, col], T[j, col] = 0.5, 0.5 * sgn
        self._setup(chart, W @ T, need_act)
        self.half, self.poly = _dexpinv_so3_series(chart.terms)

    def load(self, ctx, flat):
        c = _lanes(flat)
        return c[:3], c[3:]

    def domain_norm2(self, t) -> np.ndarray:
        return 4.0 * (_sq3(t[0]) + _sq3(t[1]))  # |X|_F² = 4 (|p|² + |q|²)

    def _coefficients(self, p: tuple, q: tuple) -> tuple:
        """``phi(X) = c0 I + c1 P + c2 Q + c3 PQ`` (Cayley), or ``(cos|p|, sinc|p|, cos|q|, sinc|q|)`` (exp)."""
        if self.exp:
            return _cos_sinc_each(_sq3(p)) + _cos_sinc_each(_sq3(q))
        return _so4_cayley_coefficients(p, q)

    def _inverse_map(self, t):
        """``v -> phi(-X) v`` on lanes (X ↔ (p, q)), from its coefficients."""
        p, q = t
        c = self._coefficients(p, q)
        apply = _so4_exp_apply_c if self.exp else _so4_lin_apply_c
        return lambda v: apply(c, p, q, v, -1.0)

    def act(self, ctx, t) -> np.ndarray:
        return _rows_out(self._inverse_map(t)(_lanes(ctx.V)))

    def dinv(self, ctx, t, om, out) -> None:
        p, q = t
        ap, aq = om[:3], om[3:]
        a2, b2 = _sq3(p), _sq3(q)
        if self.exp:  # the truncated series on each factor
            cp = _dexpinv_so3_poly(4.0 * a2, self.poly)
            cq = _dexpinv_so3_poly(4.0 * b2, self.poly)
            vals = _so4_dexpinv_c(self.half, cp, cq, a2, b2, p, q, ap, aq)
        else:  # exact: (I + Θ/2) Ω (I − Θ/2)
            vals = _so4_dcayinv_c(a2, b2, p, q, ap, aq)
        for j in range(6):
            out[j] = vals[j]

    def matrix(self, ctx, flat) -> np.ndarray:
        p, q = self.load(ctx, flat)
        return _matrices(_so4_mat_c((0.0, 1.0, 1.0, 0.0), p, q), 4)


class _LowRankKernel(_MatrixKernel):
    """Fedorov–Kozlov models: stage values ``Q M Q^T`` in a per-step orthonormal basis ``Q`` (see the module docstring).

    ``Q`` (B, n, r), r = slots + 1: column 0 is ``e_n``, column ``i + 1`` the part of stage i's
    ``u = (xi, 0)`` orthogonal to the previous columns (classical Gram–Schmidt, twice; a ``u`` already in
    the span to rounding adds a zero column, which the zero rows and columns of every M ignore). With
    ``u = Q c``: ``Omega = u ∧ e_n = Q (c ∧ e_0) Q^T``. Brackets, dexp⁻¹ and dcay⁻¹ act on the r×r
    coordinates M (``[Q A Q^T, Q B Q^T] = Q [A, B] Q^T``), ``phi(Q M Q^T) = I + Q (phi(M) - I) Q^T``,
    and ``|Q E Q^T|_F = |E|_F``.
    """

    def __init__(self, chart: Chart, model, slots: int, need_act: bool) -> None:
        n = int(model.n)
        r = slots + 1
        self.chart, self.n, self.r, self.q = chart, n, r, r * r
        self.exp, self.skew, self.terms = chart.name == "exp", True, chart.terms

    def begin(self, G, gamma, mode) -> _Context:
        Gam0 = _start_vertical(G, gamma, mode)
        B = (Gam0 if Gam0 is not None else G).shape[0]
        Q = np.zeros((B, self.n, self.r))
        Q[:, self.n - 1, 0] = 1.0
        return _Context(gam0=Gam0, Q=Q, cols=1)

    def omega(self, ctx, Xi, X) -> np.ndarray:
        j = ctx.cols
        ctx.cols = j + 1
        u = X[:, 0, :]  # (B, n - 1): the u-part of Omega = u ∧ e_n
        Qu = ctx.Q[:, : self.n - 1, :]  # the u-part (rows 0..n-2) of the columns
        c = np.matmul(u[:, None, :], Qu)[:, 0, :]  # (B, r): Q^T u
        w = u - np.matmul(Qu, c[:, :, None])[:, :, 0]
        rho1 = np.sqrt(np.sum(w * w, axis=-1))
        c2 = np.matmul(w[:, None, :], Qu)[:, 0, :]  # second pass (Kahan: twice is enough)
        w = w - np.matmul(Qu, c2[:, :, None])[:, :, 0]
        c = c + c2
        rho = np.sqrt(np.sum(w * w, axis=-1))
        # a second pass that removes more than half means u was in the span to rounding: no new direction
        keep = rho > 0.5 * rho1
        c[:, j] = np.where(keep, rho, 0.0)
        Qu[:, :, j] = w * np.divide(1.0, rho, out=np.zeros_like(rho), where=keep)[:, None]
        M = np.zeros((u.shape[0], self.r, self.r))
        M[:, :, 0] = c
        M[:, 0, :] = -c
        return M

    def first(self, om, out) -> None:
        out[...] = om.reshape(-1, self.q).T

    def load(self, ctx, flat) -> np.ndarray:
        return np.ascontiguousarray(flat.T).reshape(-1, self.r, self.r)

    def domain_norm2(self, M) -> np.ndarray:
        return self._norm2(M)  # |Q M Q^T|_F = |M|_F

    def _phi_active(self, ctx, M) -> np.ndarray:
        """``phi`` of the block of M on the columns built so far (Theta_i lies in their span)."""
        ra = ctx.cols
        return self._phi(np.ascontiguousarray(M[:, :ra, :ra]))

    def act(self, ctx, M) -> np.ndarray:
        Qa = ctx.Q[:, :, : ctx.cols]
        y = np.matmul(ctx.gam0[:, None, :], Qa)  # (B, 1, ra): Q^T Gamma0 as a row
        z = np.matmul(y, self._phi_active(ctx, M)) - y  # (phi(-M) - I) Q^T Gamma0, as a row: phi(-M) = phi(M)^T
        return ctx.gam0 + np.matmul(z, np.swapaxes(Qa, -1, -2))[:, 0, :]

    def dinv(self, ctx, M, om, out) -> None:
        if self.exp:
            K = groups.dexpinv(M, om, self.terms, side="right", skew=True)
        else:
            P = om + 0.5 * np.matmul(M, om)
            K = P - 0.5 * np.matmul(P, M)
        out[...] = K.reshape(-1, self.q).T

    def advance(self, ctx, G, M) -> np.ndarray:
        Qa = ctx.Q[:, :, : ctx.cols]
        F = self._phi_active(ctx, M) - _eye(ctx.cols)
        return G + np.matmul(np.matmul(np.matmul(G, Qa), F), np.swapaxes(Qa, -1, -2))

    def matrix(self, ctx, flat) -> np.ndarray:
        Q = ctx.Q
        return np.matmul(np.matmul(Q, self.load(ctx, flat)), np.swapaxes(Q, -1, -2))
