"""Reading algebra elements and moving vectors between frames: the one place for each.

* :func:`omega_coordinates` — ``Omega`` given as matrices of the representation (skew on so(n)) *or*
  as coordinates, to coordinates ``(..., d)``: used by the systems, the integrators and the reductions.
* :func:`body_vector` — ``Gamma = g^T gamma``: a vector fixed in space (the field direction gamma)
  written in the body frame of the attitude ``g``; :func:`space_vector` is its inverse ``gamma = g Gamma``.
"""

from __future__ import annotations

import numpy as np

from .._validation import as_float_array

__all__ = ["omega_coordinates", "body_vector", "space_vector"]

#: Relative tolerance (times max |X|) for a matrix to count as in the algebra's image.
OMEGA_MATRIX_RTOL = 1e-12
#: Where d == m (so(3), se(2)) an (m, m) array off the image by more than OMEGA_MATRIX_RTOL but less than this
#: (relative) is refused rather than read as m coordinate vectors: matrices with an error, most likely.
OMEGA_MATRIX_NEAR = 1e-6


def omega_coordinates(algebra, Omega, name: str = "Omega") -> np.ndarray:
    """``Omega`` as coordinates ``(..., d)`` from representation matrices ``(..., m, m)`` or coordinates.

    Parameters
    ----------
    algebra : LieAlgebra
        The algebra (dimension ``d``, representation of size ``m`` or none).
    Omega : array_like, shape (..., m, m) or (..., d)
        An array whose trailing ``(m, m)`` block lies in the image of the representation (skew-symmetric
        on so(n), to ``1e-12 max |Omega|``: relative) is read as matrices, ``vee(Omega)``; otherwise the
        last axis must be the ``d`` coordinates. On so(3) and se(2) (``d = m = 3``) a stack of three
        coordinate vectors that happens to be skew is read as a matrix, and one within ``1e-6`` (relative) of
        a matrix is refused as ambiguous: pass another batch shape, or matrices.
    name : str
        The argument's name for the error messages.

    Returns
    -------
    ndarray, shape (..., d)

    Raises
    ------
    TypeError
        Not a real numeric array (complex values included).
    ValueError
        Non-finite values; ``(m, m)`` matrices outside the algebra (not skew on so(n)) when ``d != m``, or
        near it when ``d == m``; a last axis that is neither.
    """
    X = as_float_array(Omega, name, ndim_min=1)
    d, m = algebra.dim, algebra.matrix_size
    is_so = algebra.name.startswith("so(")
    if m is not None and X.ndim >= 2 and X.shape[-2:] == (m, m):
        x = algebra.vee(X)
        scale = float(np.max(np.abs(X), initial=0.0))  # relative: a small Omega is tested as a large one
        if np.allclose(algebra.hat(x), X, rtol=0, atol=OMEGA_MATRIX_RTOL * scale):
            return x
        what = "skew-symmetric" if is_so else f"in the image of {algebra.name}'s representation"
        defect = float(np.max(np.abs(algebra.hat(x) - X), initial=0.0))
        if X.shape[-1] != d:  # (m, m) could also be m coordinate vectors only when d == m
            raise ValueError(f"{name} as ({m}, {m}) matrices must be {what} (largest defect {defect:.3g}); "
                             f"or pass coordinates of shape (..., {d})")
        if defect <= OMEGA_MATRIX_NEAR * scale:  # d == m: matrices off by more than rounding, not vectors
            raise ValueError(f"{name} of shape {X.shape}: ({m}, {m}) matrices must be {what} to "
                             f"{OMEGA_MATRIX_RTOL:g} max|{name}| (largest defect {defect:.3g}); {m} coordinate "
                             f"vectors this close to a matrix of {algebra.name} are ambiguous: pass them with "
                             f"another batch shape, e.g. (..., {m}, 1, {d})")
    if X.shape[-1] != d:
        shapes = f"(..., {m}, {m}) matrices or " if m is not None else ""
        raise ValueError(f"{name} must be {shapes}(..., {d}) coordinates in {algebra.name}, got shape {X.shape}")
    return X


def body_vector(g, gamma) -> np.ndarray:
    """``Gamma = g^T gamma``: the space vector ``gamma`` in the body frame of ``g``.

    Parameters
    ----------
    g : array_like, shape (..., m, m)
        Attitudes (rotations; not checked).
    gamma : array_like, shape (..., m)
        Vectors fixed in space; batch axes broadcast with those of ``g``.

    Returns
    -------
    ndarray, shape (..., m)
        ``Gamma_i = sum_j g_ji gamma_j``.
    """
    g = np.asarray(g, dtype=float)
    gamma = np.asarray(gamma, dtype=float)
    # gamma^T g as a (1, m) @ (m, m) product: one BLAS call per matrix, no transposed copy of g
    return np.matmul(gamma[..., None, :], g)[..., 0, :]


def space_vector(g, Gamma) -> np.ndarray:
    """``gamma = g Gamma``: the body vector ``Gamma`` in space, the inverse of :func:`body_vector`.

    Shapes as in :func:`body_vector`: (..., m, m), (..., m) -> (..., m).
    """
    g = np.asarray(g, dtype=float)
    Gamma = np.asarray(Gamma, dtype=float)
    return np.matmul(g, Gamma[..., :, None])[..., 0]
