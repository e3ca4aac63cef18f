"""Inertia operators J: g -> g* ≅ g, symmetric positive definite.

On so(n) a rigid body has ``J(Omega) = I Omega + Omega I`` for its mass tensor I (``docs/concepts.md``);
in the basis E_ij its matrix is ``K[a, b] = <E_a, I E_b + E_b I>``, diagonal ``I_i + I_j`` when
I is diagonal. Any SPD matrix in the algebra's coordinates is an inertia operator too.

A mass tensor is kept as it is given: the d×d matrix K (d = n(n-1)/2, so d² ~ n⁴/4 numbers) is
built only when :attr:`Inertia.matrix` is read. J acts by ``I Omega + Omega I`` (or, for a diagonal
I, by the diagonal ``I_i + I_j`` of K), its inverse by the Sylvester solution in the eigenbasis of
I, and restrictions to sparse subspaces (the Fedorov–Kozlov D) touch only their nonzero entries —
so a body in SO(256) costs O(n²) memory and its reduced model O(n²) time.
"""

from __future__ import annotations

import numpy as np

from .._cached import cached_property
from .._rows import rows_at, vectors
from .._validation import as_float_array, check_symmetric
from .lie import LieAlgebra
from .so import SpecialOrthogonalAlgebra, so
from .subspace import Subspace

__all__ = ["Inertia"]

# A general (non-diagonal) mass tensor acts through its d×d matrix K up to this dimension d (one
# matmul, K built once: 32 KB at d = 64) and through I Omega + Omega I (two n×n products) above it.
_DENSE_ACTION_MAX_DIM = 64
# A subspace basis with at most this many nonzeros per row is handled as a sparse matrix.
_SPARSE_ROW_NNZ = 4


class Inertia:
    """A symmetric positive definite inertia operator on a Lie algebra.

    Parameters
    ----------
    algebra : LieAlgebra
    K : array_like, shape (d, d)
        Matrix of J in the algebra's coordinates: ``J(x) = K x`` (K symmetric, so also ``x @ K``).
    mass_tensor : array_like, shape (n, n) or (n,), optional
        The body's mass tensor I when K is ``J(Omega) = I Omega + Omega I`` on so(n): kept as
        :attr:`mass_tensor`, through which the so(n) paths act (O(n^3) instead of O(d^2)); checked to give K.

    Attributes
    ----------
    algebra : LieAlgebra
    mass_tensor : ndarray, shape (n, n), or None
        The mass tensor I of a body built by :meth:`from_mass_tensor` (None for a given K).
    diagonal : ndarray, shape (d,), or None
        The diagonal of K when K is known to be diagonal (a diagonal mass tensor:
        ``I_i + I_j`` on ``E_ij``), else None.

    Raises
    ------
    ValueError
        If K has the wrong shape, is not symmetric, or not positive definite (the message gives
        the smallest eigenvalue); if ``mass_tensor`` does not give K.

    Notes
    -----
    :attr:`matrix` and :attr:`inverse_matrix` are computed on first access (read-only, cached).
    Everything else — ``J(x)``, :meth:`inverse`, :meth:`kinetic_energy`, :meth:`restrict`,
    :meth:`is_invariant` — works from the mass tensor without them.

    Examples
    --------
    >>> J = Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0, 4.0]))
    >>> J(np.ones(6)).shape
    (6,)
    """

    def __init__(self, algebra: LieAlgebra, K, *, mass_tensor=None) -> None:
        if not isinstance(algebra, LieAlgebra):
            raise TypeError(f"algebra must be a LieAlgebra (e.g. ls.so(4)), got {type(algebra).__name__}")
        K = as_float_array(K, "K")
        d = algebra.dim
        if K.shape != (d, d):
            raise ValueError(f"K must have shape ({d}, {d}) for {algebra.name}, got {K.shape}")
        check_symmetric(K, "K")
        K = 0.5 * (K + K.T)
        lam = np.linalg.eigvalsh(K)
        if lam[0] <= 0:
            raise ValueError(f"K must be positive definite: its smallest eigenvalue is {lam[0]:.6g}")
        _check_invertible(lam[0], "K")
        K.setflags(write=False)
        self.algebra = algebra
        self.__dict__["matrix"] = K  # fills the cached property
        self.mass_tensor, self.diagonal, self._eig = None, None, None
        if mass_tensor is not None:
            # the so(n) paths act through I (O(n^3)) and never read K: an I that is not K's would be used silently
            body = Inertia.from_mass_tensor(mass_tensor)
            if body.algebra.dim != d or not algebra.name.startswith("so("):
                raise ValueError(f"mass_tensor is a body on {body.algebra.name}, but the algebra is {algebra.name}; "
                                 "pass mass_tensor only on so(n), with the K it gives")
            gap = float(np.max(np.abs(body.matrix - K)))
            if gap > 1e-12 * max(1.0, float(np.max(np.abs(K)))):
                raise ValueError(f"mass_tensor: K is not the inertia J(Omega) = I Omega + Omega I of this mass tensor "
                                 f"(largest difference {gap:.3g}); build it with Inertia.from_mass_tensor(I), or "
                                 "leave mass_tensor out")
            self.mass_tensor, self.diagonal, self._eig = body.mass_tensor, body.diagonal, body._eig

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_mass_tensor(cls, I) -> Inertia:
        """The rigid body on so(n): ``J(Omega) = I Omega + Omega I``.

        Parameters
        ----------
        I : array_like, shape (n, n) or (n,)
            Symmetric mass tensor (a vector means ``diag(I)``), n >= 2.

        Raises
        ------
        ValueError
            If I is not symmetric, or J is not positive definite: that holds iff
            ``lambda_i + lambda_j > 0`` for every pair i != j of eigenvalues of I.

        Notes
        -----
        O(n²) memory and O(n³) time (one symmetric eigendecomposition of I, O(n) for a diagonal
        I); the d×d matrix :attr:`matrix` is built only if it is read.
        """
        I = as_float_array(I, "I")
        vector = I.ndim == 1
        if vector:
            I = np.diag(I)
        if I.ndim != 2 or I.shape[0] != I.shape[1] or I.shape[0] < 2:
            raise ValueError(f"I (the mass tensor) must be a symmetric (n, n) matrix or a vector of n >= 2 "
                             f"diagonal entries, got shape {I.shape}")
        check_symmetric(I, "I (the mass tensor)")
        I = 0.5 * (I + I.T)
        n = I.shape[0]
        diag = np.diag(I).copy()
        is_diag = vector or not np.any(I - np.diag(diag))
        if is_diag:
            lam, V = np.sort(diag), None
        else:
            lam, V = np.linalg.eigh(I)
        if lam[0] + lam[1] <= 0:
            raise ValueError("I (the mass tensor) gives an inertia J(Omega) = I Omega + Omega I that is not "
                             "positive definite: J > 0 iff lambda_i + lambda_j > 0 for all i != j "
                             f"(eigenvalues of I); here the two smallest sum to {lam[0] + lam[1]:.6g}")
        _check_invertible(lam[0] + lam[1], "I (the mass tensor)")
        self = cls.__new__(cls)
        alg = so(n)
        self.algebra = alg
        self.mass_tensor = I
        self.mass_tensor.setflags(write=False)
        if is_diag:
            r, c = alg._rows, alg._cols
            kd = diag[r] + diag[c]  # J(E_ij) = (I_i + I_j) E_ij
            kd.setflags(write=False)
            self.diagonal = kd
            self._eig = None
        else:
            self.diagonal = None
            self._eig = (lam, V)
        return self

    @classmethod
    def from_principal_moments(cls, J) -> Inertia:
        """The 3-D body from the paper's inertia acting on ``w`` (``J(hat w) = hat(J w)``).

        Parameters
        ----------
        J : array_like, shape (3,) or (3, 3)
            Principal moments ``(J1, J2, J3)`` or a symmetric 3×3 matrix in the ``w`` form.

        Notes
        -----
        The map to the mass tensor is ``I = 1/2 tr(J) Id - J`` (inverse ``J = tr(I) Id - I``);
        e.g. ``J = diag(J1, J2, J3)`` gives ``I_1 = (J2 + J3 - J1) / 2`` and cyclic. J must be
        positive definite (the triangle inequalities of physical bodies are not required).
        """
        J = as_float_array(J, "J")
        if J.shape == (3,):
            J = np.diag(J)
        if J.shape != (3, 3):
            raise ValueError(f"J must be the principal moments (3,) or a 3×3 matrix, got shape {J.shape}")
        check_symmetric(J, "J")
        if np.linalg.eigvalsh(0.5 * (J + J.T))[0] <= 0:
            raise ValueError("J must be positive definite (all principal moments > 0)")
        return cls.from_mass_tensor(0.5 * np.trace(J) * np.eye(3) - J)

    # ------------------------------------------------------------------ data
    @property
    def dim(self) -> int:
        return self.algebra.dim

    @cached_property
    def matrix(self) -> np.ndarray:
        """K, shape (d, d), read-only: ``K[a, b] = <E_a, I E_b + E_b I>`` for a mass tensor (built on first access).

        From ``I E_b + E_b I`` with ``E_b = e_i e_j^T - e_j e_i^T``, the entry on ``E_pq`` (p < q) is
        ``I_pi δ_qj - I_pj δ_qi + δ_pi I_jq - δ_pj I_iq``: O(d²) work, no (d, n, n) basis tensor.
        """
        if self.diagonal is not None:
            K = np.diag(self.diagonal)
        else:
            I = self.mass_tensor
            r, c = self.algebra._rows, self.algebra._cols
            p, q = r[:, None], c[:, None]  # the row E_pq
            i, j = r[None, :], c[None, :]  # the column E_ij
            K = (I[p, i] * (q == j) - I[p, j] * (q == i) + (p == i) * I[j, q] - (p == j) * I[i, q])
        K.setflags(write=False)
        return K

    @cached_property
    def inverse_matrix(self) -> np.ndarray:
        """K⁻¹, shape (d, d), read-only (built on first access)."""
        if self.diagonal is not None:
            Kinv = np.diag(1.0 / self.diagonal)
        else:
            Kinv = np.linalg.inv(self.matrix)
        Kinv.setflags(write=False)
        return Kinv

    @property
    def principal_moments(self) -> np.ndarray:
        """n = 3: the matrix of J acting on ``w`` (the paper's J), shape (3, 3)."""
        if not (isinstance(self.algebra, SpecialOrthogonalAlgebra) and self.algebra.n == 3):
            raise ValueError("principal_moments exist for so(3) only")
        T = self.algebra.to_vector3(np.eye(3))  # rows: w of each basis vector; w = x @ T
        return T.T @ self.matrix @ T

    def __repr__(self) -> str:
        return f"Inertia({self.algebra.name})"

    # ------------------------------------------------------------------ action
    def _dense(self) -> bool:
        """Act through K: a given K, or a small non-diagonal mass tensor (K built once)."""
        return self.mass_tensor is None or (self.diagonal is None and self.algebra.dim <= _DENSE_ACTION_MAX_DIM)

    def __call__(self, x) -> np.ndarray:
        """``J(x) = K x`` batched: (..., d) -> (..., d).

        A diagonal mass tensor multiplies by ``I_i + I_j``; a large general one forms
        ``vee(I X + X I)`` (O(n³) per element, no d×d matrix).
        """
        x = vectors(x, "x", self.algebra.dim)
        if self.diagonal is not None:
            return x * self.diagonal
        if self._dense():
            return rows_at(x, self.matrix)  # (the same bits for a row alone or in a batch)
        alg, I = self.algebra, self.mass_tensor
        X = alg.hat(x)
        IX = I @ X
        return alg.vee(IX - np.swapaxes(IX, -1, -2))  # X I = -(I X)^T for skew X

    def inverse(self, m) -> np.ndarray:
        """``J^{-1}(m)`` batched: (..., d) -> (..., d).

        A large general mass tensor solves ``I X + X I = M`` in the eigenbasis of ``I = V Λ V^T``:
        ``X = V ((V^T M V)_ij / (λ_i + λ_j)) V^T`` (O(n³), no d×d matrix).
        """
        m = vectors(m, "m", self.algebra.dim)
        if self.diagonal is not None:
            return m / self.diagonal
        if self._dense():
            return m @ self.inverse_matrix
        alg = self.algebra
        lam, V = self._eig
        M = V.T @ alg.hat(m) @ V
        return alg.vee(V @ (M / (lam[:, None] + lam[None, :])) @ V.T)

    def kinetic_energy(self, x) -> np.ndarray:
        """``1/2 <J x, x>``: (..., d) -> (...)."""
        x = vectors(x, "x", self.algebra.dim)
        return 0.5 * np.sum(self(x) * x, axis=-1)

    def restrict(self, D: Subspace) -> np.ndarray:
        """The restriction ``d^T K d`` to a subspace (d = D.basis.T): the reduced mass matrix (k, k).

        A sparse basis (a few nonzeros per row, e.g. the Fedorov–Kozlov ``E_in``) with a diagonal
        mass tensor costs O(nnz) after an O(k d) scan; otherwise ``B J(B)^T`` (O(k² d)).
        """
        self._same_algebra(D)
        B = D.basis
        S = self._sparse_basis(B)
        if S is not None:
            KD = (S.multiply(self.diagonal[None, :]) @ S.T).toarray()
        else:
            KD = B @ self(B).T
        return 0.5 * (KD + KD.T)

    def is_invariant(self, D: Subspace, tol: float = 1e-10) -> bool:
        """True iff ``J(D) ⊂ D`` (D is a sum of eigenspaces of J), the condition for form (2.3).

        Tested as ``|x - P x| <= tol max(|x|, max|K|)`` for the images x of the unit basis rows (P the
        orthogonal projector on D) — relative to J's own scale, so that it does not change when J is
        rescaled (a body of 1e-12 kg m^2) — sparse for a sparse basis and a diagonal mass tensor.
        """
        self._same_algebra(D)
        if D.dim == 0:
            return True
        scale = self._max_abs_entry()
        atol = tol * scale
        B = D.basis
        S = self._sparse_basis(B)
        if S is None:
            return bool(np.all(D.contains(self(B), tol, atol=atol)))
        X = S.multiply(self.diagonal[None, :]).tocsr()  # J of each basis row, same pattern
        R = X - (X @ S.T) @ S
        res = np.sqrt(np.asarray(R.multiply(R).sum(axis=1)).ravel())
        nx = np.sqrt(np.asarray(X.multiply(X).sum(axis=1)).ravel())
        return bool(np.all(res <= tol * np.maximum(scale, nx)))

    # ------------------------------------------------------------------ helpers
    def _max_abs_entry(self) -> float:
        """``max |K_ab|`` without K: ``|I_i + I_j|`` on the diagonal, ``|I_pq|`` (p != q) off it."""
        if self.mass_tensor is None:
            return float(np.max(np.abs(self.matrix)))
        if self.diagonal is not None:
            return float(np.max(np.abs(self.diagonal)))
        I = self.mass_tensor
        d = np.diag(I)
        r, c = self.algebra._rows, self.algebra._cols
        big = float(np.max(np.abs(d[r] + d[c])))
        if I.shape[0] >= 3:  # off-diagonal entries of I appear in K only when two basis pairs share an index
            big = max(big, float(np.max(np.abs(I - np.diag(d)))))
        return big

    def _sparse_basis(self, B: np.ndarray):
        """B as a CSR matrix when J is diagonal and B has few nonzeros per row, else None."""
        if self.diagonal is None or B.shape[0] == 0:
            return None
        nnz = int(np.count_nonzero(B))
        if nnz > _SPARSE_ROW_NNZ * B.shape[0]:
            return None
        import scipy.sparse  # loaded on first use

        return scipy.sparse.csr_matrix(B)

    def _same_algebra(self, D: Subspace) -> None:
        if not isinstance(D, Subspace):
            raise TypeError(f"expected a Subspace, got {type(D).__name__}")
        if D.algebra.dim != self.algebra.dim:
            raise ValueError(f"the subspace lives in {D.algebra.name}, the inertia in {self.algebra.name}")


def _check_invertible(smallest: float, name: str) -> None:
    """ValueError naming ``name`` when the inertia's smallest eigenvalue ``smallest`` (> 0) has no finite inverse:
    a scale near the bottom of the float range (1e-320) passes "positive definite" but every velocity from a
    momentum would be inf."""
    with np.errstate(divide="ignore", over="ignore"):
        if not np.isfinite(1.0 / smallest):
            raise ValueError(f"{name}: the inertia's smallest eigenvalue {smallest:.3g} has no finite inverse (below "
                             "the float range): rescale the units of mass or length")
