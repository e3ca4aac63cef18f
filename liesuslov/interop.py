"""Conversions to and from geomstats (2.8.0): SO(n), so(n) coordinates, the sphere S^{n-1}.

geomstats is imported lazily, on the first call that needs it, never by ``import liesuslov``.
That import is guarded: ``GEOMSTATS_BACKEND`` is set to ``numpy`` if unset (any other backend is
refused with a :class:`RuntimeError`), and the root logger's level, handlers and filters are
restored afterwards (geomstats calls ``logging.basicConfig`` and sets the root level to INFO when
imported; your logging configuration stays as it was).

What differs between the two libraries, and what does not:

* **SO(n) points** are rotation matrices in both, shape ``(..., n, n)``:
  :func:`rotation_to_geomstats` and :func:`rotation_from_geomstats` only validate and copy.
* **so(n) as matrices**: identical skew-symmetric matrices.
* **so(n) coordinates** differ for n = 2 and n = 3. Ours are on ``E_ij = e_i e_j^T - e_j e_i^T``
  (i < j, lexicographic). geomstats' ``SkewSymmetricMatrices(n).basis`` is
  ``[[0, -1], [1, 0]] = -E_12`` for n = 2, ``hat(e_1), hat(e_2), hat(e_3)`` = ``-E_23, +E_13, -E_12``
  for n = 3 (its coordinates are the vector ``w`` of ``hat(w) v = w x v``), and ``E_ij`` as ours
  for n >= 4. :func:`algebra_to_geomstats` / :func:`algebra_from_geomstats` convert, with the
  signed permutation :func:`geomstats_basis` read off geomstats' own basis.
* **Rotation vectors** (geomstats' ``SpecialOrthogonal(n, point_type="vector")``, n = 2, 3) are the
  geomstats coordinates of ``log g``: ``g = expm(hat3(r))`` for n = 3 (``r`` = ``w``) and
  ``g = [[cos r, -sin r], [sin r, cos r]]`` for n = 2. See :func:`rotation_vector_from_matrix` and
  :func:`matrix_from_rotation_vector`.
* **Sphere points**: unit vectors of R^n in both (``Hypersphere(dim=n - 1)``, extrinsic
  coordinates): :func:`sphere_to_geomstats` and :func:`sphere_from_geomstats` validate and copy.

Every function is batched over leading axes. Invalid points raise :class:`ValueError` naming the
argument.

Examples
--------
>>> import numpy as np
>>> from liesuslov import interop
>>> interop.algebra_to_geomstats(np.array([1.0, 2.0, 3.0]))  # so(3): (x12, x13, x23) -> w
array([-3.,  2., -1.])
"""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from functools import lru_cache
from types import ModuleType
from typing import Any

import numpy as np

from ._validation import as_float_array
from .algebra.so import so

__all__ = ["import_geomstats", "geomstats_special_orthogonal", "geomstats_skew_symmetric_matrices",
           "geomstats_hypersphere", "geomstats_basis", "algebra_to_geomstats", "algebra_from_geomstats",
           "rotation_to_geomstats", "rotation_from_geomstats", "rotation_vector_from_matrix",
           "matrix_from_rotation_vector", "sphere_to_geomstats", "sphere_from_geomstats"]

#: Default tolerance of the membership checks: ``max |g^T g - I|`` for SO(n), ``| |x| - 1 |`` for spheres.
ATOL = 1e-8

_HOW_TO_FIX = ("liesuslov.interop needs geomstats' numpy backend: set the environment variable "
               "GEOMSTATS_BACKEND=numpy before geomstats is first imported (e.g. "
               "`GEOMSTATS_BACKEND=numpy python script.py`, or os.environ['GEOMSTATS_BACKEND'] = 'numpy' "
               "at the top of the script, before any import of geomstats)")


# ---------------------------------------------------------------------------- guarded import
@contextmanager
def _root_logging_preserved() -> Iterator[None]:
    """Restore the root logger's level, handlers and filters (and ``logging.disable``) on exit."""
    root = logging.getLogger()
    level, handlers, filters = root.level, root.handlers[:], root.filters[:]
    disabled = logging.root.manager.disable
    try:
        yield
    finally:
        added = [h for h in root.handlers if h not in handlers]
        root.handlers[:] = handlers
        root.filters[:] = filters
        root.setLevel(level)
        logging.disable(disabled)
        for h in added:  # handlers geomstats' basicConfig created; closing one never closes stderr
            h.close()


def _loaded_backend() -> str | None:
    """The backend of an already imported geomstats, or None if geomstats is not imported yet."""
    backend_module = sys.modules.get("geomstats._backend")
    return None if backend_module is None else getattr(backend_module, "BACKEND_NAME", None)


def import_geomstats() -> ModuleType:
    """Import geomstats with the numpy backend, leaving the user's logging configuration untouched.

    Sets ``GEOMSTATS_BACKEND=numpy`` if the variable is unset.

    Returns
    -------
    module
        The ``geomstats`` package (its ``geometry`` subpackage loaded).

    Raises
    ------
    RuntimeError
        If ``GEOMSTATS_BACKEND`` names another backend, or geomstats was already imported with one.
    ImportError
        If geomstats is not installed.
    """
    backend = _loaded_backend()
    if backend is None:
        backend = os.environ.setdefault("GEOMSTATS_BACKEND", "numpy")
        source = "the environment variable GEOMSTATS_BACKEND"
    else:
        source = "the already imported geomstats"
    if backend != "numpy":
        raise RuntimeError(f"geomstats backend is {backend!r} (from {source}); {_HOW_TO_FIX}")
    with _root_logging_preserved():
        try:
            import geomstats
            import geomstats.geometry.hypersphere
            import geomstats.geometry.skew_symmetric_matrices
            import geomstats.geometry.special_orthogonal  # noqa: F401
        except ImportError as exc:
            raise ImportError("liesuslov.interop needs geomstats, an optional extra: pip install "
                              "'liesuslov[geomstats]' (geomstats 2.8.0, which needs numpy < 2.4)") from exc
    backend = _loaded_backend()
    if backend != "numpy":  # pragma: no cover - only if geomstats changes how it picks a backend
        raise RuntimeError(f"geomstats loaded the backend {backend!r}; {_HOW_TO_FIX}")
    return geomstats


def geomstats_special_orthogonal(n: int, point_type: str = "matrix", **kwargs: Any) -> Any:
    """geomstats' ``SpecialOrthogonal(n, point_type)``, imported with :func:`import_geomstats`."""
    n = so(n).n
    import_geomstats()
    from geomstats.geometry.special_orthogonal import SpecialOrthogonal

    with _root_logging_preserved():
        return SpecialOrthogonal(n, point_type=point_type, **kwargs)


def geomstats_skew_symmetric_matrices(n: int) -> Any:
    """geomstats' so(n), ``SkewSymmetricMatrices(n)``, imported with :func:`import_geomstats`."""
    n = so(n).n
    import_geomstats()
    from geomstats.geometry.skew_symmetric_matrices import SkewSymmetricMatrices

    with _root_logging_preserved():
        return SkewSymmetricMatrices(n)


def geomstats_hypersphere(n: int | None = None, *, dim: int | None = None) -> Any:
    """geomstats' ``Hypersphere(dim=n - 1)``: the unit vectors of R^n (where Γ of an SO(n) body lives).

    Give the ambient dimension ``n`` (the length of Γ) or, as geomstats' own ``Hypersphere(dim)`` takes
    it, the dimension ``dim = n - 1`` of the sphere: ``geomstats_hypersphere(3)`` and
    ``geomstats_hypersphere(dim=2)`` are both S^2 in R^3. Passing both is allowed only when they agree,
    since a sphere of the wrong size silently answers ``belongs = False`` for every point.

    Parameters
    ----------
    n : int, optional
        Ambient dimension, n >= 2.
    dim : int, optional (keyword)
        Dimension of the sphere, dim >= 1.

    Raises
    ------
    TypeError
        If neither is given.
    ValueError
        If both are given and ``dim != n - 1``, or either is out of range.
    """
    if n is None and dim is None:
        raise TypeError("geomstats_hypersphere needs the ambient dimension n (the length of Gamma) or, as "
                        "geomstats' Hypersphere(dim) takes it, dim = n - 1 (keyword)")
    if dim is not None:
        if isinstance(dim, bool) or not isinstance(dim, (int, np.integer)) or dim < 1:
            raise ValueError(f"dim (the sphere's dimension, n - 1) must be an integer >= 1, got {dim!r}")
        if n is not None and n != dim + 1:
            raise ValueError(f"n = {n} (ambient dimension) and dim = {dim} (sphere dimension) disagree: dim must be "
                             f"n - 1; pass one of them (geomstats_hypersphere({dim + 1}) or dim={dim} is S^{dim} "
                             f"in R^{dim + 1})")
        n = int(dim) + 1
    n = so(n).n
    import_geomstats()
    from geomstats.geometry.hypersphere import Hypersphere

    with _root_logging_preserved():
        return Hypersphere(dim=n - 1)


# ---------------------------------------------------------------------------- so(n) coordinates
@lru_cache(maxsize=32)
def _basis_change(n: int) -> tuple[np.ndarray, np.ndarray]:
    basis = np.asarray(geomstats_skew_symmetric_matrices(n).basis, dtype=float)
    T = so(n).vee(basis)  # row k: our coordinates of geomstats' k-th basis matrix
    if not np.allclose(so(n).hat(T), basis, rtol=0, atol=1e-14):  # pragma: no cover
        raise RuntimeError(f"geomstats' so({n}) basis is not skew-symmetric; unsupported geomstats version")
    T_inv = np.linalg.inv(T)
    T.setflags(write=False)
    T_inv.setflags(write=False)
    return T, T_inv


def geomstats_basis(n: int) -> np.ndarray:
    """The change of basis ``T`` (d, d) from geomstats' so(n) coordinates to ours: ``x = c @ T``.

    Row k holds our coordinates of geomstats' k-th basis matrix. It is a signed permutation:
    ``[[-1]]`` for n = 2; for n = 3 ``c = w = (-x_23, x_13, -x_12)``, i.e. ``x = (-c_3, c_2, -c_1)``;
    the identity for n >= 4. Read-only.
    """
    return _basis_change(so(n).n)[0]


def _n_from_dim(d: int, name: str) -> int:
    n = int(round((1 + np.sqrt(1 + 8 * d)) / 2))
    if d < 1 or n * (n - 1) // 2 != d:
        raise ValueError(f"{name} must have shape (..., n (n - 1) / 2) (so(n) coordinates, n >= 2), "
                         f"got a last axis of length {d}")
    return n


def algebra_to_geomstats(x) -> np.ndarray:
    """Our so(n) coordinates to geomstats' ``SkewSymmetricMatrices(n)`` coordinates.

    Parameters
    ----------
    x : array_like, shape (..., d), d = n (n - 1) / 2
        Coordinates on ``E_ij`` (i < j, lexicographic); n is read off d.

    Returns
    -------
    ndarray, shape (..., d)
        ``c`` with ``sum_k c_k basis_k = hat(x)`` for geomstats' basis (for n = 3, ``c = w``).
    """
    x = as_float_array(x, "x", ndim_min=1)
    n = _n_from_dim(x.shape[-1], "x")
    return x @ _basis_change(n)[1]


def algebra_from_geomstats(c) -> np.ndarray:
    """geomstats' so(n) coordinates back to ours; inverse of :func:`algebra_to_geomstats`.

    Parameters
    ----------
    c : array_like, shape (..., d)

    Returns
    -------
    ndarray, shape (..., d)
    """
    c = as_float_array(c, "c", ndim_min=1)
    n = _n_from_dim(c.shape[-1], "c")
    return c @ _basis_change(n)[0]


# ---------------------------------------------------------------------------- SO(n)
def _check_rotation(g, name: str, atol: float) -> np.ndarray:
    g = as_float_array(g, name, ndim_min=2)
    n = g.shape[-1]
    if g.shape[-2] != n or n < 2:
        raise ValueError(f"{name} must have shape (..., n, n) with n >= 2 (rotation matrices), got {g.shape}")
    err = float(np.max(np.abs(np.swapaxes(g, -1, -2) @ g - np.eye(n)), initial=0.0))
    if err > atol:
        raise ValueError(f"{name} is not in SO({n}): max |g^T g - I| = {err:.3g} > atol = {atol:g}; "
                         "pass orthogonal matrices (re-orthonormalise, e.g. by a polar decomposition) "
                         "or raise atol")
    det = np.linalg.det(g)
    if np.any(det <= 0):
        raise ValueError(f"{name} is not in SO({n}): determinant {float(np.min(det)):.3g} (an orthogonal "
                         "matrix with determinant -1 is a reflection, not a rotation)")
    return g


def rotation_to_geomstats(g, *, atol: float = ATOL) -> np.ndarray:
    """A rotation (our ``g``, shape (..., n, n)) as a point of geomstats' ``SpecialOrthogonal(n)``.

    Both libraries use the rotation matrix itself, so this validates and copies.

    Raises
    ------
    ValueError
        If ``g`` is not in SO(n): ``max |g^T g - I| > atol`` or ``det g <= 0``.
    """
    return np.array(_check_rotation(g, "g", atol))


def rotation_from_geomstats(point, *, atol: float = ATOL) -> np.ndarray:
    """A point of geomstats' ``SpecialOrthogonal(n)`` (matrix form) as our ``g``: validates and copies.

    Raises
    ------
    ValueError
        If ``point`` is not in SO(n).
    """
    return np.array(_check_rotation(point, "point", atol))


def _vector_group(n: int) -> Any:
    return geomstats_special_orthogonal(n, point_type="vector")


def rotation_vector_from_matrix(g, *, atol: float = ATOL) -> np.ndarray:
    """geomstats' rotation vector of ``g`` in SO(2) or SO(3): the geomstats coordinates of ``log g``.

    Parameters
    ----------
    g : array_like, shape (..., n, n), n in {2, 3}

    Returns
    -------
    ndarray, shape (..., 1) for n = 2 (the angle), (..., 3) for n = 3 (``r`` with
    ``g = expm(hat3(r))``, ``|r| <= pi``; our so(3) coordinates of ``log g`` are
    ``so(3).from_vector3(r)``).

    Raises
    ------
    ValueError
        If ``g`` is not in SO(2) or SO(3).
    """
    g = _check_rotation(g, "g", atol)
    n = g.shape[-1]
    if n not in (2, 3):
        raise ValueError(f"g must be in SO(2) or SO(3) for a rotation vector, got SO({n})")
    batch = g.shape[:-2]
    flat = g.reshape((-1, n, n))  # geomstats handles at most one batch axis
    if flat.shape[0] == 0:
        return np.zeros(batch + (n * (n - 1) // 2,))
    r = np.asarray(_vector_group(n).rotation_vector_from_matrix(flat), dtype=float)
    return r.reshape(batch + (n * (n - 1) // 2,))


def matrix_from_rotation_vector(r) -> np.ndarray:
    """The rotation matrix of a geomstats rotation vector; inverse of :func:`rotation_vector_from_matrix`.

    Parameters
    ----------
    r : array_like, shape (..., 1) (SO(2), the angle) or (..., 3) (SO(3))

    Returns
    -------
    ndarray, shape (..., n, n)
    """
    r = as_float_array(r, "r", ndim_min=1)
    if r.shape[-1] not in (1, 3):
        raise ValueError(f"r must have shape (..., 1) (SO(2)) or (..., 3) (SO(3)), got {r.shape}")
    n = 2 if r.shape[-1] == 1 else 3
    batch = r.shape[:-1]
    if r.size == 0:
        return np.zeros(batch + (n, n))
    g = np.asarray(_vector_group(n).matrix_from_rotation_vector(r.reshape((-1, r.shape[-1]))), dtype=float)
    return g.reshape(batch + (n, n))


# ---------------------------------------------------------------------------- spheres
def _check_unit(x, name: str, atol: float) -> np.ndarray:
    x = as_float_array(x, name, ndim_min=1)
    if x.shape[-1] < 2:
        raise ValueError(f"{name} must have shape (..., n) with n >= 2 (points of S^(n-1)), got {x.shape}")
    err = float(np.max(np.abs(np.linalg.norm(x, axis=-1) - 1.0), initial=0.0))
    if err > atol:
        raise ValueError(f"{name} must be unit vectors (points of the sphere S^{x.shape[-1] - 1}): "
                         f"max | |{name}| - 1 | = {err:.3g} > atol = {atol:g}; normalise it or raise atol")
    return x


def sphere_to_geomstats(Gamma, *, atol: float = ATOL) -> np.ndarray:
    """Unit vectors ``Gamma`` (..., n) as points of geomstats' ``Hypersphere(dim=n - 1)`` (extrinsic).

    Both libraries use the unit vector itself: this validates and copies.

    Raises
    ------
    ValueError
        If ``| |Gamma| - 1 | > atol`` somewhere.
    """
    return np.array(_check_unit(Gamma, "Gamma", atol))


def sphere_from_geomstats(point, *, atol: float = ATOL) -> np.ndarray:
    """Points of geomstats' ``Hypersphere(dim=n - 1)`` (extrinsic, (..., n)) as our ``Gamma``.

    Raises
    ------
    ValueError
        If ``point`` is not of unit norm.
    """
    return np.array(_check_unit(point, "point", atol))
