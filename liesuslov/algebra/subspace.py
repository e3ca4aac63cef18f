"""Linear subspaces of a Lie algebra: the fibres D of left-invariant distributions.

A nonholonomic constraint ``<a^i, Omega> = 0`` (i = 1..r) confines the body angular velocity to
``D = {x : A x = 0}``; the distribution is nonholonomic iff D is not a subalgebra. Everything
here is in coordinates with the algebra's pairing (the Euclidean product of coordinates, which on
so(n) is -1/2 tr(AB)).
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

import numpy as np

from .._rows import rows_at, vectors
from .._validation import as_float_array, check_symmetric
from .lie import LieAlgebra

__all__ = ["Subspace", "is_symmetric_pair", "suslov_distribution", "SymmetricOperator"]


@runtime_checkable
class SymmetricOperator(Protocol):
    """A symmetric operator on the algebra given by its matrix ``K`` (d, d) in the algebra's basis — an
    :class:`~liesuslov.algebra.inertia.Inertia` (which this layer cannot import: it imports this one)."""

    @property
    def matrix(self) -> np.ndarray: ...

_RANK_TOL = 1e-10
#: Largest dimension d for which :meth:`Subspace.contains` keeps the (d, d) residual projector.
_PROJECTOR_MAX_DIM = 128
#: Largest dimension d for which :meth:`Subspace.contains` tests one vector of a coordinate subspace on
#: Python floats.
_PYTHON_MAX_DIM = 32


class Subspace:
    """A linear subspace of a Lie algebra, with an orthonormal basis.

    Parameters
    ----------
    algebra : LieAlgebra
    rows : array_like, shape (k, d) or (d,)
        Spanning vectors in coordinates (they may be dependent). Orthonormal rows are kept as the
        basis unchanged (so they define the reduced coordinates ``xi``); otherwise the basis is the
        canonical one: the Gram–Schmidt orthonormalisation, in index order, of the projections of
        the coordinate axes that are best conditioned — for a coordinate subspace that is exactly
        its coordinate axes.
    tol : float
        Relative tolerance of rank decisions and membership tests.

    Attributes
    ----------
    basis : ndarray, shape (k, d)
        Orthonormal rows; ``x = xi @ basis`` for ``x`` in the subspace.
    dim : int
    """

    def __init__(self, algebra: LieAlgebra, rows, *, tol: float = _RANK_TOL) -> None:
        if not isinstance(algebra, LieAlgebra):
            raise TypeError(f"algebra must be a LieAlgebra (e.g. ls.so(4)), got {type(algebra).__name__}")
        d = algebra.dim
        B = as_float_array(rows, "rows")
        if B.ndim == 1:
            B = B[None, :]
        if B.ndim != 2 or B.shape[1] != d:
            raise ValueError(f"rows must have shape (k, {d}) for {algebra.name}, got {np.shape(rows)}")
        self.algebra = algebra
        self.tol = float(tol)
        if B.shape[0] and np.allclose(B @ B.T, np.eye(B.shape[0]), rtol=0, atol=1e-12):
            basis = B.copy()
        else:
            basis = _canonical_basis(_span(B, tol), d)
        basis.setflags(write=False)
        self.basis = basis

    @classmethod
    def annihilator(cls, algebra: LieAlgebra, covectors, *, tol: float = _RANK_TOL) -> Subspace:
        """``D = {x : A x = 0}`` for constraint covectors ``A`` of shape (r, d) (or (d,)).

        Raises
        ------
        ValueError
            If the covectors are linearly dependent (remove the redundant constraints) or of the
            wrong shape.
        """
        if not isinstance(algebra, LieAlgebra):
            raise TypeError(f"algebra must be a LieAlgebra (e.g. ls.so(4)), got {type(algebra).__name__}")
        A = as_float_array(covectors, "covectors")
        if A.ndim == 1:
            A = A[None, :]
        d = algebra.dim
        if A.ndim != 2 or A.shape[1] != d:
            raise ValueError(f"covectors must have shape (r, {d}) for {algebra.name}, got {np.shape(covectors)}")
        if A.shape[0] > 0:
            s = np.linalg.svd(A, compute_uv=False)
            rank = int(np.sum(s > tol * s[0])) if s[0] > 0 else 0
            if rank < A.shape[0]:
                raise ValueError(f"covectors are linearly dependent: rank {rank} < {A.shape[0]} constraints; "
                                 "remove the redundant rows (each constraint must be independent)")
        null = _scipy_linalg().null_space(A) if A.shape[0] else np.eye(d)
        return cls(algebra, _canonical_basis(null.T, d), tol=tol)

    # ------------------------------------------------------------------ data
    @property
    def dim(self) -> int:
        """Dimension k of the subspace."""
        return self.basis.shape[0]

    @property
    def covectors(self) -> np.ndarray:
        """Orthonormal constraint covectors: a basis of the annihilator, shape (d - k, d)."""
        return self.complement().basis

    def __repr__(self) -> str:
        return f"Subspace({self.algebra.name}, dim={self.dim})"

    # ------------------------------------------------------------------ geometry
    def contains(self, x, tol: float | None = None, atol: float = 0.0) -> np.ndarray:
        """Membership test ``|x - P x|^2 <= (tol |x|)^2 + atol^2``, batched: (..., d) -> bool (...).

        Relative to ``|x|`` (the default ``tol`` is ten times the subspace's rank tolerance), so that it
        does not change with the scale of x; ``atol`` is for vectors that may vanish to rounding (brackets,
        whose scale is the algebra's :attr:`~.lie.LieAlgebra.bracket_scale`, not their own).

        The residual ``r = x - P x``: for one vector of a coordinate subspace with d <= :data:`_PYTHON_MAX_DIM`,
        x's entries off D's axes (on Python floats: the front door tests every Omega0); else through the
        complement's projector ``I - B^T B`` (d, d) when d <= :data:`_PROJECTOR_MAX_DIM` (one matrix-vector
        product), else through the basis (O(k d), not the d - k covectors: d - k ~ d^2/2 on so(n) with
        Fedorov–Kozlov constraints); squared norms on both sides.
        """
        x = vectors(x, "x", self.algebra.dim)
        tol = self.tol * 10 if tol is None else tol
        bound = tol * tol
        floor = atol * atol
        if x.ndim == 1 and x.shape[0] <= _PYTHON_MAX_DIM:
            outside = self._outside_axes()
            if outside is not None:
                # one short vector, coordinate subspace (every scene of the paper): r = x off D's axes, on
                # Python floats (~1.5 µs where the projector's product costs ~4 µs, ~10 µs after a cold start)
                vals = x.tolist()
                r2 = 0.0
                for i in outside:
                    r2 += vals[i] * vals[i]
                x2 = 0.0
                for v in vals:
                    x2 += v * v
                if x2 == math.inf:  # squares beyond the floats (|x| > 1e154): inf <= inf accepted anything
                    return self._contains_huge(x, tol)
                return np.bool_(r2 <= bound * x2 + floor)
        # (overflowing squares are caught below, not warned about: ~1 µs)
        with np.errstate(over="ignore", invalid="ignore"):
            if x.ndim == 1 and x.shape[0] <= _PROJECTOR_MAX_DIM:  # (one vector: ~4 µs; the batch form took ~10 µs)
                r = self._residual_projector() @ x
                x2 = float(x @ x)
                if x2 == math.inf:
                    return self._contains_huge(x, tol)
                return np.bool_(float(r @ r) <= bound * x2 + floor)
            r = x - (x @ self.basis.T) @ self.basis
            x2 = np.add.reduce(x * x, axis=-1)
            out = np.add.reduce(r * r, axis=-1) <= bound * x2 + floor
        huge = x2 == math.inf
        if np.any(huge):
            if out.ndim == 0:  # one long vector (d above the projector's size)
                return np.bool_(self._contains_huge(x, tol))
            out[huge] = self._contains_huge(x[huge], tol)
        return out

    def _contains_huge(self, x: np.ndarray, tol: float) -> np.ndarray:
        """:meth:`contains` of vectors whose squares overflow, scaled to their largest entry first (the test is
        relative; ``atol`` is nothing beside such a vector). An infinite entry stays refused (inf/inf is NaN)."""
        with np.errstate(invalid="ignore", over="ignore"):
            return self.contains(x / np.max(np.abs(x), axis=-1, keepdims=True), tol=tol)

    def _outside_axes(self) -> tuple[int, ...] | None:
        """The coordinate axes off D when D is a coordinate subspace (basis rows ±e_i), else None; kept.

        For such a D the residual ``x - B^T B x`` is x on these axes and 0 on D's own, exactly."""
        if "_outside" not in self.__dict__:
            B = self.basis
            nz = B != 0
            coordinate = bool(np.all(nz.sum(axis=1) == 1) and np.all(np.abs(B[nz]) == 1.0))
            axes = set(np.argmax(nz, axis=1).tolist()) if B.shape[0] else set()
            self._outside = tuple(i for i in range(self.algebra.dim) if i not in axes) if coordinate else None
        return self._outside

    def _residual_projector(self) -> np.ndarray:
        """``I - B^T B`` (d, d), kept: ``x - P x`` for the orthonormal basis rows B."""
        R = self.__dict__.get("_residual")
        if R is None:
            d = self.algebra.dim
            R = self._residual = np.eye(d) - self.basis.T @ self.basis
            R.setflags(write=False)
        return R

    def complement(self) -> Subspace:
        """The orthogonal complement for the pairing (the span of the constraint covectors)."""
        d = self.algebra.dim
        if self.dim == 0:
            return Subspace(self.algebra, np.eye(d), tol=self.tol)
        B = self.basis
        nz = B != 0
        if np.all(nz.sum(axis=1) == 1):  # coordinate subspace (e.g. Fedorov-Kozlov): O(k d), no SVD
            rest = np.ones(d, dtype=bool)
            rest[np.argmax(nz, axis=1)] = False
            return Subspace(self.algebra, np.eye(d)[rest], tol=self.tol)
        null = _scipy_linalg().null_space(B) if self.dim < d else np.zeros((d, 0))
        return Subspace(self.algebra, _canonical_basis(null.T, d), tol=self.tol)

    def coordinates(self, x) -> np.ndarray:
        """Coordinates ``xi = x @ basis.T`` of (the orthogonal projection of) x: (..., d) -> (..., k), each row
        summed alone (:func:`~liesuslov._rows.rows_at`)."""
        return rows_at(vectors(x, "x", self.algebra.dim), self.basis.T)

    def from_coordinates(self, xi) -> np.ndarray:
        """``x = xi @ basis``: (..., k) -> (..., d), each row summed alone."""
        return rows_at(vectors(xi, "xi", self.dim), self.basis)

    def projector(self, metric=None) -> np.ndarray:
        """Matrix ``P`` (d, d) of the projection onto the subspace, acting on columns (``P @ x``).

        Parameters
        ----------
        metric : None, array_like (d, d) or Inertia
            None: the orthogonal projector ``B^T B`` for the pairing (symmetric). An SPD matrix K
            (or an :class:`~liesuslov.algebra.inertia.Inertia`): the K-orthogonal projector
            ``P_K = B^T (B K B^T)^{-1} B K``, self-adjoint for ``<x, y>_K = x^T K y``. With K the
            inertia, ``P_K K^{-1} F`` is the acceleration that the constraint reaction leaves of
            a force F: the reaction lies in the annihilator and is removed exactly.
        """
        B = self.basis
        if metric is None:
            return B.T @ B
        K = metric.matrix if isinstance(metric, SymmetricOperator) else as_float_array(metric, "metric")
        d = self.algebra.dim
        if K.shape != (d, d):
            raise ValueError(f"metric must have shape ({d}, {d}), got {K.shape}")
        check_symmetric(K, "metric")
        if np.linalg.eigvalsh(0.5 * (K + K.T))[0] <= 0:
            raise ValueError("metric must be positive definite (an inertia matrix or another SPD K)")
        if self.dim == 0:
            return np.zeros((d, d))
        return B.T @ np.linalg.solve(B @ K @ B.T, B @ K)

    def project(self, x, metric=None) -> np.ndarray:
        """Apply :meth:`projector` to a batch of vectors: (..., d) -> (..., d), each row summed alone."""
        return rows_at(vectors(x, "x", self.algebra.dim), self.projector(metric).T)

    def distance(self, x) -> np.ndarray:
        """``|x - P x|``, the distance of each vector to the subspace: (..., d) -> (...); no overflow for huge x
        (a hypotenuse, not a root of squares: 1e160 vectors read inf)."""
        x = vectors(x, "x", self.algebra.dim)
        s = np.max(np.abs(x), axis=-1, keepdims=True, initial=0.0)
        s = np.where(s > 0.0, s, 1.0)
        y = x / s
        return np.linalg.norm(y - self.project(y), axis=-1) * s[..., 0]

    # ------------------------------------------------------------------ Lie structure
    def _pair_brackets(self, U: np.ndarray, V: np.ndarray) -> np.ndarray:
        return self.algebra.bracket(U[:, None, :], V[None, :, :]).reshape(-1, self.algebra.dim)

    def _brackets_in(self, brackets: np.ndarray, tol: float | None) -> bool:
        """Every bracket of unit vectors in this subspace, to ``tol`` relative to the algebra's bracket scale
        (a bracket that vanishes is computed as rounding noise of that scale, not of its own)."""
        tol = self.tol * 10 if tol is None else tol
        return bool(np.all(self.contains(brackets, tol, atol=tol * self.algebra.bracket_scale)))

    def is_subalgebra(self, tol: float | None = None) -> bool:
        """True iff ``[D, D] ⊂ D``, i.e. the constraints are holonomic (integrable distribution)."""
        if self.dim < 2:
            return True
        return self._brackets_in(self._pair_brackets(self.basis, self.basis), tol)

    def growth_vector(self) -> tuple[int, ...]:
        """Dimensions of ``D, D + [D, D], D + [D, D] + [D, [D, D]], …`` until they stop growing.

        The distribution is bracket-generating (the constrained body can reach every
        orientation, Chow–Rashevskii) iff the last entry is the algebra's dimension.
        """
        if self.dim == 0:
            return (0,)
        dims = [self.dim]
        V = self.basis
        while True:
            new = np.vstack([V, self._pair_brackets(self.basis, V)])
            V = _span(new, self.tol)
            if V.shape[0] == dims[-1]:
                return tuple(dims)
            dims.append(V.shape[0])

    def is_bracket_generating(self) -> bool:
        """True iff iterated brackets of D span the whole algebra (see :meth:`growth_vector`)."""
        return self.growth_vector()[-1] == self.algebra.dim

    def is_symmetric(self) -> bool:
        """True iff ``(algebra, k)`` with ``k = D^⊥`` is a symmetric pair with ``p = D``.

        This is the structure (``[k, k] ⊂ k``, ``[k, D] ⊂ D``, ``[D, D] ⊂ k``) under which the
        eigenspace form (2.3) of the equations loses its quadratic term, giving (4.3).
        """
        return is_symmetric_pair(self.complement(), self)


def is_symmetric_pair(k: Subspace, p: Subspace, tol: float | None = None) -> bool:
    """Whether ``g = k ⊕ p`` is a symmetric decomposition.

    Checks that k and p live in the same algebra, that ``k ⊕ p`` is the whole algebra (dimensions
    add up and the sum is direct), and ``[k, k] ⊂ k``, ``[k, p] ⊂ p``, ``[p, p] ⊂ k``.

    Parameters
    ----------
    k, p : Subspace
    tol : float, optional
        Membership tolerance (default: the subspaces' own).

    Returns
    -------
    bool
    """
    for name, s in (("k", k), ("p", p)):
        if not isinstance(s, Subspace):
            raise TypeError(f"{name} must be a Subspace, got {type(s).__name__}")
    if k.algebra is not p.algebra and (k.algebra.dim != p.algebra.dim or not np.allclose(
            k.algebra.structure_constants, p.algebra.structure_constants)):
        raise ValueError("k and p must be subspaces of the same algebra")
    d = k.algebra.dim
    if k.dim + p.dim != d or _span(np.vstack([k.basis, p.basis]), k.tol).shape[0] != d:
        return False
    return (k._brackets_in(k._pair_brackets(k.basis, k.basis), tol)
            and p._brackets_in(k._pair_brackets(k.basis, p.basis), tol)
            and k._brackets_in(p._pair_brackets(p.basis, p.basis), tol))


def suslov_distribution(n: int) -> Subspace:
    """The Fedorov–Kozlov constraint subspace of so(n): ``Omega_ij = 0`` for ``i, j <= n - 1``.

    ``D = span{E_1n, …, E_{n-1,n}}``, dimension n - 1, with exactly these basis rows in this order,
    so the reduced coordinates are ``xi_i = Omega_in``. For n = 3 this is Suslov's constraint
    ``w_3 = 0``.
    """
    from .so import so  # local: so imports lie only, no cycle, but keep module import light

    alg = so(n)
    rows = np.zeros((n - 1, alg.dim))
    rows[np.arange(n - 1), [alg.index(i, n - 1) for i in range(n - 1)]] = 1.0
    return Subspace(alg, rows)


def _span(B: np.ndarray, tol: float) -> np.ndarray:
    """Orthonormal rows spanning the row space of B (rank by SVD, relative to the largest singular value)."""
    if B.shape[0] == 0:
        return np.zeros((0, B.shape[1]))
    _, s, Vt = np.linalg.svd(B, full_matrices=False)
    if s[0] == 0:
        return np.zeros((0, B.shape[1]))
    r = int(np.sum(s > tol * s[0]))
    return Vt[:r]


def _canonical_basis(V: np.ndarray, d: int) -> np.ndarray:
    """A basis of span(V) that depends only on the subspace (V orthonormal rows, shape (k, d)).

    The projections ``P e_j`` of the coordinate axes span the subspace; pick k best-conditioned
    ones by pivoted QR, keep them in index order and Gram–Schmidt them (positive diagonal).
    """
    k = V.shape[0]
    if k == 0:
        return np.zeros((0, d))
    P = V.T @ V
    _, _, piv = _scipy_linalg().qr(P, pivoting=True, mode="economic")
    cols = np.sort(piv[:k])
    Q, R = np.linalg.qr(P[:, cols])
    Q = Q * np.sign(np.where(np.diag(R) == 0, 1.0, np.diag(R)))
    Q[np.abs(Q) < 1e-15] = 0.0
    return np.ascontiguousarray(Q.T)


def _scipy_linalg():
    """scipy.linalg, imported on first use (``import liesuslov`` does not load it)."""
    import scipy.linalg

    return scipy.linalg
