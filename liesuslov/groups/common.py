"""Small helpers shared by the group maps: identity matrices, linear solves, cross products, the so(3) coefficients."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

# cyclic index permutations for the component-wise cross product
_I = np.array((2, 0, 1), dtype=np.intp)
_J = np.array((1, 2, 0), dtype=np.intp)

# Below this half-angle, sin(x)/x is replaced by its Taylor polynomial 1 − x²/6 + x⁴/120, whose
# truncation error x⁶/5040 < 2e-28 is far below rounding. The branch only avoids 0/0: sin(x)/x has
# no cancellation for x > 0, and (1 − cos θ)/θ² is formed as ½ (sin(θ/2)/(θ/2))², which has none
# either, so the threshold is not accuracy-critical.
_SINC_TAYLOR = 1e-4

# Below this angle the dexp⁻¹ coefficient (1 − (θ/2) cot(θ/2)) / θ² (which cancels like
# ε/θ² near 0) is taken from its series Σ |B_2k| θ^(2k−2) / (2k)!, kept through θ⁸: the next term
# θ¹⁰/1.9e9 is < 1e-19 relative to 1/12 for θ < 0.1.
_DEXP3_TAYLOR = 0.1


# ---------------------------------------------------------------------------- small helpers
@lru_cache(maxsize=32)
def _eye(n: int) -> np.ndarray:
    """Read-only identity, shared (allocating one per call costs as much as an add)."""
    eye = np.eye(n)
    eye.setflags(write=False)
    return eye


def _solve(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A⁻¹ B`` for (..., n, n) and (..., n, k); a single real system goes straight to LAPACK ``dgesv``.

    ``np.linalg.solve`` spends ~3 µs in Python wrappers on one small system, ``dgesv`` ~1 µs.
    """
    n, k = B.shape[-2:]
    if A.size == n * n and B.size == n * k and A.dtype == np.float64 and B.dtype == np.float64:
        from scipy.linalg.lapack import dgesv  # scipy.linalg loads on first use, not on import

        x, info = dgesv(A.reshape(n, n), B.reshape(n, k))[2:]  # one system, whatever its unit axes
        if info:
            raise np.linalg.LinAlgError("Singular matrix")
        if A.ndim == 2 and B.ndim == 2:
            return x
        return x.reshape((1,) * (max(A.ndim, B.ndim) - 2) + (n, k))  # leading axes all have length 1
    return np.linalg.solve(A, B)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product keeping the last axis: (..., n), (..., n) -> (..., 1) (a scalar for 1-D)."""
    if a.ndim == 1 and b.ndim == 1:
        return a @ b
    return (a * b).sum(-1, keepdims=True)


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product ``a × b`` of 3-vectors by components (``np.cross`` is ~5x slower per call).

    Parameters
    ----------
    a, b : ndarray, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3)
        ``(a1 b2 − a2 b1, a2 b0 − a0 b2, a0 b1 − a1 b0)``.
    """
    return a[..., _J] * b[..., _I] - a[..., _I] * b[..., _J]


_Coef = float | np.ndarray  # a coefficient: a Python float for one element, an array for a batch


def _rodrigues(t2: _Coef) -> tuple[_Coef, _Coef, _Coef]:
    """``(cos θ, sin θ/θ, (1 − cos θ)/θ²)`` from ``θ²``, accurate to rounding for every θ ≥ 0.

    Written with the half angle ``x = θ/2`` and ``s = sin x / x``: ``sin θ/θ = s cos x``,
    ``(1 − cos θ)/θ² = s²/2`` and ``cos θ = 1 − 2 (s x)²`` — no cancellation anywhere. A single
    value is computed with ``math`` (numpy spends ~0.5 µs per call on tiny arrays).
    """
    if not isinstance(t2, np.ndarray) or t2.size == 1:
        t2 = float(t2) if not isinstance(t2, np.ndarray) else t2.item()
        x2 = 0.25 * t2
        x = math.sqrt(x2)
        s = 1.0 - x2 * (1.0 / 6.0 - x2 / 120.0) if x < _SINC_TAYLOR else math.sin(x) / x
        b = 0.5 * s * s
        return 1.0 - b * t2, s * math.cos(x), b
    x2 = 0.25 * t2
    x = np.sqrt(x2)
    small = x < _SINC_TAYLOR
    xs = np.where(small, 1.0, x)  # keeps sin(xs)/xs finite where the branch is not used
    s = np.where(small, 1.0 - x2 * (1.0 / 6.0 - x2 / 120.0), np.sin(xs) / xs)
    b = 0.5 * s * s
    return 1.0 - b * t2, s * np.cos(x), b


def _cayley_coefficients(t2: _Coef) -> tuple[_Coef, _Coef, _Coef]:
    """``((4 − θ²)/(4 + θ²), 4/(4 + θ²), 2/(4 + θ²))``: cay = c I + a Ω + b (Ω² + θ² I) for Ω³ = −θ²Ω."""
    k = 2.0 / (4.0 + t2)
    return 1.0 - k * t2, 2.0 * k, k
