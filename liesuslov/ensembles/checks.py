"""Small checks of the ensemble's own arguments (the integrator checks the rest)."""

from __future__ import annotations

import numpy as np


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
