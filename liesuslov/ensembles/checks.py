"""Small checks of the ensemble's own arguments (the integrator checks the rest)."""

from __future__ import annotations

import numpy as np


def _as_given(v, name: str, core: int) -> np.ndarray:
    """Gamma0 or g0 for the chunks: a floating array as given (float32 stays float32, so that each chunk's
    integrate grants it float32's tolerance, as one call on the whole batch does), anything else as floats."""
    from .._validation import as_float_array

    a = np.asarray(v)
    if np.issubdtype(a.dtype, np.floating) and a.ndim >= core:
        return a
    return as_float_array(v, name, ndim_min=core)


def _naming(exc: OSError, message: str) -> OSError:
    """``exc``'s class and errno with ``message`` (the argument named, the fix): the system's reason, said."""
    return type(exc)(message) if exc.errno is None else type(exc)(exc.errno, message, exc.filename)


def _positive_int(v, name: str) -> int:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"{name} must be a positive integer, got {type(v).__name__}")
    if v < 1:
        raise ValueError(f"{name} must be a positive integer, got {v}")
    return int(v)


def _nonneg_int(v, name: str) -> int:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"{name} must be an integer >= 0, got {type(v).__name__}")
    if v < 0:
        raise ValueError(f"{name} must be an integer >= 0, got {v}")
    return int(v)
