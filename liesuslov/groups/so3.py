"""so(3) by components: Rodrigues and the so(3) closed forms on rotation vectors, for one element or a batch."""

from __future__ import annotations

import math

import numpy as np

from .common import _DEXP3_TAYLOR, _SINC_TAYLOR, _Coef, _rodrigues


# ---------------------------------------------------------------------------- so(3) by components
# Every so(3) map of this module has the form v ↦ c v + a w × v + b (w·v) w, or as a matrix
# c I + a hat(w) + b w wᵀ. It is written once, on components that are Python floats for a single
# element (no numpy call at all) or arrays of shape (...) for a batch (contiguous 1-D arithmetic:
# (..., 3, 3) broadcasting and np.matmul on stacked 3×3 matrices cost ~10x more per element).
def _vee_c(X: np.ndarray) -> tuple:
    """Components of ``w = vee(X) = (X21, X02, X10)`` of (..., 3, 3); floats for a single matrix."""
    if X.size == 9:  # (3, 3), (1, 3, 3), …: flat indices of (2, 1), (0, 2), (1, 0)
        return X.item(7), X.item(2), X.item(3)
    return X[..., 2, 1], X[..., 0, 2], X[..., 1, 0]


def _vec_c(v: np.ndarray) -> tuple:
    """Components of (..., 3); floats for a single vector."""
    if v.size == 3:
        return v.item(0), v.item(1), v.item(2)
    return v[..., 0], v[..., 1], v[..., 2]


def _vec4_c(v: np.ndarray) -> tuple:
    """Components of (..., 4); floats for a single vector."""
    if v.size == 4:
        return v.item(0), v.item(1), v.item(2), v.item(3)
    return v[..., 0], v[..., 1], v[..., 2], v[..., 3]


def _sq(w: tuple) -> _Coef:
    return w[0] * w[0] + w[1] * w[1] + w[2] * w[2]


def _stack(parts: tuple, tail: tuple[int, ...], *leads: tuple[int, ...]) -> np.ndarray:
    """Components -> (batch, *tail), batch the broadcast of the inputs' leading shapes ``leads``.

    The parts are all floats (every input a single element, leading shapes all ones) or all arrays
    of one shape (each part depends on every input); a single-element input with more leading axes
    than the batched ones is the only case that needs an explicit broadcast.
    """
    if isinstance(parts[0], float):
        return np.array(parts).reshape((1,) * max(map(len, leads)) + tail)
    shape = parts[0].shape
    if max(map(len, leads)) > len(shape):
        shape = np.broadcast_shapes(shape, *leads)
    return np.stack(parts, -1).reshape(shape + tail)


def _so3_lin_c(c: _Coef, a: _Coef, b: _Coef, w: tuple, v: tuple) -> tuple:
    """Components of ``c v + a w × v + b (w·v) w``."""
    w0, w1, w2 = w
    v0, v1, v2 = v
    d = b * (w0 * v0 + w1 * v1 + w2 * v2)
    return (c * v0 + a * (w1 * v2 - w2 * v1) + d * w0,
            c * v1 + a * (w2 * v0 - w0 * v2) + d * w1,
            c * v2 + a * (w0 * v1 - w1 * v0) + d * w2)


def _so3_lin(c: _Coef, a: _Coef, b: _Coef, w: tuple, v: tuple, *leads: tuple[int, ...]) -> np.ndarray:
    """``c v + a w × v + b (w·v) w`` -> (..., 3)."""
    return _stack(_so3_lin_c(c, a, b, w, v), (3,), *leads)


def _so3_mat(c: _Coef, a: _Coef, b: _Coef, w: tuple, lead: tuple[int, ...]) -> np.ndarray:
    """``c I + a hat(w) + b w wᵀ`` -> (..., 3, 3)."""
    w0, w1, w2 = w
    bw0, bw1, bw2 = b * w0, b * w1, b * w2
    o01, o02, o12 = bw0 * w1, bw0 * w2, bw1 * w2
    aw0, aw1, aw2 = a * w0, a * w1, a * w2
    return _stack((c + bw0 * w0, o01 - aw2, o02 + aw1,
                   o01 + aw2, c + bw1 * w1, o12 - aw0,
                   o02 - aw1, o12 + aw0, c + bw2 * w2), (3, 3), lead)


def _hat_c(w: tuple, *leads: tuple[int, ...]) -> np.ndarray:
    """``hat(w)`` -> (..., 3, 3) from components."""
    w0, w1, w2 = w
    z = 0.0 * w0
    return _stack((z, -w2, w1, w2, z, -w0, -w1, w0, z), (3, 3), *leads)


def _sinc_half(t2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(x, s, sin x, cos x)`` with ``x = θ/2`` and ``s = sin x / x`` (1 at 0), for an array of ``θ²``.

    No Taylor branch: ``sin x / x`` has no cancellation, so the quotient is accurate to rounding for
    every x > 0; only x = 0 needs a value (``np.divide(..., where=)``, no 0/0 warning).
    """
    x = np.sqrt(0.25 * t2)
    sx, cx = np.sin(x), np.cos(x)
    s = np.divide(sx, x, out=np.ones_like(x), where=x > 0.0)
    return x, s, sx, cx


# For a large batch whose angles all satisfy θ² <= _POLY_T2, sin θ/θ and (1 − cos θ)/θ² come from their
# Taylor polynomials Σ_k<K (−θ²)^k/(2k+1)! and Σ_k<K (−θ²)^k/(2k+2)!, K the fewest terms whose first
# dropped one, at most (θ²)^K/(2K+1)!, is below 2^-60 (K = 9 at θ² = 0.25, 4 at 1e-3): to rounding,
# and a few multiply-adds per element instead of np.sin and np.cos (~8 ns per element each). Small
# batches keep the trigonometric functions (fewer numpy calls).
_POLY_T2 = 0.25
_POLY_MIN_SIZE = 512
_SINC_POLY = tuple((-1.0) ** k / math.factorial(2 * k + 1) for k in range(9))
_VERS_POLY = tuple((-1.0) ** k / math.factorial(2 * k + 2) for k in range(9))
_POLY_TERMS = tuple(((2.0**-60 * math.factorial(2 * K + 1)) ** (1.0 / K), K) for K in range(2, 10))


def _horner(t: np.ndarray, coef: tuple[float, ...]) -> np.ndarray:
    out = coef[-1] * t + coef[-2]
    for a in coef[-3::-1]:
        out *= t
        out += a
    return out


def _rodrigues_poly(t2: np.ndarray, top: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_rodrigues` by Taylor polynomials, for arrays with ``max θ² = top <= _POLY_T2``."""
    K = next(K for bound, K in _POLY_TERMS if top <= bound)
    a = _horner(t2, _SINC_POLY[:K])
    b = _horner(t2, _VERS_POLY[:K])
    return 1.0 - b * t2, a, b


def _dexp3_series(t2: _Coef) -> _Coef:
    return 1.0 / 12.0 + t2 * (1.0 / 720.0 + t2 * (1.0 / 30240.0 + t2 * (1.0 / 1209600.0 + t2 / 47900160.0)))


def _rodrigues_dexp3(t2: _Coef) -> tuple[_Coef, _Coef, _Coef, _Coef]:
    """``_rodrigues(t2) + (_dexp3_coefficient(t2),)`` from one sine and one cosine of θ/2.

    The RKMK stage on so(3) needs both the exponential (to move the vertical) and the exact
    dexp⁻¹ at the same Θ; for a batch the transcendental functions dominate, so they are shared.
    Same formulas and thresholds as the two functions (the sinc branch only avoids 0/0, see
    :func:`_sinc_half`).
    """
    if not isinstance(t2, np.ndarray):
        x2 = 0.25 * t2
        x = math.sqrt(x2)
        sx, cx = math.sin(x), math.cos(x)
        s = 1.0 - x2 * (1.0 / 6.0 - x2 / 120.0) if x < _SINC_TAYLOR else sx / x
        c = _dexp3_series(t2) if t2 < _DEXP3_TAYLOR**2 else (1.0 - x * cx / sx) / t2
    else:
        top = t2.max(initial=0.0)
        if top < _DEXP3_TAYLOR**2 and t2.size >= _POLY_MIN_SIZE:  # usual in a step, |Θ| = O(h): polynomials
            return _rodrigues_poly(t2, top) + (_dexp3_series(t2),)
        x, s, sx, cx = _sinc_half(t2)
        c = _dexp3_series(t2)
        big = t2 >= _DEXP3_TAYLOR**2
        if big.any():
            c[big] = (1.0 - x[big] * cx[big] / sx[big]) / t2[big]
    b = 0.5 * s * s
    return 1.0 - b * t2, s * cx, b, c


def _rodrigues_fast(t2: _Coef) -> tuple[_Coef, _Coef, _Coef]:
    """:func:`_rodrigues`; for a batch by polynomials (small angles) or without ``np.where`` branches."""
    if not isinstance(t2, np.ndarray) or t2.size == 1:
        return _rodrigues(t2)
    if t2.size >= _POLY_MIN_SIZE:
        top = t2.max(initial=0.0)
        if top <= _POLY_T2:
            return _rodrigues_poly(t2, top)
    _, s, _, cx = _sinc_half(t2)
    b = 0.5 * s * s
    return 1.0 - b * t2, s * cx, b
