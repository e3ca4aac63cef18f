"""Input checks for the analytic references: each names the argument and says how to fix the call.

The generic checks are the package's own (:mod:`liesuslov._validation`); the ones specific to the
references (unit vectors, diagonal mass tensors, symmetric matrices) live here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import as_float_array, check_positive, check_real

#: Tolerance on ``| |x| - 1 |`` for the unit vectors (Gamma, q, gamma) accepted as input.
UNIT_TOL = 1e-10


def as_array(x: Any, name: str, *, tail: tuple[int, ...] | None = None, ndim_min: int = 0) -> np.ndarray:
    """Convert ``x`` to a finite float64 array, optionally with a fixed trailing shape."""
    return as_float_array(x, name, tail=tail, ndim_min=ndim_min)


as_scalar = check_real  # a finite real number
as_positive = check_positive  # a finite, strictly positive real number


def check_unit(x: np.ndarray, name: str, tol: float = UNIT_TOL) -> None:
    """Raise unless every vector along the last axis has norm 1 to ``tol``."""
    dev = np.abs(np.linalg.norm(x, axis=-1) - 1.0)
    if dev.size and float(np.max(dev)) > tol:
        raise ValueError(f"{name} must be a unit vector (|{name}| = 1 to {tol:g}); the largest deviation of "
                         f"the norm from 1 is {float(np.max(dev)):.3g}: normalise it")


def diagonal_mass(I: Any, name: str = "I", *, n_min: int = 3) -> np.ndarray:
    """The diagonal of a mass tensor, shape (n,), with ``I_i + I_j > 0`` (positive inertia operator)."""
    I = as_array(I, name)
    if I.ndim != 1 or I.shape[0] < n_min:
        raise ValueError(f"{name} must be the diagonal (I_1, ..., I_n) of the mass tensor, shape (n,) with "
                         f"n >= {n_min}, got shape {I.shape}")
    pair = I[:, None] + I[None, :]
    off = ~np.eye(I.shape[0], dtype=bool)
    if np.any(pair[off] <= 0.0):
        raise ValueError(f"{name}: the inertia operator needs I_i + I_j > 0 for all i != j, got {I.tolist()}")
    return I


def symmetric_matrix(M: Any, name: str, *, n: int | None = None, positive: bool = True) -> np.ndarray:
    """A symmetric (optionally positive definite) square matrix."""
    M = as_array(M, name)
    if M.ndim != 2 or M.shape[0] != M.shape[1] or (n is not None and M.shape[0] != n):
        want = f"({n}, {n})" if n is not None else "(n, n)"
        raise ValueError(f"{name} must be a square matrix of shape {want}, got {M.shape}")
    scale = max(float(np.max(np.abs(M))), np.finfo(float).tiny)
    if float(np.max(np.abs(M - M.T))) > 1e-12 * scale:
        raise ValueError(f"{name} must be symmetric; pass (M + M.T) / 2 if that is what you mean")
    M = 0.5 * (M + M.T)
    if positive and float(np.min(np.linalg.eigvalsh(M))) <= 0.0:
        raise ValueError(f"{name} must be positive definite, its eigenvalues are {np.linalg.eigvalsh(M)}")
    return M


def times(t: Any, name: str = "t") -> np.ndarray:
    """Times: any shape, finite."""
    return as_array(t, name)


def broadcast_batch(*pairs: tuple[np.ndarray, int]) -> tuple[int, ...]:
    """Broadcast the batch shapes (all but the last ``k`` axes) of the arrays; raise a clear error."""
    shapes = [a.shape[:a.ndim - k] for a, k in pairs]
    try:
        return tuple(np.broadcast_shapes(*shapes))
    except ValueError as exc:
        raise ValueError(f"the batch shapes {shapes} of the initial data do not broadcast") from exc
