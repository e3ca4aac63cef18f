"""Explicit Runge–Kutta methods as data: a frozen, validated Butcher tableau and the library's tableaux.

One generic (RKMK) stepper consumes any :class:`ButcherTableau`; nothing here knows about groups or
mechanics. A method of classical order p applied by RKMK keeps order p on the group (Munthe-Kaas), since
inside one step RKMK *is* classical RK applied to the chart equation ``dTheta/dt = dphi^{-1}(...)``.

Conventions
-----------
Stage ``i`` (0-based) sits at ``t + c[i] h`` and sees ``y + h sum_{j<i} A[i, j] k_j``; the step is
``y1 = y + h sum_i b[i] k_i``. Only explicit methods: ``A`` is strictly lower triangular.

Error estimators and the norm the controller must use
-----------------------------------------------------
Let ``err_w = h * sum_i w[i] k_i`` for each weight vector ``w`` of :attr:`ButcherTableau.error_weights`
(``h`` included, as the stepper returns them), ``scale = atol + rtol * max(|y0|, |y1|)`` elementwise, and
``n`` the number of components reduced over.

* Ordinary embedded pair (``b_hat`` given; "bs3", "dopri5"): ``error_weights == (e,)`` with
  ``e = b - b_hat`` and ``norm = sqrt(mean((err_e / scale)**2))`` — scipy's RK23/RK45 RMS norm (scipy's
  ``E`` is ``b_hat - b``, the sign is immaterial).
* DOP853 (``E5``, ``E3`` given): ``error_weights == (E5, E3)`` and, with
  ``s5 = sum((err_E5 / scale)**2)`` and ``s3 = sum((err_E3 / scale)**2)``,
  ``norm = s5 / sqrt(n * (s5 + 0.01 * s3))`` (``0`` when ``s5 == s3 == 0``). This is Hairer's DOP853 /
  scipy's ``DOP853._estimate_error_norm`` ``|h| S5 / sqrt(n (S5 + 0.01 S3))`` with
  ``S = sum((K E / scale)**2)``, written for ``h``-scaled estimates (the factors of ``h`` cancel).

A step is accepted when ``norm <= 1``; the new step is ``h * min(fac_max, max(fac_min,
safety * norm**error_exponent))`` with ``error_exponent = -1 / (error_order + 1)``: ``-1/3`` for bs3,
``-1/5`` for dopri5 and ``-1/8`` for dop853 (its combined estimator behaves like ``O(h^8)``, so its
``error_order`` is 7 although ``b - E5`` and ``b - E3`` are embedded formulas of orders 5 and 3).
:meth:`ButcherTableau.error_norm` implements both formulas.

Dense output (optional): ``b(theta) = dense @ [theta, theta**2, ..., theta**m]`` gives
``y(t + theta h) = y + h sum_i b_i(theta) k_i`` (scipy's ``P`` convention); ``b(1) == b``.
For RKMK this interpolates the chart coordinate ``Theta`` of the step, which is legitimate for the
same reason as above.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from .control import combine

__all__ = [
    "ButcherTableau",
    "TABLEAUX",
    "get_tableau",
    "EULER",
    "MIDPOINT",
    "HEUN2",
    "KUTTA3",
    "RALSTON3",
    "RK4",
    "RK38",
    "BS3",
    "DOPRI5",
    "DOP853",
]

# Relative slack of the consistency checks: coefficients are float literals, so A @ 1 == c and
# sum(b) == 1 hold to a few ulps of the row's absolute sum (DOP853's rows reach ~100).
_RTOL = 64 * np.finfo(float).eps


def _frozen(x, name: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """A read-only float64 copy of ``x``; ValueError naming ``name`` if the shape or values are wrong."""
    try:
        arr = np.array(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"ButcherTableau field {name!r} must be a real array: {exc}") from exc
    if shape is not None and arr.shape != shape:
        raise ValueError(f"ButcherTableau field {name!r} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"ButcherTableau field {name!r} has non-finite entries")
    arr.setflags(write=False)
    return arr


def _close(value: float, target: float, size: float) -> bool:
    return abs(value - target) <= _RTOL * (1.0 + size)


@dataclass(frozen=True, eq=False, repr=False)
class ButcherTableau:
    """An explicit Runge–Kutta method, validated on construction; all arrays are read-only float64.

    Attributes
    ----------
    name : str
    A : (s, s) ndarray
        Strictly lower triangular (explicit methods only).
    b : (s,) ndarray
        Weights of the propagated solution; ``sum(b) == 1``.
    c : (s,) ndarray
        Nodes; ``A @ 1 == c``.
    order : int
        Classical order of ``(A, b)``.
    b_hat : (s,) ndarray or None
        Embedded weights of an ordinary pair (``sum(b_hat) == 1``), of order ``error_order``.
    error_order : int or None
        Set iff the tableau has an error estimator; the controller uses the exponent
        ``-1 / (error_order + 1)``. For DOP853 it is 7 (see the module docstring).
    fsal : bool
        First Same As Last: the last row of ``A`` is ``b`` and ``c[-1] == 1``, so the last stage sits at
        the new point and its *raw* right-hand side value can be the next step's stage 0. (In RKMK the
        last stage's ``dphi^{-1}_{Theta}`` is taken at ``Theta != 0``; the next stage 0 is at
        ``Theta = 0``, so reuse the field value, not the transformed stage.) Must match the structure.
    E3, E5 : (s,) ndarray or None
        DOP853's two estimators (both or neither; exclusive with ``b_hat``), each ``b`` minus an
        embedded formula of order 3 and 5, so each sums to 0. Scipy stores them with a 13th entry for
        the derivative at the new point; that entry is zero and is dropped here.
    dense : (s, m) ndarray or None
        Continuous-extension coefficients, ``b(theta) = dense @ [theta, ..., theta**m]``.
    dense_order : int or None
        Order of the continuous extension (set iff ``dense`` is).
    dense_A, dense_c : ndarray or None
        The extra stages of a continuous extension (DOP853's three): rows over stages ``0 … s + e``
        (stage ``s`` is the derivative at the new point), and their nodes.

    Derived (not constructor arguments)
    -----------------------------------
    stages : int
        ``s``.
    a_rows : tuple of s contiguous read-only arrays
        ``a_rows[i] = A[i, :i]`` (``a_rows[0]`` is empty): stage ``i`` needs ``a_rows[i] @ K[:i]``.
    e : (s,) ndarray or None
        ``b - b_hat`` for an ordinary pair.
    error_weights : tuple of (s,) ndarrays
        ``(e,)`` for an ordinary pair, ``(E5, E3)`` for DOP853, ``()`` without an estimator — the
        order :meth:`error_norm` expects its estimates in.
    error_exponent : float or None
        ``-1 / (error_order + 1)``.

    Notes
    -----
    Equality is identity (``eq=False``): arrays make value equality ambiguous.
    """

    name: str
    A: np.ndarray
    b: np.ndarray
    c: np.ndarray
    order: int
    b_hat: np.ndarray | None = None
    error_order: int | None = None
    fsal: bool = False
    E3: np.ndarray | None = None
    E5: np.ndarray | None = None
    dense: np.ndarray | None = None
    dense_order: int | None = None
    dense_A: np.ndarray | None = None
    dense_c: np.ndarray | None = None
    stages: int = field(init=False)
    a_rows: tuple[np.ndarray, ...] = field(init=False)
    e: np.ndarray | None = field(init=False)
    error_weights: tuple[np.ndarray, ...] = field(init=False)
    error_exponent: float | None = field(init=False)

    def __post_init__(self) -> None:
        put = object.__setattr__
        if not isinstance(self.name, str) or not self.name:
            raise ValueError("ButcherTableau field 'name' must be a non-empty string")
        A = _frozen(self.A, "A")
        if A.ndim != 2 or A.shape[0] != A.shape[1] or A.shape[0] == 0:
            raise ValueError(f"ButcherTableau field 'A' must be a non-empty square matrix, "
                             f"got shape {A.shape}")
        s = A.shape[0]
        if np.any(np.triu(A) != 0):
            i, j = np.argwhere(np.triu(A) != 0)[0]
            raise ValueError(f"ButcherTableau field 'A' must be strictly lower triangular (explicit methods "
                             f"only): A[{i}, {j}] = {A[i, j]!r} is not zero")
        b = _frozen(self.b, "b", (s,))
        c = _frozen(self.c, "c", (s,))
        for i in range(s):
            if not _close(A[i].sum(), c[i], np.abs(A[i]).sum()):
                raise ValueError(f"ButcherTableau field 'c' violates the row-sum condition A @ 1 == c at row "
                                 f"{i}: sum(A[{i}]) = {A[i].sum()!r}, c[{i}] = {c[i]!r}")
        if not _close(b.sum(), 1.0, np.abs(b).sum()):
            raise ValueError(f"ButcherTableau field 'b' must sum to 1, got {b.sum()!r}")
        for fname in ("order", "error_order", "dense_order"):
            v = getattr(self, fname)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1):
                raise ValueError(f"ButcherTableau field {fname!r} must be a positive integer, got {v!r}")
        if self.order is None:
            raise ValueError("ButcherTableau field 'order' is required")

        b_hat = None if self.b_hat is None else _frozen(self.b_hat, "b_hat", (s,))
        if b_hat is not None and not _close(b_hat.sum(), 1.0, np.abs(b_hat).sum()):
            raise ValueError(f"ButcherTableau field 'b_hat' must sum to 1, got {b_hat.sum()!r}")
        if (self.E3 is None) != (self.E5 is None):
            raise ValueError("ButcherTableau fields 'E3' and 'E5' go together: give both or neither")
        E3 = None if self.E3 is None else _frozen(self.E3, "E3", (s,))
        E5 = None if self.E5 is None else _frozen(self.E5, "E5", (s,))
        if E3 is not None and b_hat is not None:
            raise ValueError("ButcherTableau field 'b_hat' excludes 'E3'/'E5': one error estimator "
                             "per tableau")
        for fname, E in (("E3", E3), ("E5", E5)):
            if E is not None and not _close(E.sum(), 0.0, np.abs(E).sum()):
                raise ValueError(f"ButcherTableau field {fname!r} must sum to 0 (b minus a consistent "
                                 f"embedded formula), got {E.sum()!r}")
        has_estimator = b_hat is not None or E3 is not None
        if has_estimator != (self.error_order is not None):
            raise ValueError("ButcherTableau field 'error_order' must be given exactly when 'b_hat' or "
                             "'E3'/'E5' is")
        if self.error_order is not None and self.error_order >= self.order:
            raise ValueError(f"ButcherTableau field 'error_order' ({self.error_order}) must be below "
                             f"'order' ({self.order})")

        fsal_structure = s > 1 and c[-1] == 1.0 and bool(np.array_equal(A[-1], b))
        if bool(self.fsal) != fsal_structure:
            raise ValueError(f"ButcherTableau field 'fsal' is {self.fsal!r} but the structure says "
                             f"{fsal_structure} (FSAL means A[-1] == b and c[-1] == 1)")

        dense = dense_A = dense_c = None
        if (self.dense_A is None) != (self.dense_c is None):
            raise ValueError("ButcherTableau fields 'dense_A' and 'dense_c' go together: give both or neither")
        if self.dense_A is not None:
            dense_A = _frozen(self.dense_A, "dense_A")
            e = dense_A.shape[0]
            if dense_A.ndim != 2 or dense_A.shape[1] != s + 1 + e:
                raise ValueError(f"ButcherTableau field 'dense_A' must have shape (e, {s} + 1 + e), got "
                                 f"{dense_A.shape}")
            if np.any(np.triu(dense_A, s + 1) != 0):
                raise ValueError("ButcherTableau field 'dense_A' must be explicit (row i reads stages < s + 1 + i)")
            dense_c = _frozen(self.dense_c, "dense_c", (e,))
        if self.dense is not None:
            dense = _frozen(self.dense, "dense")
            rows = s if dense_A is None else s + 1 + dense_A.shape[0]
            if dense.ndim != 2 or dense.shape[0] != rows:
                raise ValueError(f"ButcherTableau field 'dense' must have shape ({rows}, m), got {dense.shape}")
            b_full = np.zeros(rows)
            b_full[:s] = b
            if not np.allclose(dense.sum(axis=1), b_full, rtol=0, atol=1e3 * _RTOL):
                raise ValueError("ButcherTableau field 'dense' must give b(1) == b (rows summing to b)")
        if (dense is None) != (self.dense_order is None):
            raise ValueError("ButcherTableau field 'dense_order' must be given exactly when 'dense' is")

        put(self, "A", A)
        put(self, "b", b)
        put(self, "c", c)
        put(self, "order", int(self.order))
        put(self, "fsal", bool(self.fsal))
        put(self, "b_hat", b_hat)
        put(self, "E3", E3)
        put(self, "E5", E5)
        put(self, "dense", dense)
        put(self, "dense_A", dense_A)
        put(self, "dense_c", dense_c)
        put(self, "stages", s)
        rows = []
        for i in range(s):
            r = np.ascontiguousarray(A[i, :i])
            r.setflags(write=False)
            rows.append(r)
        put(self, "a_rows", tuple(rows))
        e = None
        if b_hat is not None:
            e = b - b_hat
            e.setflags(write=False)
        put(self, "e", e)
        put(self, "error_weights", (e,) if e is not None else (E5, E3) if E5 is not None else ())
        put(self, "error_exponent", None if self.error_order is None else -1.0 / (self.error_order + 1))

    def __repr__(self) -> str:
        extra = "" if self.error_order is None else f", error_order={self.error_order}"
        return (f"ButcherTableau(name={self.name!r}, stages={self.stages}, order={self.order}{extra}, "
                f"fsal={self.fsal})")

    @property
    def adaptive(self) -> bool:
        """Whether the tableau carries an error estimator."""
        return bool(self.error_weights)

    def error_norm(self, errors: Sequence[np.ndarray], scale=1.0, axis=None):
        """The scaled error norm of one step (accept the step when it is ``<= 1``).

        Parameters
        ----------
        errors : sequence of arrays, one per entry of :attr:`error_weights`, all of one shape
            ``errors[k] = h * sum_i error_weights[k][i] * k_i`` — ``(err_e,)`` for an ordinary pair,
            ``(err_E5, err_E3)`` for DOP853.
        scale : array_like, broadcastable to the estimates
            ``atol + rtol * max(|y0|, |y1|)``.
        axis : None, int or tuple of ints
            Axes reduced over (None: all, a float comes back; e.g. ``-1`` for one norm per trajectory).

        Returns
        -------
        float or ndarray
            ``sqrt(mean((err_e / scale)**2))`` for an ordinary pair; for DOP853, with ``s5``, ``s3`` the
            sums of squares of ``err_E5 / scale``, ``err_E3 / scale`` and ``n`` the number of reduced
            components, ``s5 / sqrt(n * (s5 + 0.01 * s3))`` (``0`` where both vanish).
        """
        if not self.error_weights:
            raise ValueError(f"tableau {self.name!r} has no error estimator; use an adaptive one "
                             f"({', '.join(n for n, t in TABLEAUX.items() if t.adaptive)})")
        if len(errors) != len(self.error_weights):
            raise ValueError(f"errors must hold {len(self.error_weights)} estimate(s) for tableau "
                             f"{self.name!r}, got {len(errors)}")
        sums = [np.sum((np.asarray(err) / scale) ** 2, axis=axis) for err in errors]
        n = np.broadcast_shapes(np.shape(errors[0]), np.shape(scale))
        ncomp = int(np.prod(n)) // max(1, np.size(sums[0]))
        two = self.E5 is not None
        return np.asarray(combine(sums[0], sums[1] if two else 0.0, ncomp, two))[()]  # the controller's formula

    def weights_at(self, theta: float) -> np.ndarray:
        """Dense-output weights ``b(theta)``, ``0 <= theta <= 1``: ``y(t + theta h) = y + h b(theta) @ K``."""
        if self.dense is None:
            raise ValueError(f"tableau {self.name!r} has no dense output")
        powers = theta ** np.arange(1, self.dense.shape[1] + 1)
        return self.dense @ powers


def _lower(rows: Sequence[Sequence[float]]) -> np.ndarray:
    """Strictly lower triangular s×s matrix from the prefixes ``A[i, :i]`` of rows 1..s-1."""
    s = len(rows) + 1
    A = np.zeros((s, s))
    for i, row in enumerate(rows, start=1):
        if len(row) != i:
            raise ValueError(f"row {i} of the tableau needs {i} entries, got {len(row)}")
        A[i, :i] = row
    return A


# ------------------------------------------------------------------------ fixed-step methods

EULER = ButcherTableau("euler", A=[[0.0]], b=[1.0], c=[0.0], order=1)
"""Forward Euler; under RKMK, the Lie–Euler method ``y1 = phi(h f(y0)) y0``."""

MIDPOINT = ButcherTableau("midpoint", A=_lower([[1 / 2]]), b=[0.0, 1.0], c=[0.0, 1 / 2], order=2)
"""Explicit midpoint rule."""

HEUN2 = ButcherTableau("heun2", A=_lower([[1.0]]), b=[1 / 2, 1 / 2], c=[0.0, 1.0], order=2)
"""Heun's method (explicit trapezoidal rule)."""

KUTTA3 = ButcherTableau("kutta3", A=_lower([[1 / 2], [-1.0, 2.0]]), b=[1 / 6, 2 / 3, 1 / 6],
                        c=[0.0, 1 / 2, 1.0], order=3)
"""Kutta's third-order method."""

RALSTON3 = ButcherTableau("ralston3", A=_lower([[1 / 2], [0.0, 3 / 4]]), b=[2 / 9, 1 / 3, 4 / 9],
                          c=[0.0, 1 / 2, 3 / 4], order=3)
"""Ralston's third-order method (minimum error bound; the propagating formula of bs3)."""

RK4 = ButcherTableau("rk4", A=_lower([[1 / 2], [0.0, 1 / 2], [0.0, 0.0, 1.0]]),
                     b=[1 / 6, 1 / 3, 1 / 3, 1 / 6], c=[0.0, 1 / 2, 1 / 2, 1.0], order=4)
"""The classical fourth-order Runge–Kutta method."""

RK38 = ButcherTableau("rk38", A=_lower([[1 / 3], [-1 / 3, 1.0], [1.0, -1.0, 1.0]]),
                      b=[1 / 8, 3 / 8, 3 / 8, 1 / 8], c=[0.0, 1 / 3, 2 / 3, 1.0], order=4)
"""Kutta's 3/8 rule."""

# ------------------------------------------------------------------------ embedded pairs

BS3 = ButcherTableau(
    "bs3",
    A=_lower([[1 / 2], [0.0, 3 / 4], [2 / 9, 1 / 3, 4 / 9]]),
    b=[2 / 9, 1 / 3, 4 / 9, 0.0],
    c=[0.0, 1 / 2, 3 / 4, 1.0],
    order=3,
    b_hat=[7 / 24, 1 / 4, 1 / 3, 1 / 8],
    error_order=2,
    fsal=True,
    # Cubic Hermite interpolation (scipy RK23.P).
    dense=[[1.0, -4 / 3, 5 / 9],
           [0.0, 1.0, -2 / 3],
           [0.0, 4 / 3, -8 / 9],
           [0.0, -1.0, 1.0]],
    dense_order=3,
)
"""Bogacki–Shampine 3(2), FSAL (4 stages, 3 new evaluations per accepted step)."""

DOPRI5 = ButcherTableau(
    "dopri5",
    A=_lower([
        [1 / 5],
        [3 / 40, 9 / 40],
        [44 / 45, -56 / 15, 32 / 9],
        [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729],
        [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656],
        [35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84],
    ]),
    b=[35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0],
    c=[0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0],
    order=5,
    b_hat=[5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40],
    error_order=4,
    fsal=True,
    # Shampine's quartic continuous extension (scipy RK45.P).
    dense=[
        [1.0, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432],
        [0.0, 0.0, 0.0, 0.0],
        [0.0, 131558114200 / 32700410799, -68118460800 / 10900136933, 87487479700 / 32700410799],
        [0.0, -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072],
        [0.0, 127303824393 / 49829197408, -318862633887 / 49829197408, 701980252875 / 199316789632],
        [0.0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844],
        [0.0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423],
    ],
    dense_order=4,
)
"""Dormand–Prince 5(4), FSAL (7 stages, 6 new evaluations per accepted step)."""

# DOP853 (Hairer, Nørsett & Wanner; Hairer's dop853.f), literals as in scipy's dop853_coefficients.py.
_DOP853_C = (
    0.0,
    0.526001519587677318785587544488e-01,
    0.789002279381515978178381316732e-01,
    0.118350341907227396726757197510,
    0.281649658092772603273242802490,
    0.333333333333333333333333333333,
    0.25,
    0.307692307692307692307692307692,
    0.651282051282051282051282051282,
    0.6,
    0.857142857142857142857142857142,
    1.0,
)
_DOP853_ROWS = (
    # stage 1
    (5.26001519587677318785587544488e-2,),
    # stage 2
    (1.97250569845378994544595329183e-2, 5.91751709536136983633785987549e-2),
    # stage 3
    (2.95875854768068491816892993775e-2, 0.0, 8.87627564304205475450678981324e-2),
    # stage 4
    (
        2.41365134159266685502369798665e-1, 0.0, -8.84549479328286085344864962717e-1,
        9.24834003261792003115737966543e-1,
    ),
    # stage 5
    (
        3.7037037037037037037037037037e-2, 0.0, 0.0, 1.70828608729473871279604482173e-1,
        1.25467687566822425016691814123e-1,
    ),
    # stage 6
    (
        3.7109375e-2, 0.0, 0.0, 1.70252211019544039314978060272e-1, 6.02165389804559606850219397283e-2,
        -1.7578125e-2,
    ),
    # stage 7
    (
        3.70920001185047927108779319836e-2, 0.0, 0.0, 1.70383925712239993810214054705e-1,
        1.07262030446373284651809199168e-1, -1.53194377486244017527936158236e-2,
        8.27378916381402288758473766002e-3,
    ),
    # stage 8
    (
        6.24110958716075717114429577812e-1, 0.0, 0.0, -3.36089262944694129406857109825,
        -8.68219346841726006818189891453e-1, 2.75920996994467083049415600797e1,
        2.01540675504778934086186788979e1, -4.34898841810699588477366255144e1,
    ),
    # stage 9
    (
        4.77662536438264365890433908527e-1, 0.0, 0.0, -2.48811461997166764192642586468,
        -5.90290826836842996371446475743e-1, 2.12300514481811942347288949897e1,
        1.52792336328824235832596922938e1, -3.32882109689848629194453265587e1,
        -2.03312017085086261358222928593e-2,
    ),
    # stage 10
    (
        -9.3714243008598732571704021658e-1, 0.0, 0.0, 5.18637242884406370830023853209,
        1.09143734899672957818500254654, -8.14978701074692612513997267357,
        -1.85200656599969598641566180701e1, 2.27394870993505042818970056734e1,
        2.49360555267965238987089396762, -3.0467644718982195003823669022,
    ),
    # stage 11
    (
        2.27331014751653820792359768449, 0.0, 0.0, -1.05344954667372501984066689879e1,
        -2.00087205822486249909675718444, -1.79589318631187989172765950534e1,
        2.79488845294199600508499808837e1, -2.85899827713502369474065508674,
        -8.87285693353062954433549289258, 1.23605671757943030647266201528e1,
        6.43392746015763530355970484046e-1,
    ),
)
_DOP853_B = (
    5.42937341165687622380535766363e-2, 0.0, 0.0, 0.0, 0.0, 4.45031289275240888144113950566,
    1.89151789931450038304281599044, -5.8012039600105847814672114227,
    3.1116436695781989440891606237e-1, -1.52160949662516078556178806805e-1,
    2.01365400804030348374776537501e-1, 4.47106157277725905176885569043e-2,
)
# Third-order embedded weights (Hairer's bhh1, bhh2, bhh3 on stages 0, 8, 11): E3 = b - bhh.
_DOP853_BHH = {0: 0.244094488188976377952755905512, 8: 0.733846688281611857341361741547,
               11: 0.220588235294117647058823529412e-1}
_DOP853_E5 = (
    0.1312004499419488073250102996e-1, 0.0, 0.0, 0.0, 0.0, -0.1225156446376204440720569753e1,
    -0.4957589496572501915214079952, 0.1664377182454986536961530415e1, -0.3503288487499736816886487290,
    0.3341791187130174790297318841, 0.8192320648511571246570742613e-1, -0.2235530786388629525884427845e-1,
)


def _dop853_e3() -> np.ndarray:
    E3 = np.array(_DOP853_B)
    for i, w in _DOP853_BHH.items():
        E3[i] -= w
    return E3


# Hairer's 7th-order continuous extension of DOP853 (dop853.f, CONTD8): three extra stages after the
# derivative at the new point (stage 12) and the coefficients d of the interpolant's top four terms
# (literals as in scipy's dop853_coefficients.py, rows 13–15 of its A and its D).
_DOP853_DENSE_C = (0.1, 0.2, 0.777777777777777777777777777778)
_DOP853_DENSE_ROWS = (
    {0: 5.61675022830479523392909219681e-2, 6: 2.53500210216624811088794765333e-1,
     7: -2.46239037470802489917441475441e-1, 8: -1.24191423263816360469010140626e-1,
     9: 1.5329179827876569731206322685e-1, 10: 8.20105229563468988491666602057e-3,
     11: 7.56789766054569976138603589584e-3, 12: -8.298e-3},
    {0: 3.18346481635021405060768473261e-2, 5: 2.83009096723667755288322961402e-2,
     6: 5.35419883074385676223797384372e-2, 7: -5.49237485713909884646569340306e-2,
     10: -1.08347328697249322858509316994e-4, 11: 3.82571090835658412954920192323e-4,
     12: -3.40465008687404560802977114492e-4, 13: 1.41312443674632500278074618366e-1},
    {0: -4.28896301583791923408573538692e-1, 5: -4.69762141536116384314449447206,
     6: 7.68342119606259904184240953878, 7: 4.06898981839711007970213554331,
     8: 3.56727187455281109270669543021e-1, 12: -1.39902416515901462129418009734e-3,
     13: 2.9475147891527723389556272149, 14: -9.15095847217987001081870187138},
)
_DOP853_D = (
    {0: -0.84289382761090128651353491142e1, 5: 0.56671495351937776962531783590,
     6: -0.30689499459498916912797304727e1, 7: 0.23846676565120698287728149680e1,
     8: 0.21170345824450282767155149946e1, 9: -0.87139158377797299206789907490,
     10: 0.22404374302607882758541771650e1, 11: 0.63157877876946881815570249290,
     12: -0.88990336451333310820698117400e-1, 13: 0.18148505520854727256656404962e2,
     14: -0.91946323924783554000451984436e1, 15: -0.44360363875948939664310572000e1},
    {0: 0.10427508642579134603413151009e2, 5: 0.24228349177525818288430175319e3,
     6: 0.16520045171727028198505394887e3, 7: -0.37454675472269020279518312152e3,
     8: -0.22113666853125306036270938578e2, 9: 0.77334326684722638389603898808e1,
     10: -0.30674084731089398182061213626e2, 11: -0.93321305264302278729567221706e1,
     12: 0.15697238121770843886131091075e2, 13: -0.31139403219565177677282850411e2,
     14: -0.93529243588444783865713862664e1, 15: 0.35816841486394083752465898540e2},
    {0: 0.19985053242002433820987653617e2, 5: -0.38703730874935176555105901742e3,
     6: -0.18917813819516756882830838328e3, 7: 0.52780815920542364900561016686e3,
     8: -0.11573902539959630126141871134e2, 9: 0.68812326946963000169666922661e1,
     10: -0.10006050966910838403183860980e1, 11: 0.77771377980534432092869265740,
     12: -0.27782057523535084065932004339e1, 13: -0.60196695231264120758267380846e2,
     14: 0.84320405506677161018159903784e2, 15: 0.11992291136182789328035130030e2},
    {0: -0.25693933462703749003312586129e2, 5: -0.15418974869023643374053993627e3,
     6: -0.23152937917604549567536039109e3, 7: 0.35763911791061412378285349910e3,
     8: 0.93405324183624310003907691704e2, 9: -0.37458323136451633156875139351e2,
     10: 0.10409964950896230045147246184e3, 11: 0.29840293426660503123344363579e2,
     12: -0.43533456590011143754432175058e2, 13: 0.96324553959188282948394950600e2,
     14: -0.39177261675615439165231486172e2, 15: -0.14972683625798562581422125276e3},
)


def _dop853_dense() -> tuple[np.ndarray, np.ndarray]:
    """The extra stages' rows (3, 16) and the weights ``dense`` (16, 7) of ``y(t + x h) = y + h sum_j b_j(x) k_j``.

    Hairer's interpolant is ``x (F0 + (1-x) (F1 + x (F2 + (1-x) (F3 + x (F4 + (1-x) (F5 + x F6))))))`` with
    ``F0 = dy``, ``F1 = h k_0 - dy``, ``F2 = 2 dy - h (k_12 + k_0)``, ``F3..F6 = h d k`` and ``dy = h b k``; each
    ``F`` is ``h`` times a weight vector over the 16 stages, so expanding the nested product gives b_j(x).
    """
    S = 16
    rows = np.zeros((3, S))
    for r, row in enumerate(_DOP853_DENSE_ROWS):
        for j, v in row.items():
            rows[r, j] = v
    b = np.zeros(S)
    b[:12] = _DOP853_B
    e0, e12 = np.eye(S)[0], np.eye(S)[12]
    F = [b, e0 - b, 2 * b - e12 - e0]
    for drow in _DOP853_D:
        d = np.zeros(S)
        for j, v in drow.items():
            d[j] = v
        F.append(d)
    # polynomials in x as coefficient rows (S, 8), lowest power first: times x is a shift, times (1 - x) a
    # difference of shifts
    poly = np.zeros((S, 8))
    for i, f in enumerate(reversed(F)):
        poly[:, 0] += f
        shifted = np.zeros_like(poly)
        shifted[:, 1:] = poly[:, :-1]
        poly = shifted if i % 2 == 0 else poly - shifted
    dense = np.ascontiguousarray(poly[:, 1:8])  # no constant term: b_j(0) = 0
    return rows, dense


_DOP853_DENSE_A, _DOP853_DENSE = _dop853_dense()

DOP853 = ButcherTableau(
    "dop853",
    A=_lower(_DOP853_ROWS),
    b=_DOP853_B,
    c=_DOP853_C,
    order=8,
    error_order=7,
    E3=_dop853_e3(),
    E5=_DOP853_E5,
    dense=_DOP853_DENSE,
    dense_order=7,
    dense_A=_DOP853_DENSE_A,
    dense_c=_DOP853_DENSE_C,
)
"""Dormand–Prince 8(5,3) as in Hairer's DOP853: 12 stages; not FSAL (the derivative at the new point,
a 13th evaluation Hairer reuses as the next stage 0, is not needed by the step or its error estimate)."""

TABLEAUX: MappingProxyType[str, ButcherTableau] = MappingProxyType(
    {t.name: t for t in (EULER, MIDPOINT, HEUN2, KUTTA3, RALSTON3, RK4, RK38, BS3, DOPRI5, DOP853)}
)
"""Read-only mapping name -> tableau."""


def get_tableau(name: str | ButcherTableau) -> ButcherTableau:
    """The tableau called ``name`` (case-insensitive); a :class:`ButcherTableau` is returned as is.

    Raises
    ------
    ValueError
        For an unknown name, listing the valid ones.
    """
    if isinstance(name, ButcherTableau):
        return name
    key = name.lower() if isinstance(name, str) else name
    if key not in TABLEAUX:
        raise ValueError(f"unknown tableau {name!r}; valid names: {', '.join(TABLEAUX)}")
    return TABLEAUX[key]
