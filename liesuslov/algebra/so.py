"""The orthogonal algebras so(n) in the basis fixed by ``docs/concepts.md``.

Basis ``E_ij = e_i e_j^T - e_j e_i^T`` for ``i < j`` in lexicographic order (1,2), (1,3), …,
(1,n), (2,3), …; the coordinate of ``Omega`` on ``E_ij`` is ``Omega[i, j]``. The pairing
``<A, B> = -1/2 tr(AB)`` makes this basis orthonormal, so it is the Euclidean product of
coordinates, and so(n)* is identified with so(n) by it.

n = 3: ``Omega = hat(w)`` with ``hat(w) v = w x v``, i.e. ``w = (-Omega_23, Omega_13, -Omega_12)``;
``[hat a, hat b] = hat(a x b)``. :meth:`SpecialOrthogonalAlgebra.to_vector3` and
:meth:`SpecialOrthogonalAlgebra.from_vector3` convert between coordinates and ``w``.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .._cached import cached_property
from .._rows import matrices, paired, real_floats, vectors
from .lie import LieAlgebra

__all__ = ["SpecialOrthogonalAlgebra", "so", "wedge", "pairing", "hat3", "vee3"]


class SpecialOrthogonalAlgebra(LieAlgebra):
    """so(n): skew-symmetric n×n matrices, brackets by commutators (no dense n^6 contraction).

    Build it with :func:`so`. The structure constants are generated on demand only.

    Parameters
    ----------
    n : int
        Matrix size, ``n >= 2``; ``dim = n (n - 1) / 2``.
    """

    def __init__(self, n: int) -> None:  # validated by so(); constants exact by construction
        self.n = int(n)
        self._dim = self.n * (self.n - 1) // 2
        self.name = f"so({self.n})"
        rows, cols = np.triu_indices(self.n, 1)  # row-major = lexicographic (i, j), i < j
        self._rows, self._cols = rows, cols
        self._index = np.full((self.n, self.n), -1, dtype=int)
        self._index[rows, cols] = np.arange(self._dim)
        self._index[cols, rows] = np.arange(self._dim)

    # ------------------------------------------------------------------ data
    @property
    def matrix_size(self) -> int:
        return self.n

    @cached_property
    def representation(self) -> np.ndarray:  # type: ignore[override]
        """Basis matrices ``E_ij``, shape (d, n, n), read-only."""
        E = self.hat(np.eye(self._dim))
        E.setflags(write=False)
        return E

    @property
    def _rep(self):  # the base class checks this attribute for reconstruction support
        return self.representation

    @cached_property
    def structure_constants(self) -> np.ndarray:  # type: ignore[override]
        """``C[i, j, k]`` with ``[E_i, E_j] = sum_k C[i, j, k] E_k``; built on first access, O(n^6)."""
        C = np.ascontiguousarray(self.ad(np.eye(self._dim)).transpose(0, 2, 1))
        C.setflags(write=False)
        return C

    @property
    def _C(self):
        return self.structure_constants

    @property
    def bracket_scale(self) -> float:  # type: ignore[override]
        """1: the constants of the basis E_ij are 0 and ±1 (without building the O(d^3) array)."""
        return 1.0

    def is_abelian(self, tol: float = 1e-12) -> bool:
        return self.n == 2

    def index(self, i: int, j: int) -> int:
        """Position of ``E_ij`` (0-based ``i != j``) in the basis; the sign is +1 for i < j."""
        k = int(self._index[i, j])
        if k < 0:
            raise ValueError(f"no basis element E_ij for i = j = {i}")
        return k

    # ------------------------------------------------------------------ hat / vee
    def hat(self, x) -> np.ndarray:
        """Coordinates to skew matrices: ``(..., d) -> (..., n, n)``, ``X[i, j] = x_ij``, ``X[j, i] = -x_ij``."""
        x = vectors(x, "x", self._dim, self.name)
        X = np.zeros(x.shape[:-1] + (self.n, self.n))
        X[..., self._rows, self._cols] = x
        X[..., self._cols, self._rows] = -x
        return X

    def vee(self, X) -> np.ndarray:
        """Skew matrices to coordinates: ``(..., n, n) -> (..., d)``, the upper-triangle entries."""
        X = real_floats(X, "X")
        if X.shape[-2:] != (self.n, self.n):
            raise ValueError(f"X must have shape (..., {self.n}, {self.n}) for {self.name}, got {X.shape}")
        return X[..., self._rows, self._cols]

    # ------------------------------------------------------------------ operations
    def bracket(self, x, y) -> np.ndarray:
        """``[x, y] = vee(XY - YX)`` by the matrix commutator, batched ``(..., d)``."""
        x = vectors(x, "x", self._dim, self.name)
        y = vectors(y, "y", self._dim, self.name)
        paired(x, y, "x and y")
        X = self.hat(x)
        Y = self.hat(y)
        return self.vee(X @ Y - Y @ X)

    def ad(self, x) -> np.ndarray:
        """Matrices of ``ad_x``, shape (..., d, d), from commutators with the basis matrices."""
        X = self.hat(x)[..., None, :, :]
        E = self.representation
        cols = self.vee(X @ E - E @ X)  # (..., d_j, d_k): [x, E_j]
        return np.swapaxes(cols, -1, -2)

    def coad(self, x, m) -> np.ndarray:
        """Coadjoint action ``ad*_x m = [M, X]`` (so(n)* identified with so(n) by the pairing)."""
        x = vectors(x, "x", self._dim, self.name)
        m = vectors(m, "m", self._dim, self.name)
        paired(x, m, "x and m")
        X = self.hat(x)
        M = self.hat(m)
        return self.vee(M @ X - X @ M)

    def pairing(self, x, y) -> np.ndarray:
        """``<x, y> = -1/2 tr(XY)``: the Euclidean product of coordinates, shape (...)."""
        x = vectors(x, "x", self._dim, self.name)
        y = vectors(y, "y", self._dim, self.name)
        paired(x, y, "x and y")
        return np.sum(x * y, axis=-1)

    # ------------------------------------------------------------------ n = 3
    def to_vector3(self, x) -> np.ndarray:
        """so(3) coordinates ``(Omega_12, Omega_13, Omega_23)`` to ``w = (-Omega_23, Omega_13, -Omega_12)``."""
        self._need3()
        x = vectors(x, "x", 3)
        return np.stack([-x[..., 2], x[..., 1], -x[..., 0]], axis=-1)

    def from_vector3(self, w) -> np.ndarray:
        """``w`` (the cross-product form) to so(3) coordinates; inverse of :meth:`to_vector3`."""
        self._need3()
        w = vectors(w, "w", 3)
        return np.stack([-w[..., 2], w[..., 1], -w[..., 0]], axis=-1)

    def _need3(self) -> None:
        if self.n != 3:
            raise ValueError(f"the vector form exists for so(3) only, this is so({self.n})")


@lru_cache(maxsize=64)
def _so_cached(n: int) -> SpecialOrthogonalAlgebra:
    return SpecialOrthogonalAlgebra(n)


def so(n: int) -> SpecialOrthogonalAlgebra:
    """The algebra so(n) of skew-symmetric n×n matrices, ``n >= 2`` (instances are shared).

    Examples
    --------
    >>> so4 = so(4); so4.dim
    6
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise TypeError(f"n must be an integer >= 2, got {type(n).__name__}")
    if n < 2:
        raise ValueError(f"n must be >= 2 for so(n), got {n}")
    if n > SO_MAX_N:
        raise ValueError(f"n = {n} is beyond so(n)'s largest size {SO_MAX_N}: its index tables hold n^2 entries "
                         f"({8 * n * n / 1e9:.3g} GB each; n = 10^4 already takes seconds to build)")
    return _so_cached(int(n))


#: The largest n of :func:`so` (its tables are n×n; the low-rank kernel runs Fedorov–Kozlov to n = 256).
SO_MAX_N = 10_000


def wedge(x, y) -> np.ndarray:
    """``x ∧ y = x y^T - y x^T`` for vectors of shape (..., n); returns (..., n, n).

    For n = 3, ``x ∧ y = hat(y × x)``.
    """
    x = real_floats(x, "x")
    if x.ndim == 0 or x.shape[-1] < 2:
        raise ValueError(f"x must have shape (..., n) with n >= 2, got {x.shape}")
    y = vectors(y, "y", x.shape[-1])
    paired(x, y, "x and y")
    P = x[..., :, None] * y[..., None, :]
    return P - np.swapaxes(P, -1, -2)


def pairing(A, B) -> np.ndarray:
    """``<A, B> = -1/2 tr(AB)`` for matrices of shape (..., n, n); returns (...)."""
    A = real_floats(A, "A")
    if A.ndim < 2 or A.shape[-1] != A.shape[-2]:
        raise ValueError(f"A must have shape (..., n, n), got {A.shape}")
    B = matrices(B, "B", A.shape[-1])
    paired(A, B, "A and B", core=2)
    return -0.5 * np.einsum("...ij,...ji->...", A, B)


def hat3(w) -> np.ndarray:
    """``hat(w)`` with ``hat(w) v = w × v``: (..., 3) -> (..., 3, 3)."""
    w = vectors(w, "w", 3)
    z = np.zeros_like(w[..., 0])
    return np.stack([np.stack([z, -w[..., 2], w[..., 1]], -1),
                     np.stack([w[..., 2], z, -w[..., 0]], -1),
                     np.stack([-w[..., 1], w[..., 0], z], -1)], -2)


def vee3(W) -> np.ndarray:
    """Inverse of :func:`hat3`: (..., 3, 3) -> (..., 3)."""
    W = matrices(W, "W", 3)
    return np.stack([W[..., 2, 1], W[..., 0, 2], W[..., 1, 0]], axis=-1)
