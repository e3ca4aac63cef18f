"""Potentials ``V(Gamma)`` of a body in a field fixed in space, batched over leading axes.

``Gamma`` is the unit vector of the field written in body coordinates, shape ``(..., n)``. Every
potential has ``V(Gamma) -> (...)`` and ``grad(Gamma) = dV/dGamma -> (..., n)``; only the part of the
gradient tangent to the sphere enters the equations (``dV/dGamma ∧ Gamma`` kills the normal part).

The built-in kinds carry their structure in attributes that :meth:`SuslovSystem.model` exploits
(``kind``): ``"zero"`` (:class:`ZeroPotential`), ``"linear"`` (:class:`LinearPotential`, ``B``),
``"quadratic"`` (:class:`QuadraticPotential`, ``matrix`` and ``diagonal``), ``"family"``
(:class:`FamilyPotential`, the 3-D family of the paper) and ``"general"`` (:class:`Potential`, user
callables). :func:`check_gradient` compares ``grad`` with central finite differences of ``V``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._rows import real_floats, rows_at
from .._validation import as_float_array, read_only

__all__ = ["Potential", "ZeroPotential", "LinearPotential", "QuadraticPotential", "FamilyPotential",
           "GradientCheck", "check_gradient"]


def _vertical(Gamma, n: int) -> np.ndarray:
    """``Gamma`` as floats (..., n), or a ValueError naming it (numpy's broadcast error named nothing)."""
    G = np.asarray(Gamma, dtype=float)
    if G.ndim == 0 or G.shape[-1] != n:
        raise ValueError(f"Gamma must have shape (..., {n}) for this potential on S^{n - 1}, got {G.shape}")
    return G


def real_values(value, label: str) -> np.ndarray:
    """``value`` as a float array; a complex (or object) result of a user callable is a TypeError.

    numpy would cast it with a ComplexWarning and drop the imaginary part: a potential meant differently."""
    return real_floats(value, label, "must return real numbers (return the real part if that is the potential "
                                     "meant)")


class Potential:
    """A potential ``V(Gamma)`` from user callables.

    Parameters
    ----------
    V : callable
        ``V(Gamma) -> (...)`` for ``Gamma`` of shape ``(..., n)`` (it must accept batches).
    grad : callable
        ``grad(Gamma) -> (..., n)``, the gradient ``dV/dGamma`` (use :func:`check_gradient`).
    n : int, optional
        Dimension of ``Gamma``; when given, :class:`SuslovSystem` checks it against so(n).
    name : str, optional
        A label for printing.

    Attributes
    ----------
    kind : str
        ``"general"`` here; the subclasses set ``"zero"``, ``"linear"``, ``"quadratic"``, ``"family"``.
    n : int or None

    Examples
    --------
    >>> P = Potential(lambda G: G[..., 0] ** 3, lambda G: np.stack([3 * G[..., 0] ** 2,
    ...               0 * G[..., 1], 0 * G[..., 2]], -1), n=3)
    >>> check_gradient(P).ok
    True
    """

    kind = "general"

    def __init__(self, V: Callable, grad: Callable, *, n: int | None = None, name: str | None = None) -> None:
        if not callable(V):
            raise TypeError(f"V must be a callable V(Gamma) -> (...), got {type(V).__name__}")
        if not callable(grad):
            raise TypeError(f"grad must be a callable grad(Gamma) -> (..., n), got {type(grad).__name__}")
        self._V = V
        self._grad = grad
        self.n = _check_n(n)
        self.name = name or "Potential(user)"

    @property
    def is_zero(self) -> bool:
        """True for the zero potential (the model then drops ``Gamma`` unless asked for)."""
        return False

    def V(self, Gamma) -> np.ndarray:
        """Value ``V(Gamma)``: (..., n) -> (...)."""
        return real_values(self._V(read_only(Gamma)), "potential.V")

    def grad(self, Gamma) -> np.ndarray:
        """Gradient ``dV/dGamma``: (..., n) -> (..., n)."""
        return real_values(self._grad(read_only(Gamma)), "potential.grad")

    def check_gradient(self, Gamma=None, **options) -> GradientCheck:
        """Shortcut for :func:`check_gradient` ``(self, Gamma, **options)``."""
        return check_gradient(self, Gamma, **options)

    def __repr__(self) -> str:
        return self.name


class ZeroPotential(Potential):
    """``V = 0`` (the same as ``potential=None``)."""

    kind = "zero"

    def __init__(self, n: int | None = None) -> None:
        self.n = _check_n(n)
        self.name = "ZeroPotential()"

    @property
    def is_zero(self) -> bool:
        return True

    def V(self, Gamma) -> np.ndarray:
        return np.zeros(np.shape(Gamma)[:-1])

    def grad(self, Gamma) -> np.ndarray:
        return np.zeros(np.shape(Gamma))


class LinearPotential(Potential):
    """``V = <B, Gamma>``: a homogeneous field, ``B`` the centre of mass times the field strength.

    Parameters
    ----------
    B : array_like, shape (n,)
    """

    kind = "linear"

    def __init__(self, B) -> None:
        B = as_float_array(B, "B")
        if B.ndim != 1 or B.shape[0] < 2:
            raise ValueError(f"B must be a vector of shape (n,) with n >= 2, got shape {B.shape}")
        B.setflags(write=False)
        self.B = B
        self.n = B.shape[0]
        self.name = f"LinearPotential(B={np.array2string(B, precision=4)})"

    @property
    def is_zero(self) -> bool:
        return not np.any(self.B)

    def V(self, Gamma) -> np.ndarray:
        return rows_at(_vertical(Gamma, self.B.shape[-1]), self.B)

    def grad(self, Gamma) -> np.ndarray:
        return np.zeros(_vertical(Gamma, self.B.shape[-1]).shape) + self.B


class QuadraticPotential(Potential):
    """``V = 1/2 Gamma^T B Gamma``.

    Parameters
    ----------
    B : array_like, shape (n,) or (n, n)
        A vector means ``diag(B)``: ``V = 1/2 sum_i B_i Gamma_i^2``; a matrix is used through its symmetric
        part ``(B + B^T)/2`` (the only part V sees), which is stored as ``matrix``.

    Attributes
    ----------
    matrix : ndarray, shape (n, n)
    diagonal : ndarray of shape (n,), or None
        The diagonal when ``matrix`` is diagonal (the fast paths use it).
    """

    kind = "quadratic"

    def __init__(self, B) -> None:
        B = as_float_array(B, "B")
        if B.ndim == 1 and B.shape[0] >= 2:
            S = np.diag(B)
        elif B.ndim == 2 and B.shape[0] == B.shape[1] and B.shape[0] >= 2:
            S = 0.5 * (B + B.T)  # 1/2 G^T B G only sees the symmetric part of B
        else:
            raise ValueError(f"B must have shape (n,) (diagonal) or (n, n) with n >= 2, "
                             f"got shape {B.shape}")
        S.setflags(write=False)
        self.matrix = S
        diag = np.diag(S).copy()
        self.diagonal = diag if np.array_equal(S, np.diag(diag)) else None
        if self.diagonal is not None:
            self.diagonal.setflags(write=False)
        self.n = S.shape[0]
        shown = self.diagonal if self.diagonal is not None else S
        self.name = f"QuadraticPotential(B={np.array2string(shown, precision=4)})"

    @property
    def is_zero(self) -> bool:
        return not np.any(self.matrix)

    def V(self, Gamma) -> np.ndarray:
        G = _vertical(Gamma, self.matrix.shape[-1])
        if self.diagonal is not None:
            return 0.5 * rows_at(G * G, self.diagonal)
        return 0.5 * np.sum(rows_at(G, self.matrix) * G, axis=-1)

    def grad(self, Gamma) -> np.ndarray:
        G = _vertical(Gamma, self.matrix.shape[-1])
        if self.diagonal is not None:
            return G * self.diagonal
        return rows_at(G, self.matrix)


class FamilyPotential(Potential):
    """The 3-D family ``V = v1(Gamma_1, Gamma_2^2 + Gamma_3^2) + v2(Gamma_2, Gamma_1^2 + Gamma_3^2)``.

    With ``J1 != J2`` the Suslov problem is integrable for every such V (Dragović–Gajić–Jovanović),
    with the integral ``F = 1/2 <J w, J w> + J2 v1 + J1 v2`` (see ``docs/mechanics.md``).

    Parameters
    ----------
    v1, v2 : callable
        ``v1(s, r)`` and ``v2(t, q)``, batched (arrays in, array of the same shape out).
    dv1, dv2 : callable
        Their partial derivatives: ``dv1(s, r) -> (dv1/ds, dv1/dr)``, ``dv2(t, q) -> (dv2/dt, dv2/dq)``.

    Notes
    -----
    ``dV/dGamma = (v1_s + 2 Gamma_1 v2_q, 2 Gamma_2 v1_r + v2_t, 2 Gamma_3 (v1_r + v2_q))``.
    """

    kind = "family"

    def __init__(self, v1: Callable, dv1: Callable, v2: Callable, dv2: Callable) -> None:
        for label, f in (("v1", v1), ("dv1", dv1), ("v2", v2), ("dv2", dv2)):
            if not callable(f):
                raise TypeError(f"{label} must be callable, got {type(f).__name__}")
        self.v1, self.dv1, self.v2, self.dv2 = v1, dv1, v2, dv2
        self.n = 3
        self.name = "FamilyPotential(v1, v2)"

    def V(self, Gamma) -> np.ndarray:
        G = read_only(Gamma)  # its components go to the user's v1, v2
        g1, g2, g3 = G[..., 0], G[..., 1], G[..., 2]
        s3 = g3 * g3
        return real_values(self.v1(g1, g2 * g2 + s3) + self.v2(g2, g1 * g1 + s3), "v1 + v2")

    def grad(self, Gamma) -> np.ndarray:
        G = read_only(Gamma)  # its components go to the user's dv1, dv2
        g1, g2, g3 = G[..., 0], G[..., 1], G[..., 2]
        s3 = g3 * g3
        v1s, v1r = (real_values(d, "dv1") for d in self.dv1(g1, g2 * g2 + s3))
        v2t, v2q = (real_values(d, "dv2") for d in self.dv2(g2, g1 * g1 + s3))
        out = np.empty(np.broadcast_shapes(G.shape, np.shape(v1s) + (3,), np.shape(v2t) + (3,)))
        out[..., 0] = v1s + 2.0 * g1 * v2q
        out[..., 1] = 2.0 * g2 * v1r + v2t
        out[..., 2] = 2.0 * g3 * (v1r + v2q)
        return out


# ---------------------------------------------------------------------- gradient check
@dataclass(frozen=True)
class GradientCheck:
    """Result of :func:`check_gradient`.

    Attributes
    ----------
    ok : bool
        ``max_error <= tol``.
    max_error : float
        Worst relative error ``max_m |grad_m - fd_m| / max(1, max_m |fd_m|)`` over the points.
    worst_point : ndarray, shape (n,)
        The ``Gamma`` where it occurs, with ``grad`` and ``finite_difference`` there.
    grad, finite_difference : ndarray, shape (n,)
    tol, step : float
    points : int
        Number of points tested.
    """

    ok: bool
    max_error: float
    worst_point: np.ndarray
    grad: np.ndarray
    finite_difference: np.ndarray
    tol: float
    step: float
    points: int

    def __str__(self) -> str:
        verdict = "ok" if self.ok else "WRONG"
        return (f"gradient check {verdict}: worst relative error {self.max_error:.3g} (tol {self.tol:.1g}) "
                f"over {self.points} points, at Gamma = {np.array2string(self.worst_point, precision=6)}: "
                f"grad = {np.array2string(self.grad, precision=6)}, central differences = "
                f"{np.array2string(self.finite_difference, precision=6)}")


def check_gradient(potential: Potential, Gamma=None, *, n: int | None = None, samples: int = 16,
                   step: float = 1e-6, tol: float = 1e-6, seed: int | None = 0,
                   raise_error: bool = False) -> GradientCheck:
    """Compare ``potential.grad`` with central finite differences of ``potential.V``.

    Parameters
    ----------
    potential : Potential
    Gamma : array_like, shape (..., n), optional
        Points to test; default ``samples`` random unit vectors.
    n : int, optional
        Dimension for the random points when the potential does not know it (user callables).
    samples : int
        Number of random points.
    step : float
        Finite-difference step ``h`` (times ``max(1, |Gamma|)``); the truncation error is O(h^2).
    tol : float
        Accepted relative error.
    seed : int or None
        Seed of the random points.
    raise_error : bool
        Raise ``ValueError`` (with the report as message) instead of returning a failed report.

    Returns
    -------
    GradientCheck
        The report: ``ok``, the worst point and error, both gradients there.

    Examples
    --------
    >>> bad = Potential(lambda G: G[..., 0] ** 2, lambda G: G, n=2)  # the true gradient is (2 G_1, 0)
    >>> check_gradient(bad).ok
    False
    """
    if not isinstance(potential, Potential):
        raise TypeError(f"potential must be a Potential, got {type(potential).__name__}")
    if Gamma is None:
        dim = potential.n if potential.n is not None else _check_n(n)
        if dim is None:
            raise ValueError("n is required: the potential does not know the dimension of Gamma "
                             "(pass n= or explicit points Gamma=)")
        if int(samples) < 1:
            raise ValueError(f"samples must be >= 1, got {samples}")
        rng = np.random.default_rng(seed)
        P = rng.standard_normal((int(samples), dim))
        P /= np.linalg.norm(P, axis=-1, keepdims=True)
    else:
        P = as_float_array(Gamma, "Gamma", ndim_min=1)
        P = P.reshape(-1, P.shape[-1])
        dim = P.shape[-1]
    if not (np.isfinite(step) and step > 0):
        raise ValueError(f"step must be a positive number, got {step!r}")
    h = step * np.maximum(1.0, np.linalg.norm(P, axis=-1))  # (p,)
    E = np.eye(dim)
    shift = h[:, None, None] * E  # (p, n, n): row m shifts coordinate m
    fd = (potential.V(P[:, None, :] + shift) - potential.V(P[:, None, :] - shift)) / (2.0 * h[:, None])
    g = np.broadcast_to(potential.grad(P), P.shape)
    err = np.max(np.abs(g - fd), axis=-1) / np.maximum(1.0, np.max(np.abs(fd), axis=-1))
    err = np.where(np.isfinite(err), err, np.inf)
    w = int(np.argmax(err))
    report = GradientCheck(ok=bool(err[w] <= tol), max_error=float(err[w]), worst_point=P[w].copy(),
                           grad=np.array(g[w]), finite_difference=fd[w].copy(), tol=float(tol),
                           step=float(step), points=P.shape[0])
    if raise_error and not report.ok:
        raise ValueError(f"{potential!r}: grad disagrees with V: {report}")
    return report


def _check_n(n) -> int | None:
    if n is None:
        return None
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        raise ValueError(f"n must be an integer >= 2 (the dimension of Gamma), got {n!r}")
    return int(n)
