"""Small named checks shared by every layer.

Each check names the argument it inspects and says how to fix the call, so the public functions
stay readable: ``x = as_float_array(x, "Omega0")``.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def as_float_array(x: Any, name: str, *, ndim_min: int = 0, tail: tuple[int, ...] | None = None,
                   finite: bool = True) -> np.ndarray:
    """Convert ``x`` to a float64 array and check its trailing shape and finiteness.

    Parameters
    ----------
    x : array_like
        The value given by the user.
    name : str
        The argument's name, used in the error message.
    ndim_min : int
        Minimal number of dimensions.
    tail : tuple of int, optional
        Required trailing shape (the batch axes in front are free).
    finite : bool
        Reject NaN and infinities.

    Raises
    ------
    TypeError
        If ``x`` is not numeric.
    ValueError
        If the shape or the values are wrong.
    """
    if x is None:  # np.asarray(None, dtype=float) would be a silent NaN
        raise TypeError(f"{name} must be a real numeric array, got None")
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a real numeric array, got {type(x).__name__}") from exc
    if arr.ndim < ndim_min:
        raise ValueError(f"{name} must have at least {ndim_min} dimension(s), got shape {arr.shape}")
    if tail is not None:
        if arr.ndim < len(tail) or arr.shape[arr.ndim - len(tail):] != tuple(tail):
            want = "(..., " + ", ".join(str(t) for t in tail) + ")"
            raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if finite and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values; pass finite numbers")
    return arr


def check_real(x: Any, name: str) -> float:
    """Return ``x`` as a float after checking it is a finite real number."""
    try:
        val = float(x)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a real number, got {type(x).__name__}") from exc
    if not np.isfinite(val):
        raise ValueError(f"{name} must be finite, got {x!r}")
    return val


def check_positive(x: Any, name: str) -> float:
    """Return ``x`` as a float after checking it is finite and strictly positive."""
    val = check_real(x, name)
    if val <= 0:
        raise ValueError(f"{name} must be a finite positive number, got {x!r}")
    return val


def check_symmetric(M: np.ndarray, name: str, *, rtol: float = 1e-10) -> None:
    """Raise ``ValueError`` unless the square matrix ``M`` is symmetric to ``rtol`` (relative)."""
    if M.ndim != 2 or M.shape[0] != M.shape[1]:
        raise ValueError(f"{name} must be a square matrix, got shape {M.shape}")
    scale = max(float(np.max(np.abs(M))), np.finfo(float).tiny)
    asym = float(np.max(np.abs(M - M.T)))
    if asym > rtol * scale:
        raise ValueError(f"{name} must be symmetric: max |M - M^T| = {asym:.3g} "
                         f"(relative {asym / scale:.3g}); pass (M + M.T) / 2 if that is what you mean")
