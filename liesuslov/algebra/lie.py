"""Finite-dimensional real Lie algebras given by structure constants.

Convention (``docs/concepts.md``): with basis ``e_1..e_d``, ``[e_i, e_j] = sum_k C[i, j, k] e_k``.
Elements are coordinate vectors of shape ``(..., d)``; leading axes are batch axes.
Algebras other than so(n) are identified with their dual by the Euclidean product of
coordinates (so(n)'s pairing -1/2 tr(AB) is exactly that in its basis, see :mod:`.so`).
"""

from __future__ import annotations

import numpy as np

from .._cached import cached_property
from .._rows import paired, real_floats, rows_at, vectors
from .._validation import as_float_array

__all__ = ["LieAlgebra", "se"]


class LieAlgebra:
    """A real Lie algebra of dimension ``d`` from its structure constants.

    Parameters
    ----------
    structure_constants : array_like, shape (d, d, d)
        ``C[i, j, k]`` with ``[e_i, e_j] = sum_k C[i, j, k] e_k``.
    representation : array_like, shape (d, m, m), optional
        Matrices ``R_i`` of a faithful representation, ``R(e_i) = R_i``, with
        ``[R_i, R_j] = sum_k C[i, j, k] R_k``. Needed for reconstruction on the group.
    name : str, optional
        A label for printing.
    rtol : float
        Tolerance of the antisymmetry and Jacobi checks, relative to ``max |C|``
        (squared for Jacobi, which is quadratic in ``C``).

    Raises
    ------
    ValueError
        If ``C`` is not of shape (d, d, d), not antisymmetric in (i, j), or violates the
        Jacobi identity; the message names the identity and the worst index triple. Also if
        the representation's commutators do not reproduce ``C``.
    """

    def __init__(self, structure_constants, *, representation=None, name: str | None = None,
                 rtol: float = 1e-10) -> None:
        C = as_float_array(structure_constants, "structure_constants")
        if C.ndim != 3 or not (C.shape[0] == C.shape[1] == C.shape[2]) or C.shape[0] < 1:
            raise ValueError(f"structure_constants must have shape (d, d, d) with d >= 1, got {C.shape}")
        _check_lie_constants(C, rtol)
        self._C = C
        self._C.setflags(write=False)
        self._dim = C.shape[0]
        if name is not None and not isinstance(name, str):
            raise TypeError(f"name must be a string (a label for printing), got {type(name).__name__}")
        self.name = name or f"LieAlgebra(dim={self._dim})"
        self._rep = None
        if representation is not None:
            R = as_float_array(representation, "representation")
            if R.ndim != 3 or R.shape[0] != self._dim or R.shape[1] != R.shape[2]:
                raise ValueError(f"representation must have shape (d, m, m) with d = {self._dim}, "
                                 f"got {R.shape}")
            comm = np.einsum("iab,jbc->ijac", R, R) - np.einsum("jab,ibc->ijac", R, R)
            want = np.einsum("ijk,kab->ijab", C, R)
            err = float(np.max(np.abs(comm - want)))
            scale = max(1.0, float(np.max(np.abs(R))) ** 2)
            if err > 1e-10 * scale:
                i, j = np.unravel_index(np.argmax(np.abs(comm - want).max(axis=(2, 3))), (self._dim,) * 2)
                raise ValueError(f"representation does not represent the algebra: [R_{i}, R_{j}] differs "
                                 f"from sum_k C[{i}, {j}, k] R_k by {err:.3g}")
            flat = R.reshape(self._dim, -1)
            if np.linalg.matrix_rank(flat) < self._dim:
                raise ValueError("representation is not faithful: the matrices R_i are linearly dependent")
            self._rep = R
            self._rep.setflags(write=False)
            self._rep_pinv = np.linalg.pinv(flat)  # (m*m, d): vee by least squares

    # ------------------------------------------------------------------ basic data
    @property
    def dim(self) -> int:
        """Dimension ``d`` of the algebra."""
        return self._dim

    @property
    def structure_constants(self) -> np.ndarray:
        """The array ``C`` of shape (d, d, d), ``[e_i, e_j] = sum_k C[i, j, k] e_k`` (read-only)."""
        return self._C

    @property
    def representation(self) -> np.ndarray | None:
        """Basis matrices ``R_i`` of the faithful matrix representation, shape (d, m, m), or None."""
        return self._rep

    @property
    def matrix_size(self) -> int | None:
        """Size ``m`` of the representation matrices, or None without a representation."""
        return None if self._rep is None else self._rep.shape[1]

    def __repr__(self) -> str:
        return self.name

    # ------------------------------------------------------------------ operations
    def bracket(self, x, y) -> np.ndarray:
        """Lie bracket in coordinates: ``[x, y]_k = sum_ij x_i y_j C[i, j, k]``.

        Parameters
        ----------
        x, y : array_like, shape (..., d)

        Returns
        -------
        ndarray, shape (..., d)
        """
        x = vectors(x, "x", self._dim, self.name)
        y = vectors(y, "y", self._dim, self.name)
        paired(x, y, "x and y")
        return np.einsum("...j,...jk->...k", y, self._contract(x))

    def ad(self, x) -> np.ndarray:
        """Matrix of ``ad_x = [x, .]``: ``ad(x) @ y == bracket(x, y)``.

        Parameters
        ----------
        x : array_like, shape (..., d)

        Returns
        -------
        ndarray, shape (..., d, d), ``ad(x)[..., k, j] = sum_i x_i C[i, j, k]``.
        """
        return np.swapaxes(self._contract(vectors(x, "x", self._dim, self.name)), -1, -2)

    def _contract(self, x: np.ndarray) -> np.ndarray:
        """``sum_i x_i C[i, j, k]``, shape (..., d, d) from x (..., d): the operations' common first factor.

        Summed in one order for every row (:func:`~liesuslov._rows.rows_at`, no BLAS), so a row's bracket
        or coadjoint action has the same bits alone or in any batch (``einsum(..., optimize=True)`` handed
        the batch to BLAS).
        """
        d = self._C.shape[0]
        return rows_at(x, self._C.reshape(d, d * d)).reshape(x.shape[:-1] + (d, d))

    def coad(self, x, m) -> np.ndarray:
        """Coadjoint action ``ad*_x m`` in coordinates: ``ad(x)^T m``.

        Defined by ``<ad*_x m, y> = <m, [x, y]>`` for the coordinate pairing. On so(n),
        with so(n)* identified with so(n) by -1/2 tr(AB), ``ad*_Omega M = [M, Omega]``: the
        right-hand side of the Euler–Poincaré equation ``dM/dt = ad*_Omega M``.

        Parameters
        ----------
        x, m : array_like, shape (..., d)

        Returns
        -------
        ndarray, shape (..., d)
        """
        x = vectors(x, "x", self._dim, self.name)
        m = vectors(m, "m", self._dim, self.name)
        paired(x, m, "x and m")
        return np.einsum("...jk,...k->...j", self._contract(x), m)

    @cached_property
    def bracket_scale(self) -> float:
        """``max |C_ijk|``: the size of a bracket of unit vectors, against which the structure tests (which
        brackets vanish or lie in a subspace) measure their residuals — so they do not change when the
        constants are rescaled."""
        return float(np.max(np.abs(self._C), initial=0.0))

    @cached_property
    def killing_form(self) -> np.ndarray:
        """Killing form ``K_ij = tr(ad_{e_i} ad_{e_j})``, shape (d, d)."""
        ads = self.ad(np.eye(self._dim))
        return np.einsum("iab,jba->ij", ads, ads)

    def is_abelian(self, tol: float = 1e-12) -> bool:
        """True when every bracket vanishes: ``max |C_ijk| <= tol``.

        Absolute, not relative to the constants' scale: C = 0 in every basis of an abelian algebra, and
        a relative test would only accept C = 0 exactly; ``tol`` absorbs rounding in constants computed
        elsewhere (e.g. from commutators of matrices of size ~1)."""
        return bool(np.max(np.abs(self._C), initial=0.0) <= tol)

    # ------------------------------------------------------------------ representation
    def _require_rep(self) -> np.ndarray:
        if self._rep is None:
            raise ValueError(f"{self.name} has no matrix representation; pass representation= "
                             "to LieAlgebra to reconstruct on the group")
        return self._rep

    def hat(self, x) -> np.ndarray:
        """Coordinates to representation matrices: ``sum_i x_i R_i``.

        Parameters
        ----------
        x : array_like, shape (..., d)

        Returns
        -------
        ndarray, shape (..., m, m)
        """
        R = self._require_rep()
        d, m = R.shape[0], R.shape[1]
        x = vectors(x, "x", d, self.name)
        return rows_at(x, R.reshape(d, m * m)).reshape(x.shape[:-1] + (m, m))  # (row-exact: not tensordot's BLAS)

    def vee(self, X) -> np.ndarray:
        """Representation matrices back to coordinates (least squares; exact on the image of hat).

        Parameters
        ----------
        X : array_like, shape (..., m, m)

        Returns
        -------
        ndarray, shape (..., d)
        """
        R = self._require_rep()
        X = real_floats(X, "X")
        m = R.shape[1]
        if X.shape[-2:] != (m, m):
            raise ValueError(f"X must have shape (..., {m}, {m}) for {self.name}, got {X.shape}")
        return rows_at(X.reshape(X.shape[:-2] + (m * m,)), self._rep_pinv)


def _check_lie_constants(C: np.ndarray, rtol: float) -> None:
    """Antisymmetry and Jacobi identity of structure constants, errors naming the worst triple."""
    scale = float(np.max(np.abs(C), initial=0.0))
    if scale == 0.0:
        return  # the abelian algebra
    asym = np.abs(C + C.transpose(1, 0, 2))
    worst = float(asym.max())
    if worst > rtol * scale:
        i, j, k = np.unravel_index(np.argmax(asym), C.shape)
        raise ValueError("structure_constants are not antisymmetric: C[i, j, k] = -C[j, i, k] fails, "
                         f"worst at (i, j, k) = ({i}, {j}, {k}) with |C_ijk + C_jik| = {worst:.3g}")
    # Jac[i, j, k, m] = ([[e_i, e_j], e_k] + [[e_j, e_k], e_i] + [[e_k, e_i], e_j])_m, of C / max|C| (so that
    # C of 1e200 does not overflow to NaN, nor C of 1e-200 underflow to 0, and pass)
    Cn = C / scale
    t = np.einsum("ijl,lkm->ijkm", Cn, Cn)
    jac = t + t.transpose(1, 2, 0, 3) + t.transpose(2, 0, 1, 3)
    bad = np.abs(jac).max(axis=3)
    worst = float(bad.max())  # relative to max|C|^2
    if not worst <= rtol * C.shape[0]:
        i, j, k = np.unravel_index(np.argmax(bad), bad.shape)
        raise ValueError("structure_constants violate the Jacobi identity "
                         "[[e_i, e_j], e_k] + [[e_j, e_k], e_i] + [[e_k, e_i], e_j] = 0: "
                         f"worst at (i, j, k) = ({i}, {j}, {k}) with residual {worst:.3g} max|C|^2")


def _constants_from_matrices(R: np.ndarray) -> np.ndarray:
    """Structure constants of the span of independent matrices ``R_i`` closed under commutators."""
    d, m, _ = R.shape
    comm = np.einsum("iab,jbc->ijac", R, R) - np.einsum("jab,ibc->ijac", R, R)
    flat = R.reshape(d, m * m)
    return comm.reshape(d, d, m * m) @ np.linalg.pinv(flat)


def se(n: int) -> LieAlgebra:
    """The special Euclidean algebra se(2) or se(3) with its (n+1)×(n+1) matrix representation.

    Bases (documented in ``docs/concepts.md``):

    * se(2), d = 3: ``e_1`` the rotation generator ``[[0, -1, 0], [1, 0, 0], [0, 0, 0]]``,
      ``e_2``, ``e_3`` the translations along x and y. Brackets ``[e_1, e_2] = e_3``,
      ``[e_1, e_3] = -e_2``, ``[e_2, e_3] = 0``. An element ``(omega, v_x, v_y)`` is
      ``[[0, -omega, v_x], [omega, 0, v_y], [0, 0, 0]]``.
    * se(3), d = 6: ``e_1..e_3`` the rotations ``hat(e_k)`` (``hat(w) v = w x v``), ``e_4..e_6``
      the translations. An element ``(w, v)`` is ``[[hat(w), v], [0, 0]]`` and
      ``[(w1, v1), (w2, v2)] = (w1 x w2, w1 x v2 - w2 x v1)``.

    Parameters
    ----------
    n : {2, 3}

    Returns
    -------
    LieAlgebra
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise TypeError(f"n must be the integer 2 or 3 for se(n), got {type(n).__name__}")
    n = int(n)
    if n == 2:
        R = np.zeros((3, 3, 3))
        R[0, 0, 1], R[0, 1, 0] = -1.0, 1.0
        R[1, 0, 2] = 1.0
        R[2, 1, 2] = 1.0
    elif n == 3:
        R = np.zeros((6, 4, 4))
        for k in range(3):
            e = np.zeros(3)
            e[k] = 1.0
            R[k, :3, :3] = _hat3(e)
            R[3 + k, k, 3] = 1.0
    else:
        raise ValueError(f"se(n) is built in for n = 2 and n = 3, got n = {n!r}; "
                         "for other algebras pass structure constants to LieAlgebra")
    return LieAlgebra(_constants_from_matrices(R), representation=R, name=f"se({n})")


def _hat3(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
