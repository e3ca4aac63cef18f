"""The Cayley map cay(X) = (I - X/2)^-1 (I + X/2): dense, skew, so(3) closed form, and its action on vectors."""

from __future__ import annotations

import numpy as np

from .common import _cayley_coefficients, _eye, _solve
from .so3 import _so3_lin, _so3_mat, _sq, _stack, _vec4_c, _vec_c, _vee_c
from .so4 import _SO4_CAYLEY_MIN_BATCH, _so4_cayley_coefficients, _so4_lin_apply_c, _so4_mat_c, _so4_pq_c


# ---------------------------------------------------------------------------- Cayley
def cayley(X: np.ndarray) -> np.ndarray:
    """Cayley transform ``cay(X) = (I − X/2)⁻¹ (I + X/2)`` of general square matrices, batched.

    One LU solve per matrix; correct for any X with ``I − X/2`` invertible (se(2), se(3), …) and
    orthogonal for skew X. For skew X prefer :func:`cayley_skew` (closed forms for n <= 3).

    Parameters
    ----------
    X : ndarray, shape (..., n, n)

    Returns
    -------
    ndarray, shape (..., n, n)
    """
    eye = _eye(X.shape[-1])
    H = 0.5 * X
    return _solve(eye - H, eye + H)


_CAYLEY_POLISH = 1e2  # |X| above which the dense Cayley transform is re-orthonormalised
#: The Cayley chart's numerical domain, |X|_F / sqrt 2 < 1/sqrt(eps) (6.7e7): beyond it the solve's orthogonality
#: defect (~eps |X|², measured) is O(1), past what one Newton–Schulz step can restore; an integrator's step
#: whose chart argument reaches it is rejected or fails (both solvers, every kind).
_CAYLEY_LIMIT = float(np.finfo(float).eps) ** -0.5


def cayley_skew(X: np.ndarray) -> np.ndarray:
    """Cayley transform of skew-symmetric matrices, with closed forms for n = 2, 3.

    n = 3 (any X with ``X³ = −θ² X``): ``cay(X) = I + 4/(4 + θ²) (X + X²/2)``
    ``= (4 − θ²)/(4 + θ²) I + 4/(4 + θ²) X + 2/(4 + θ²) w wᵀ``, a rotation by ``2 arctan(θ/2)``;
    n = 4 (one matrix, or batches of at least ``_SO4_CAYLEY_MIN_BATCH``; else the solve):
    ``c0 I + c1 P + c2 Q + c3 PQ`` in the split so(4) = so(3) ⊕ so(3) (:func:`so4_split`), with
    ``μ = 1 − |p|²/4 + |q|²/4``, ``D = μ² + |p|²``: ``c0 = (2μ + |p|²)/D − 1``, ``c1 = (2 − μ)/D``,
    ``c2 = μ/D``, ``c3 = 1/D``;
    n = 2: the same rotation; n >= 5: :func:`cayley`, re-orthonormalised (polar factor) when ``|X| > 100``.

    Parameters
    ----------
    X : ndarray, shape (..., n, n)
        Skew-symmetric (not checked; for n = 3 only ``w = (X21, X02, X10)`` is read, for n = 2 ``X10``).

    Returns
    -------
    ndarray, shape (..., n, n)
        In SO(n).
    """
    n = X.shape[-1]
    if n == 3:
        w = _vee_c(X)
        return _so3_mat(*_cayley_coefficients(_sq(w)), w, X.shape[:-2])
    if n == 4 and (X.size == 16 or X.size >= 16 * _SO4_CAYLEY_MIN_BATCH):
        p, q = _so4_pq_c(X)
        return _stack(_so4_mat_c(_so4_cayley_coefficients(p, q), p, q), (4, 4), X.shape[:-2])
    if n == 2:
        t = X[..., 1, 0]
        k = 1.0 / (4.0 + t * t)
        c, s = (4.0 - t * t) * k, 4.0 * t * k
        return np.stack((c, -s, s, c), -1).reshape(X.shape)
    C = cayley(X)
    # The LU solve is orthogonal only to ~|X| eps; for large X (a diverging step near |h Omega| ~ pi,
    # |X| up to 1e17) the polar factor U V^T of the SVD puts it back on SO(n) whatever the defect.
    if X.size and float(np.abs(X).max()) > _CAYLEY_POLISH and np.all(np.isfinite(C)):
        U, _, Vt = np.linalg.svd(C)
        C = U @ Vt
    return C


def cayley_so3(w: np.ndarray) -> np.ndarray:
    """``cay(hat w)``: (..., 3) -> (..., 3, 3), see :func:`cayley_skew`."""
    wc = _vec_c(w)
    return _so3_mat(*_cayley_coefficients(_sq(wc)), wc, w.shape[:-1])


def cayley_so3_apply(w: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``cay(hat w) v = v + 4/(4 + θ²) (w × v + ½ w × (w × v))`` for 3-vectors (..., 3)."""
    wc = _vec_c(w)
    return _so3_lin(*_cayley_coefficients(_sq(wc)), wc, _vec_c(v), w.shape[:-1], v.shape[:-1])


def cayley_apply(X: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``cay(X) v = (I − X/2)⁻¹ (v + X v / 2)`` by one solve, for general square X.

    Parameters
    ----------
    X : ndarray, shape (..., n, n)
    v : ndarray, shape (..., n)

    Returns
    -------
    ndarray, shape (..., n)
    """
    Xv = (X @ v[..., None])[..., 0]
    return _solve(_eye(X.shape[-1]) - 0.5 * X, (v + 0.5 * Xv)[..., None])[..., 0]


def cayley_skew_apply(X: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``cay(X) v`` for skew X: closed forms for n = 3 (``v + 4/(4 + θ²)(X v + ½ X (X v))``) and n = 4; else a solve.

    Parameters
    ----------
    X : ndarray, shape (..., n, n)
        Skew-symmetric.
    v : ndarray, shape (..., n)

    Returns
    -------
    ndarray, shape (..., n)
    """
    if X.shape[-1] == 3:
        w = _vee_c(X)
        return _so3_lin(*_cayley_coefficients(_sq(w)), w, _vec_c(v), X.shape[:-2], v.shape[:-1])
    if X.shape[-1] == 4 and (X.size == 16 or X.size >= 16 * _SO4_CAYLEY_MIN_BATCH):
        p, q = _so4_pq_c(X)
        vc = _vec4_c(v)
        return _stack(_so4_lin_apply_c(_so4_cayley_coefficients(p, q), p, q, vc), (4,), X.shape[:-2], v.shape[:-1])
    return cayley_apply(X, v)
