"""Inertia operators J: g -> g* ≅ g, symmetric positive definite.

On so(n) a rigid body has ``J(Omega) = I Omega + Omega I`` for its mass tensor I (``MATH.md``);
in the basis E_ij its matrix is ``K[a, b] = <E_a, I E_b + E_b I>``, diagonal ``I_i + I_j`` when
I is diagonal. Any SPD matrix in the algebra's coordinates is an inertia operator too.
"""

from __future__ import annotations

import numpy as np

from .._validation import as_float_array, check_symmetric
from .lie import LieAlgebra
from .so import SpecialOrthogonalAlgebra, so
from .subspace import Subspace

__all__ = ["Inertia"]


class Inertia:
    """A symmetric positive definite inertia operator on a Lie algebra.

    Parameters
    ----------
    algebra : LieAlgebra
    K : array_like, shape (d, d)
        Matrix of J in the algebra's coordinates: ``J(x) = K x`` (K symmetric, so also ``x @ K``).

    Raises
    ------
    ValueError
        If K has the wrong shape, is not symmetric, or not positive definite (the message gives
        the smallest eigenvalue).

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
        self.algebra = algebra
        self.matrix = K
        self.matrix.setflags(write=False)
        self.inverse_matrix = np.linalg.inv(K)
        self.inverse_matrix.setflags(write=False)
        self.mass_tensor = None if mass_tensor is None else np.array(mass_tensor, dtype=float)

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
        """
        I = as_float_array(I, "I")
        if I.ndim == 1:
            I = np.diag(I)
        if I.ndim != 2 or I.shape[0] != I.shape[1] or I.shape[0] < 2:
            raise ValueError(f"I (the mass tensor) must be a symmetric (n, n) matrix or a vector of n >= 2 "
                             f"diagonal entries, got shape {I.shape}")
        check_symmetric(I, "I (the mass tensor)")
        I = 0.5 * (I + I.T)
        n = I.shape[0]
        lam = np.linalg.eigvalsh(I)
        if n >= 2 and lam[0] + lam[1] <= 0:
            raise ValueError("I (the mass tensor) gives an inertia J(Omega) = I Omega + Omega I that is not "
                             "positive definite: J > 0 iff lambda_i + lambda_j > 0 for all i != j "
                             f"(eigenvalues of I); here the two smallest sum to {lam[0] + lam[1]:.6g}")
        alg = so(n)
        E = alg.representation
        JE = I @ E + E @ I  # (d, n, n): J(E_b)
        K = alg.vee(JE).T  # K[a, b] = <E_a, J(E_b)> = coordinate a of J(E_b)
        return cls(alg, K, mass_tensor=I)

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
    def __call__(self, x) -> np.ndarray:
        """``J(x) = K x`` batched: (..., d) -> (..., d)."""
        return np.asarray(x, dtype=float) @ self.matrix

    def inverse(self, m) -> np.ndarray:
        """``J^{-1}(m)`` batched: (..., d) -> (..., d)."""
        return np.asarray(m, dtype=float) @ self.inverse_matrix

    def kinetic_energy(self, x) -> np.ndarray:
        """``1/2 <J x, x>``: (..., d) -> (...)."""
        x = np.asarray(x, dtype=float)
        return 0.5 * np.sum((x @ self.matrix) * x, axis=-1)

    def restrict(self, D: Subspace) -> np.ndarray:
        """The restriction ``d^T K d`` to a subspace (d = D.basis.T): the reduced mass matrix (k, k)."""
        self._same_algebra(D)
        return D.basis @ self.matrix @ D.basis.T

    def is_invariant(self, D: Subspace, tol: float = 1e-10) -> bool:
        """True iff ``J(D) ⊂ D`` (D is a sum of eigenspaces of J), the condition for form (2.3)."""
        self._same_algebra(D)
        if D.dim == 0:
            return True
        KD = D.basis @ self.matrix
        scale = float(np.max(np.abs(self.matrix)))
        return bool(np.all(D.contains(KD, tol * max(1.0, scale))))

    def _same_algebra(self, D: Subspace) -> None:
        if not isinstance(D, Subspace):
            raise TypeError(f"expected a Subspace, got {type(D).__name__}")
        if D.algebra.dim != self.algebra.dim:
            raise ValueError(f"the subspace lives in {D.algebra.name}, the inertia in {self.algebra.name}")
