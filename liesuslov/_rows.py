"""Products of a batch of rows with a matrix that give every row the same bits alone or in any batch."""

from __future__ import annotations

import numpy as np

__all__ = ["rows_at", "vectors", "matrices", "paired"]


def rows_at(x, M) -> np.ndarray:
    """``x @ M`` for a batch of rows, summed in one order for every row: a row's result does not depend on
    the batch it is in.

    numpy's ``matmul`` hands a batch to BLAS, whose kernels sum a row differently according to its
    position in the batch (measured on this project's machine: at every shape tried, up to all 2000 rows of
    a batch differ in the last bits from the same rows alone); ``einsum`` without ``optimize`` runs numpy's
    own loop, the same for every row. The integrators' batches rely on it (a trajectory's numbers are the
    same alone or in any batch).

    Parameters
    ----------
    x : array_like, shape (..., p)
    M : array_like, shape (p, q) or (p,)

    Returns
    -------
    ndarray, shape (..., q), or (...) for a vector ``M``
    """
    return np.einsum("...i,i->..." if np.ndim(M) == 1 else "...i,ij->...j", x, M)


def real_floats(x, name: str, must: str = "must be real numbers") -> np.ndarray:
    """``x`` as floats; a complex (or non-numeric) array is a TypeError ``f"{name} {must}, got ..."`` (numpy would
    drop the imaginary part with a warning). One dtype test on arrays that are floats already. The one such
    check: of inputs (hat, vee, vectors) and of what user callables return (potentials)."""
    x = np.asarray(x)
    if x.dtype != np.float64:
        if x.dtype.kind not in "fiub":
            raise TypeError(f"{name} {must}, got an array of {x.dtype}")
        x = x.astype(float)
    return x


def vectors(x, name: str, size: int, owner: object = None) -> np.ndarray:
    """``x`` as a float array of vectors (..., size), or a ``ValueError`` naming it (and ``owner``, e.g. the
    algebra) — the check of the batch methods of the algebra layer (numpy's IndexError or broadcasting
    message named neither the argument nor the size it needs)."""
    x = real_floats(x, name)
    if x.shape[-1:] != (size,):
        where = "" if owner is None else f" for {owner}"
        raise ValueError(f"{name} must have shape (..., {size}){where}, got {x.shape}")
    return x


def matrices(x, name: str, size: int, owner: object = None) -> np.ndarray:
    """``x`` as a float array of square matrices (..., size, size), or a ``ValueError`` naming it (numpy would
    read the entries it indexes of a matrix of another size, or fail naming neither)."""
    x = real_floats(x, name)
    if x.shape[-2:] != (size, size):
        where = "" if owner is None else f" for {owner}"
        raise ValueError(f"{name} must have shape (..., {size}, {size}){where}, got {x.shape}")
    return x


def paired(x: np.ndarray, y: np.ndarray, names: str, core: int = 1) -> None:
    """Raise a ``ValueError`` naming ``names`` (e.g. "x and y") when the batch shapes of ``x`` and ``y`` (all but
    their last ``core`` axes) do not broadcast: numpy's message names neither argument (and a batched
    product of matrices speaks of "remapped shapes")."""
    a, b = x.shape[:x.ndim - core], y.shape[:y.ndim - core]
    try:
        np.broadcast_shapes(a, b)
    except ValueError:
        raise ValueError(f"{names} must have batch shapes that broadcast (equal, or 1 where they differ), got "
                         f"{x.shape} and {y.shape}") from None
