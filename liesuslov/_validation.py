"""Small named checks shared by every layer.

Each check names the argument it inspects and says how to fix the call, so the public functions
stay readable: ``x = as_float_array(x, "Omega0")``.
"""

from __future__ import annotations

import functools
import math
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
    if not (isinstance(x, np.ndarray) and x.dtype.kind in "iuf"):  # (the common case, checked cheaply)
        given = x
        try:
            x = np.asarray(x)  # its own dtype first: what float conversion would hide
        except ValueError as exc:  # nested sequences of unequal lengths
            raise ValueError(f"{name} must be a rectangular array (nested sequences of equal lengths), got a "
                             f"ragged {type(x).__name__}") from exc
        kind = x.dtype.kind
        # float(complex) would drop the imaginary part with only a warning, float("0.3") and float(True) would
        # read them: each is a wrong type. numpy hides them in a number dtype ([True, 1.0] is float64) or an
        # object one: the given sequence is searched then.
        what = {"c": "complex values", "b": "booleans", "U": "strings", "S": "strings"}.get(kind)
        if what is None and kind == "O":
            what = _foreign_scalars(x.ravel().tolist())
        elif what is None and isinstance(given, (list, tuple)):
            what = _foreign_scalars(given)
        if what == "complex values":
            raise TypeError(f"{name} must be real, got complex values; pass the real part explicitly "
                            f"(np.real({name})) if the imaginary part is rounding noise")
        if what is not None:
            raise TypeError(f"{name} must be a real numeric array, got {what}; pass numbers")
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
    if finite and not all_finite(arr):
        raise ValueError(f"{name} contains NaN or infinite values; pass finite numbers")
    return arr


#: Largest array whose finiteness :func:`all_finite` tests on Python floats.
_SMALL = 32
#: Longest vector whose squared norm numpy's reduction sums one entry after the other (from 8 entries on it
#: sums eight partial sums): up to this length a sum on Python floats is bitwise numpy's.
_SEQUENTIAL_MAX = 7


def read_only(x: Any) -> np.ndarray:
    """``x`` as a float array that cannot be written through: what a user callable is given of the solver's state.

    A view (no copy, ~0.3 µs) with ``writeable = False``: a callable that assigns into its argument (``G[...] =
    0``) raises numpy's "assignment destination is read-only" instead of changing the state being integrated."""
    view = np.asarray(x, dtype=float).view()
    view.flags.writeable = False
    return view


def all_finite(arr: np.ndarray) -> bool:
    """True iff every entry of the float array ``arr`` is finite.

    Small arrays (the front door's one Omega0 or Gamma0) on Python floats, ~0.3 µs where numpy's ufunc
    reduction costs ~2 µs; larger ones by the reduction (ndarray.all is ~1 µs more, in Python).
    """
    if arr.size <= _SMALL:
        return all(map(math.isfinite, arr.ravel().tolist()))
    return bool(np.logical_and.reduce(np.isfinite(arr), axis=None))


def _foreign_scalars(x: Any) -> str | None:
    """What a (nested) list or tuple holds that is not a real number — "complex values", "booleans" or
    "strings" (also inside arrays among its entries) — or None."""
    for e in x:
        if isinstance(e, (list, tuple)):
            what = _foreign_scalars(e)
        elif isinstance(e, (bool, np.bool_)):
            what = "booleans"
        elif isinstance(e, (str, bytes)):
            what = "strings"
        elif isinstance(e, complex) or np.iscomplexobj(e):
            what = "complex values"
        elif isinstance(e, np.ndarray) and e.dtype.kind in "bUSO":
            what = _foreign_scalars(e.ravel().tolist()) if e.dtype.kind == "O" else (
                "booleans" if e.dtype.kind == "b" else "strings")
        else:
            what = None
        if what is not None:
            return what
    return None


def check_real(x: Any, name: str) -> float:
    """Return ``x`` as a float after checking it is a finite real number."""
    if type(x) is float or type(x) is int:  # the common case, without numpy's type inspection (~3 µs)
        val = float(x)
    else:
        if np.iscomplexobj(x):
            raise TypeError(f"{name} must be a real number, got the complex {x!r}")
        if isinstance(x, (str, bytes)):  # float("0.1") would read it
            raise TypeError(f"{name} must be a real number, got the string {x!r}")
        if isinstance(x, (bool, np.bool_)):  # float(True) would read it as 1
            raise TypeError(f"{name} must be a real number, got the boolean {x!r}")
        try:
            val = float(x)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"{name} must be a real number, got {type(x).__name__}") from exc
    if not math.isfinite(val):
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


def check_rotations(g: np.ndarray, name: str, *, tol: float = 1e-8) -> None:
    """Raise ``ValueError`` unless every ``g`` (..., k, k) is in SO(k): ``max |g^T g - I| <= tol``, ``det g > 0``.

    The one rotation check of the package (attitudes ``g0``, fibres, scene files); an empty batch passes.
    """
    k = g.shape[-1]
    if g.ndim < 2 or g.shape[-2] != k:
        raise ValueError(f"{name} must be square rotation matrices (..., k, k), got shape {g.shape}")
    if g.size == 0:
        return
    err = float(np.max(np.abs(np.swapaxes(g, -1, -2) @ g - np.eye(k))))
    if not err <= tol:  # also catches NaN
        raise ValueError(f"{name} must be in SO({k}): max |{name}^T {name} - I| = {err:.3g} > {tol:g}; "
                         "pass an orthogonal matrix (e.g. the Q factor of a QR decomposition)")
    if np.any(np.linalg.det(g) < 0):
        raise ValueError(f"{name} must be in SO({k}): some {name} have det = -1 (reflections); "
                         "flip the sign of one column")


def check_rigid_motions(g: np.ndarray, name: str, *, tol: float = 1e-8) -> None:
    """Raise ``ValueError`` unless every ``g`` (..., k+1, k+1) is in SE(k): ``[[R, p], [0, 1]]`` with R in SO(k)
    (:func:`check_rotations`) and the last row ``(0, ..., 0, 1)`` exactly."""
    k = g.shape[-1] - 1
    if g.ndim < 2 or g.shape[-2] != k + 1 or k < 1:
        raise ValueError(f"{name} must be square matrices (..., k+1, k+1) of SE(k), got shape {g.shape}")
    last = np.zeros(k + 1)
    last[k] = 1.0
    rows = g.reshape(-1, k + 1, k + 1)[:, k]
    bad = np.flatnonzero(~np.all(rows == last, axis=-1))
    if bad.size:
        raise ValueError(f"{name} must be in SE({k}), of the form [[R, p], [0, 1]]: its last row must be "
                         f"(0, ..., 0, 1), got {rows[bad[0]].tolist()} (flat batch index {int(bad[0])})")
    check_rotations(g[..., :k, :k], f"{name}[..., :{k}, :{k}]", tol=tol)


def tolerance_for(x: Any, tol: float = 1e-8) -> float:
    """``tol``, or 16 ulps of ``x``'s floating type when that is coarser (float32 data cannot be unit or
    orthogonal to 1e-8: its rounding alone is ~6e-8)."""
    dtype = getattr(x, "dtype", None)
    if isinstance(dtype, np.dtype) and dtype.kind == "f":  # a numpy floating type (np.issubdtype: ~0.7 µs a call)
        return max(tol, 16.0 * _eps(dtype))
    return tol


@functools.cache
def _eps(dtype: np.dtype) -> float:
    """The machine epsilon of a floating dtype."""
    return float(np.finfo(dtype).eps)


def unit_vectors(x: np.ndarray, name: str, *, tol: float = 1e-8) -> np.ndarray:
    """``x / |x|`` (..., n) after checking ``| |x| - 1 | <= tol`` for every vector (the one unit check).

    The division removes the rounding of the given data, so unit vectors stay unit to 1e-16.
    """
    if x.ndim == 1 and x.size <= _SEQUENTIAL_MAX:
        # one short vector on Python floats (~5 µs less per call): the same squares summed in the same order
        # as numpy's reduction of fewer than 8 entries, so its norm is bitwise the batch path's (tested)
        acc = 0.0
        for v in x.tolist():
            acc += v * v
        nrm = math.sqrt(acc)
        if x.size and not abs(nrm - 1.0) <= tol:
            raise ValueError(f"{name} must be a unit vector (|{name}| = 1 within {tol:g}); got |{name}| - 1 = "
                             f"{nrm - 1.0:.3g}: pass {name} / |{name}|")
        return x / nrm
    nrm = np.sqrt(np.add.reduce(x * x, axis=-1))  # np.linalg.norm's own formula, without its ~4 µs of checks
    if nrm.ndim == 0:  # one vector: the same test and division on the Python float (~4 µs less per call)
        if x.size and not abs(float(nrm) - 1.0) <= tol:
            raise ValueError(f"{name} must be a unit vector (|{name}| = 1 within {tol:g}); got |{name}| - 1 = "
                             f"{float(nrm) - 1.0:.3g}: pass {name} / |{name}|")
        return x / nrm
    if x.size and not (np.abs(nrm - 1.0) <= tol).all():
        raise ValueError(f"{name} must be a unit vector (|{name}| = 1 within {tol:g}); got |{name}| - 1 in "
                         f"[{nrm.min() - 1.0:.3g}, {nrm.max() - 1.0:.3g}]: pass {name} / |{name}|")
    return x / nrm[..., None]


def check_t_span(t_span) -> tuple[float, float]:
    """``(t0, t1)`` from a pair of finite, different numbers (ValueError naming ``t_span`` otherwise; TypeError
    for strings, which ``float`` would read)."""
    def bad() -> str:  # (formatted only on failure: the repr is ~1 µs of a front-door call)
        return f"t_span must be a pair of numbers (t0, t1), got {t_span!r}"

    t0 = t1 = None
    if type(t_span) is tuple and len(t_span) == 2:  # the common case on Python numbers (type(True) is bool)
        a, b = t_span
        if type(a) in (float, int) and type(b) in (float, int):
            t0, t1 = float(a), float(b)
    if t0 is None:
        if isinstance(t_span, (str, bytes)):
            raise TypeError(bad())
        try:
            pair = tuple(t_span)
        except TypeError as exc:
            raise ValueError(bad()) from exc
        # a bool would be read as 0 or 1; float() refuses a complex number with a TypeError, kept a TypeError
        if any(isinstance(v, (str, bytes, bool, np.bool_, complex, np.complexfloating)) for v in pair):
            raise TypeError(bad())
        try:
            t0, t1 = (float(v) for v in pair)
        except (TypeError, ValueError) as exc:
            raise ValueError(bad()) from exc
    if not (math.isfinite(t0) and math.isfinite(t1)):
        raise ValueError(f"t_span must be finite, got {t_span!r}")
    if t0 == t1:
        raise ValueError(f"t_span must have t0 != t1, got {t_span!r}")
    return t0, t1


def check_t_eval(t_eval, t0: float, t1: float) -> np.ndarray:
    """Output times: a non-empty 1-D array inside ``(t0, t1)``, strictly monotone in the direction of integration."""
    if t_eval is None:
        return None
    te = as_float_array(t_eval, "t_eval")
    if te.ndim != 1 or te.size == 0:
        raise ValueError(f"t_eval must be a non-empty 1-D array, got shape {te.shape}")
    if te.size > 1 and ((np.diff(te) * (1.0 if t1 > t0 else -1.0)) <= 0).any():
        raise ValueError("t_eval must be strictly increasing (decreasing for backward integration)")
    # monotone: its extremes are its ends
    first, last = float(te[0]), float(te[-1])
    if min(first, last) < min(t0, t1) or max(first, last) > max(t0, t1):
        raise ValueError(f"t_eval must lie within t_span = ({t0}, {t1})")
    return np.array(te, order="C")  # a copy: the solution's t must not be the caller's array (nor change with it)
