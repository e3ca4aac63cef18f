"""Input checks of the reduction layer that are specific to it (the shared ones are in :mod:`liesuslov._validation`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import unit_vectors

TANGENT_TOL = 1e-8  # |<q, v>| <= tol * max(1, |v|)
UNIT_TOL = 1e-8  # |q| = 1, |gamma| = 1 (as integrate's check of Gamma0)
ORTHO_TOL = 1e-8  # |g^T g - I| for attitudes (as integrate's check of g0)


def unit(x: np.ndarray, name: str) -> np.ndarray:
    """``x / |x|`` after checking ``| |x| - 1 | <= UNIT_TOL``."""
    return unit_vectors(x, name, tol=UNIT_TOL)


def tangent(q: np.ndarray, v: np.ndarray, name_q: str, name_v: str) -> np.ndarray:
    """``v - <q, v> q`` after checking that ``v`` is tangent to the sphere at the unit ``q``."""
    dot = np.sum(q * v, axis=-1)
    scale = np.maximum(1.0, np.linalg.norm(v, axis=-1))
    if dot.size and np.any(np.abs(dot) > TANGENT_TOL * scale):
        raise ValueError(f"{name_v} must be tangent to the sphere at {name_q} (<{name_q}, {name_v}> = 0); "
                         f"got |<{name_q}, {name_v}>| up to {np.max(np.abs(dot)):.3g}: pass "
                         f"{name_v} - <{name_q}, {name_v}> {name_q}")
    return v - dot[..., None] * q


def dim_n(n: Any) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise TypeError(f"n must be an integer >= 2, got {type(n).__name__}")
    if n < 2:
        raise ValueError(f"n must be >= 2 (the pendulum lives on S^(n-1)), got {n}")
    return int(n)
