"""Input checks for the analytic references: each names the argument and says how to fix the call.

The package deliberately depends on numpy and scipy only, so these small checks live here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Tolerance on ``| |x| - 1 |`` for the unit vectors (Gamma, q, gamma) accepted as input.
UNIT_TOL = 1e-10


def as_array(x: Any, name: str, *, tail: tuple[int, ...] | None = None, ndim_min: int = 0) -> np.ndarray:
    """Convert ``x`` to a finite float64 array, optionally with a fixed trailing shape."""
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a real numeric array, got {type(x).__name__}") from exc
    if arr.ndim < ndim_min:
        raise ValueError(f"{name} must have at least {ndim_min} dimension(s), got shape {arr.shape}")
    if tail is not None and (arr.ndim < len(tail) or arr.shape[arr.ndim - len(tail):] != tuple(tail)):
        want = "(..., " + ", ".join(str(k) for k in tail) + ")"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values; pass finite numbers")
    return arr


def as_scalar(x: Any, name: str) -> float:
    """A finite real number."""
    try:
        val = float(x)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a real number, got {type(x).__name__}") from exc
    if not np.isfinite(val):
        raise ValueError(f"{name} must be finite, got {x!r}")
    return val


def as_positive(x: Any, name: str) -> float:
    """A finite, strictly positive real number."""
    val = as_scalar(x, name)
    if val <= 0.0:
        raise ValueError(f"{name} must be strictly positive, got {x!r}")
    return val


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
