"""The integrable cases of Jovanović (2003) and Suslov's problem, with their first integrals.

Each constructor validates its parameters and returns a :class:`Case`: the :class:`SuslovSystem`, the
parameters, and the first integrals as batched callables ``F(omega, Gamma) -> (...)`` of the
coordinates ``omega`` (..., d) of Omega and of ``Gamma`` (..., n) (ignored where F does not use it).
Every integral is derived from the equations of motion in ``docs/mechanics.md`` and tested along
trajectories. :data:`CASES` maps names to constructors, with one-line descriptions and example
parameters (``CASES["kharlamova"].build()``).

3-D cases take the paper's inertia ``J`` acting on ``w = (-Omega_23, Omega_13, -Omega_12)``
(principal moments ``(J1, J2, J3)``; the mass tensor is ``I = 1/2 tr(J) Id - J``) and the
constraint ``w3 = 0`` (``a = e3``: ``suslov_distribution(3)``, ``xi = (Omega_13, Omega_23) = (w2, -w1)``).
n-D cases take the diagonal ``I`` of the mass tensor and the Fedorov–Kozlov constraints.
"""

from __future__ import annotations

import inspect
import pickle
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from .._validation import as_float_array, check_real
from ..algebra import Inertia, so
from .potentials import (
    FamilyPotential,
    LinearPotential,
    Potential,
    QuadraticPotential,
    ZeroPotential,
    check_gradient,
)
from .system import SuslovSystem

__all__ = ["Case", "CaseEntry", "CASES", "suslov3", "lagrange3", "kharlamova3", "klebsh_tisserand3",
           "family3", "gyroscopic3", "suslov_free", "lagrange", "kharlamova", "klebsh_tisserand"]

Integral = Callable[[np.ndarray, Any], np.ndarray]


@dataclass(frozen=True)
class Case:
    """An integrable (or reference) scene with its first integrals.

    Attributes
    ----------
    name : str
    system : SuslovSystem
    parameters : dict
        The validated parameters.
    integrals : dict of str to callable
        ``F(omega, Gamma) -> (...)``, batched; ``omega`` are coordinates (..., d). Always has "energy".
    description : str
    """

    name: str
    system: SuslovSystem
    parameters: dict
    integrals: dict = field(repr=False)
    description: str = ""

    def __reduce__(self):
        # The integrals are closures: a case pickles as its recipe, the registry's constructor and the
        # validated parameters, and is rebuilt on unpickling (the same numbers).
        if self.name not in CASES:
            raise pickle.PicklingError(f"case {self.name!r} is not in ls.CASES: it cannot be rebuilt on unpickling")
        accepted = inspect.signature(CASES[self.name].constructor).parameters
        return _rebuild_case, (self.name, {k: v for k, v in self.parameters.items() if k in accepted})

    def evaluate(self, omega, Gamma=None) -> dict[str, np.ndarray]:
        """All integrals at ``(omega, Gamma)`` (omega as coordinates or matrices): a dict of arrays (...)."""
        x = self.system.coordinates(omega, "omega")
        G = None if Gamma is None else np.asarray(Gamma, dtype=float)
        return {k: np.asarray(F(x, G)) for k, F in self.integrals.items()}

    def random_state(self, rng=None, batch: int | tuple[int, ...] = (), scale: float = 1.0):
        """A random admissible state: ``(omega (..., d) in D, Gamma (..., n) unit)``.

        Parameters
        ----------
        rng : None, int or numpy.random.Generator
            Seed or generator (``numpy.random.default_rng(rng)``).
        batch : int or tuple of int
            The batch shape ``(...)``; an int ``N`` means ``(N,)`` (as numpy's ``size``).
        scale : float
            Standard deviation of the coordinates ``xi`` of ``omega`` in D.

        Returns
        -------
        omega : ndarray, shape (..., d)
        Gamma : ndarray of shape (..., n), or None
            None when the system does not need it.
        """
        if isinstance(rng, (bool, np.bool_, str, bytes, float)):
            raise TypeError(f"rng must be None, a non-negative int or a numpy Generator, got {type(rng).__name__}")
        try:
            rng = np.random.default_rng(rng)
        except (TypeError, ValueError) as exc:
            raise type(exc)(f"rng must be None, a non-negative int or a numpy Generator: {exc}") from exc
        shape = _batch_shape(batch)
        scale = check_real(scale, "scale")
        D = self.system.constraints
        omega = (scale * rng.standard_normal(shape + (D.dim,))) @ D.basis
        if not self.system.needs_gamma:
            return omega, None
        G = rng.standard_normal(shape + (self.system.n,))
        return omega, G / np.linalg.norm(G, axis=-1, keepdims=True)


def _rebuild_case(name: str, parameters: dict) -> Case:
    """Unpickling a :class:`Case`: its constructor with its validated parameters."""
    return CASES[name].constructor(**parameters)


@dataclass(frozen=True)
class CaseEntry:
    """A registry entry: a constructor, a one-line description and example parameters."""

    name: str
    constructor: Callable[..., Case]
    description: str
    example: Mapping[str, Any]

    def build(self, **parameters) -> Case:
        """The case with the example parameters, overridden by ``parameters``."""
        return self.constructor(**{**self.example, **parameters})


# ====================================================================== helpers
def _flag(value, name: str) -> None:
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {type(value).__name__} {value!r}")


def _no_int(b):
    raise TypeError(b)  # (int(2.7) would truncate a size silently)


def _batch_shape(batch) -> tuple[int, ...]:
    """A batch shape from an int ``N`` (``(N,)``) or a tuple of ints, as numpy's ``size``."""
    if isinstance(batch, (int, np.integer)) and not isinstance(batch, bool):
        batch = (int(batch),)
    try:
        if isinstance(batch, (str, bytes)):
            raise TypeError(batch)
        shape = tuple(b if isinstance(b, (int, np.integer)) and not isinstance(b, bool) else _no_int(b)
                      for b in batch)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"batch must be an int or a tuple of ints (the batch shape), got {batch!r}") from exc
    if any(b < 0 for b in shape):
        raise ValueError(f"batch must not have negative sizes, got {shape}")
    return shape


def _energy(system: SuslovSystem) -> Integral:
    # Through the inertia operator (lazy for a mass tensor), never its dense d x d matrix.
    kinetic = system.inertia.kinetic_energy
    pot = system.potential

    def energy(x, G):
        E = kinetic(x)
        return E + pot.V(G) if not pot.is_zero else E
    return energy


def _moments(J, name: str = "J") -> np.ndarray:
    J = as_float_array(J, name)
    if J.shape != (3,):
        raise ValueError(f"{name} must be the principal moments (J1, J2, J3), shape (3,), got {J.shape}")
    if np.any(J <= 0):
        raise ValueError(f"{name} must be positive (principal moments of inertia), got {J}")
    return J


def _w(x):
    """so(3) coordinates to the paper's vector w = (-Omega_23, Omega_13, -Omega_12)."""
    return -x[..., 2], x[..., 1], -x[..., 0]


def _diagonal_mass(I, name: str = "I") -> np.ndarray:
    I = as_float_array(I, name)
    if I.ndim != 1 or I.shape[0] < 3:
        raise ValueError(f"{name} must be the diagonal (I_1, ..., I_n) of the mass tensor, n >= 3, "
                         f"got shape {I.shape}")
    return I


def _fk_index(n: int) -> np.ndarray:
    """Positions of Omega_in (i < n) in the so(n) coordinates."""
    alg = so(n)
    return np.array([alg.index(i, n - 1) for i in range(n - 1)])


def _system3(J, potential: Potential | None = None, gyroscopic: float = 0.0) -> SuslovSystem:
    return SuslovSystem(Inertia.from_principal_moments(J), potential=potential, gyroscopic=gyroscopic)


# ====================================================================== 3-D
def suslov3(J) -> Case:
    """Suslov's problem: V = 0, ``a = e3`` not an eigenvector of J (no invariant measure).

    Parameters
    ----------
    J : array_like, shape (3, 3)
        Symmetric positive definite inertia in the w form with ``J13`` or ``J23`` nonzero.

    Notes
    -----
    ``w`` moves on the energy ellipse from one asymptotic point to the opposite one; the only integral
    is the energy.
    """
    J = as_float_array(J, "J")
    if J.shape != (3, 3):
        raise ValueError(f"J must be a symmetric 3×3 matrix (the w form), got shape {J.shape}")
    if abs(J[0, 2]) + abs(J[1, 2]) <= 1e-12 * np.max(np.abs(J)):
        raise ValueError("J: a = e3 is an eigenvector of J (J13 = J23 = 0), so Omega is constant; "
                         "Suslov's asymptotic motion needs J13 or J23 != 0")
    system = _system3(J)
    return Case("suslov3", system, {"J": J}, {"energy": _energy(system)},
                "Suslov's problem (n = 3, V = 0, a not an eigenvector of J): asymptotic motion, no invariant "
                "measure")


def lagrange3(J1, J3, B3) -> Case:
    """3-D Lagrange case: ``J1 = J2``, ``V = B3 Gamma_3``; ``F = <J w, Gamma>``, multiplier ≡ 0.

    Parameters
    ----------
    J1 : float or pair (J1, J2)
        The equal moments (a pair must have J1 = J2).
    J3, B3 : float
    """
    J12 = as_float_array(J1, "J1").ravel()
    if J12.shape[0] not in (1, 2):
        raise ValueError(f"J1 must be a number or the pair (J1, J2), got {J12.shape[0]} values")
    if J12.shape[0] == 2 and J12[0] != J12[1]:
        raise ValueError(f"the Lagrange case needs J1 = J2, got J1 = {J12[0]}, J2 = {J12[1]}")
    J = _moments([J12[0], J12[0], check_real(J3, "J3")])
    B3 = check_real(B3, "B3")
    system = _system3(J, LinearPotential([0.0, 0.0, B3]))
    j1 = J[0]

    def F(x, G):
        w1, w2, _ = _w(x)
        return j1 * (w1 * G[..., 0] + w2 * G[..., 1])
    return Case("lagrange3", system, {"J1": j1, "J3": J[2], "B3": B3}, {"energy": _energy(system), "F": F},
                "Lagrange (n = 3): J1 = J2, V = B3 Gamma_3; F = <J w, Gamma>, the multiplier vanishes")


def kharlamova3(J, B1, B2) -> Case:
    """3-D Kharlamova case: ``V = B1 Gamma_1 + B2 Gamma_2``; ``F = J1 w1 B1 + J2 w2 B2``.

    Also the partial energies ``E_1 = J2 w2^2 / 2 + B1 Gamma_1``, ``E_2 = J1 w1^2 / 2 + B2 Gamma_2``
    (``E = E_1 + E_2``; from ``J2 w2' = B1 Gamma_3``, ``J1 w1' = -B2 Gamma_3``).
    """
    J = _moments(J)
    B1, B2 = check_real(B1, "B1"), check_real(B2, "B2")
    system = _system3(J, LinearPotential([B1, B2, 0.0]))
    J1, J2 = J[0], J[1]

    def F(x, G):
        w1, w2, _ = _w(x)
        return J1 * w1 * B1 + J2 * w2 * B2

    def E1(x, G):
        return 0.5 * J2 * x[..., 1] ** 2 + B1 * G[..., 0]

    def E2(x, G):
        return 0.5 * J1 * x[..., 2] ** 2 + B2 * G[..., 1]
    return Case("kharlamova3", system, {"J": J, "B1": B1, "B2": B2},
                {"energy": _energy(system), "F": F, "E_1": E1, "E_2": E2},
                "Kharlamova (n = 3): V = B1 Gamma_1 + B2 Gamma_2; F = J1 w1 B1 + J2 w2 B2")


def klebsh_tisserand3(J, eps) -> Case:
    """3-D Klebsh–Tisserand case: ``V = eps/2 <J Gamma, Gamma>``.

    ``F = 1/2 <J w, J w> - 1/2 <A Gamma, Gamma>`` with ``A = eps det(J) J^-1``, and the n-D form
    ``F_1 = eps (J1 - J3) Gamma_1^2 + J2 w2^2``, ``F_2 = eps (J2 - J3) Gamma_2^2 + J1 w1^2``
    (``2 F = J2 F_1 + J1 F_2 - eps J1 J2 |Gamma|^2``).
    """
    J = _moments(J)
    eps = check_real(eps, "eps")
    system = _system3(J, QuadraticPotential(eps * J))
    J1, J2, J3 = J
    Adiag = eps * J1 * J2 * J3 / J

    def F(x, G):
        w1, w2, _ = _w(x)
        return 0.5 * ((J1 * w1) ** 2 + (J2 * w2) ** 2) - 0.5 * ((G * G) @ Adiag)

    def F1(x, G):
        return eps * (J1 - J3) * G[..., 0] ** 2 + J2 * x[..., 1] ** 2

    def F2(x, G):
        return eps * (J2 - J3) * G[..., 1] ** 2 + J1 * x[..., 2] ** 2
    return Case("klebsh_tisserand3", system, {"J": J, "eps": eps},
                {"energy": _energy(system), "F": F, "F_1": F1, "F_2": F2},
                "Klebsh–Tisserand (n = 3): V = eps/2 <J Gamma, Gamma>; F = |J w|^2/2 - <A Gamma, Gamma>/2")


def family3(J, v1: Callable, dv1: Callable, v2: Callable, dv2: Callable, *, check: bool = True) -> Case:
    """The family ``V = v1(Gamma_1, Gamma_2^2 + Gamma_3^2) + v2(Gamma_2, Gamma_1^2 + Gamma_3^2)``, J1 != J2.

    ``F = 1/2 <J w, J w> + J2 v1 + J1 v2`` (verified: ``docs/mechanics.md``).

    Parameters
    ----------
    J : array_like, shape (3,)
        Principal moments with ``J1 != J2`` (for J1 = J2, F = J1 E is not independent).
    v1, dv1, v2, dv2 : callable
        See :class:`FamilyPotential`.
    check : bool
        Check dv1, dv2 against finite differences (ValueError if they disagree).
    """
    J = _moments(J)
    if abs(J[0] - J[1]) <= 1e-12 * max(J[0], J[1]):
        raise ValueError(f"the family case needs J1 != J2 (for J1 = J2 the integral is J1 times the energy), "
                         f"got J1 = J2 = {J[0]}")
    pot = FamilyPotential(v1, dv1, v2, dv2)
    _flag(check, "check")
    if check:
        check_gradient(pot, raise_error=True, tol=1e-5)
    system = _system3(J, pot)
    J1, J2 = J[0], J[1]

    def F(x, G):
        w1, w2, _ = _w(x)
        g1, g2, g3 = G[..., 0], G[..., 1], G[..., 2]
        return (0.5 * ((J1 * w1) ** 2 + (J2 * w2) ** 2) + J2 * v1(g1, g2 * g2 + g3 * g3)
                + J1 * v2(g2, g1 * g1 + g3 * g3))
    return Case("family3", system, {"J": J, "v1": v1, "dv1": dv1, "v2": v2, "dv2": dv2},
                {"energy": _energy(system), "F": F},
                "Dragović–Gajić–Jovanović family (n = 3, J1 != J2): "
                "V = v1(G1, G2^2+G3^2) + v2(G2, G1^2+G3^2)")


def gyroscopic3(J, eps, potential: Potential | None = None) -> Case:
    """Suslov's problem with the gyroscopic force ``eps Gamma x w``: the three integrable potentials.

    Parameters
    ----------
    J : array_like, shape (3,)
        Principal moments.
    eps : float
    potential : None, LinearPotential or QuadraticPotential
        ``V = 0``; ``V = B1 Gamma_1 + B2 Gamma_2`` (``B3 = 0``); ``V = 1/2 sum a_i Gamma_i^2`` (diagonal).

    Notes
    -----
    Integrals besides the energy (derived in ``docs/mechanics.md``):

    * V = 0: ``F_1 = J1 w1 - eps Gamma_1`` and ``F_2 = J2 w2 - eps Gamma_2``.
    * V linear: ``F = B1 (J1 w1 - eps Gamma_1) + B2 (J2 w2 - eps Gamma_2)``.
    * V quadratic, ``b_i = a_i - a_3``: ``F = J1 J2 (b2 w1^2 + b1 w2^2) + b1 (J1 b1 - eps^2) Gamma_1^2
      + b2 (J2 b2 - eps^2) Gamma_2^2 + 2 eps (J1 b1 w1 Gamma_1 + J2 b2 w2 Gamma_2)``.
    """
    J = _moments(J)
    eps = check_real(eps, "eps")
    J1, J2 = J[0], J[1]
    if potential is None or isinstance(potential, ZeroPotential):
        system = _system3(J, None, eps)

        def F1(x, G):
            return J1 * _w(x)[0] - eps * G[..., 0]

        def F2(x, G):
            return J2 * _w(x)[1] - eps * G[..., 1]
        integrals = {"F_1": F1, "F_2": F2}
        kind, params = "V = 0", {}
    elif isinstance(potential, LinearPotential):
        if potential.n != 3 or potential.B[2] != 0.0:
            raise ValueError("potential: the gyroscopic case is integrable for V = B1 Gamma_1 + B2 Gamma_2; "
                             f"LinearPotential needs B = (B1, B2, 0), got {potential.B}")
        B1, B2 = potential.B[0], potential.B[1]
        system = _system3(J, potential, eps)

        def F(x, G):
            w1, w2, _ = _w(x)
            return B1 * (J1 * w1 - eps * G[..., 0]) + B2 * (J2 * w2 - eps * G[..., 1])
        integrals = {"F": F}
        kind, params = "V = B1 Gamma_1 + B2 Gamma_2", {"B": potential.B}
    elif isinstance(potential, QuadraticPotential) and potential.diagonal is not None and potential.n == 3:
        a = potential.diagonal
        b1, b2 = a[0] - a[2], a[1] - a[2]
        system = _system3(J, potential, eps)

        def F(x, G):
            w1, w2, _ = _w(x)
            g1, g2 = G[..., 0], G[..., 1]
            return (J1 * J2 * (b2 * w1 ** 2 + b1 * w2 ** 2) + b1 * (J1 * b1 - eps ** 2) * g1 ** 2
                    + b2 * (J2 * b2 - eps ** 2) * g2 ** 2
                    + 2.0 * eps * (J1 * b1 * w1 * g1 + J2 * b2 * w2 * g2))
        integrals = {"F": F}
        kind, params = "V = 1/2 sum a_i Gamma_i^2", {"a": a}
    else:
        raise ValueError("potential: the gyroscopic Suslov problem is integrable for V = 0, V = B1 Gamma_1 + "
                         "B2 Gamma_2 (LinearPotential) and V = 1/2 sum a_i Gamma_i^2 (diagonal "
                         "QuadraticPotential); "
                         f"got {potential!r}. Build SuslovSystem(..., gyroscopic=eps) directly for others")
    return Case("gyroscopic3", system, {"J": J, "eps": eps, "potential": potential, **params},
                {"energy": _energy(system), **integrals},
                f"Suslov with gyroscopic force eps Gamma x w (n = 3), {kind}")


# ====================================================================== n-D, Fedorov–Kozlov constraints
def suslov_free(I) -> Case:
    """The n-D Suslov problem (Fedorov–Kozlov): V = 0, a symmetric mass tensor I (n, n).

    For a generic I, D is not J-invariant: no invariant measure, trajectories on the energy ellipsoid
    are asymptotic to two opposite points. The energy is the only integral given.
    """
    I = as_float_array(I, "I")
    if I.ndim != 2 or I.shape[0] != I.shape[1] or I.shape[0] < 3:
        raise ValueError(f"I must be a symmetric (n, n) mass tensor with n >= 3, got shape {I.shape}")
    system = SuslovSystem(Inertia.from_mass_tensor(I))
    return Case("suslov_free", system, {"I": system.inertia.mass_tensor}, {"energy": _energy(system)},
                f"Fedorov–Kozlov Suslov problem in SO({I.shape[0]}), V = 0, general I: asymptotic motion")


def lagrange(n: int, I1, In, Bn) -> Case:
    """n-D Lagrange case: ``I = diag(I1, ..., I1, In)``, ``V = Bn Gamma_n``; multipliers ≡ 0.

    Integrals: the energy and ``N_i_j = (I1 + In)(Omega_in Gamma_j - Omega_jn Gamma_i)``, i < j < n
    (the bivector ``xi ∧ Gamma'`` is conserved; n = 3: ``N_1_2 = <J w, Gamma>``).

    Parameters
    ----------
    n : int >= 3
    I1 : float or array of n - 1 equal values
    In, Bn : float
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 3:
        raise ValueError(f"n must be an integer >= 3, got {n!r}")
    I1v = as_float_array(I1, "I1").ravel()
    if I1v.shape[0] not in (1, n - 1):
        raise ValueError(f"I1 must be a number or n - 1 = {n - 1} equal values, got {I1v.shape[0]} values")
    if np.any(I1v != I1v[0]):
        raise ValueError(f"the Lagrange case needs I_1 = I_2 = ... = I_(n-1) (dynamical symmetry about e_n), "
                         f"got {I1v}")
    i1, i_n, Bn = float(I1v[0]), check_real(In, "In"), check_real(Bn, "Bn")
    I = np.array([i1] * (n - 1) + [i_n])
    system = SuslovSystem(Inertia.from_mass_tensor(I), potential=LinearPotential(np.eye(n)[-1] * Bn))
    idx = _fk_index(n)
    c = i1 + i_n
    integrals: dict[str, Integral] = {"energy": _energy(system)}
    for i in range(n - 1):
        for j in range(i + 1, n - 1):
            def N(x, G, i=i, j=j):
                return c * (x[..., idx[i]] * G[..., j] - x[..., idx[j]] * G[..., i])
            integrals[f"N_{i + 1}_{j + 1}"] = N
    return Case("lagrange", system, {"n": n, "I1": i1, "In": i_n, "Bn": Bn}, integrals,
                f"Lagrange in SO({n}): I = diag(I1, ..., I1, In), V = Bn Gamma_n; spherical pendulum, "
                "multipliers 0")


def kharlamova(I, B) -> Case:
    """n-D Kharlamova case: ``V = sum_{i<n} B_i Gamma_i`` (all ``B_i != 0``), diagonal I.

    Integrals: energy, ``F_i_j = (I_i+I_n)/B_i Omega_in - (I_j+I_n)/B_j Omega_jn`` (i < j < n; those
    with i = 1 are independent) and the partial energies ``E_i = 1/2 (I_i + I_n) Omega_in^2 + B_i Gamma_i``
    (``E = sum_i E_i``).

    Parameters
    ----------
    I : array_like, shape (n,)
    B : array_like, shape (n - 1,)
    """
    I = _diagonal_mass(I)
    n = I.shape[0]
    B = as_float_array(B, "B")
    if B.shape != (n - 1,):
        raise ValueError(f"B must have shape ({n - 1},) (B_1, ..., B_(n-1)) for I of length {n}, "
                         f"got {B.shape}")
    if np.any(B == 0):
        raise ValueError(f"B: the Kharlamova integrals divide by B_i, all must be nonzero, got {B}")
    system = SuslovSystem(Inertia.from_mass_tensor(I), potential=LinearPotential(np.append(B, 0.0)))
    idx = _fk_index(n)
    c = (I[:-1] + I[-1]) / B
    integrals: dict[str, Integral] = {"energy": _energy(system)}
    for i in range(n - 1):
        for j in range(i + 1, n - 1):
            def F(x, G, i=i, j=j):
                return c[i] * x[..., idx[i]] - c[j] * x[..., idx[j]]
            integrals[f"F_{i + 1}_{j + 1}"] = F
    for i in range(n - 1):
        def Ei(x, G, i=i):
            return 0.5 * (I[i] + I[-1]) * x[..., idx[i]] ** 2 + B[i] * G[..., i]
        integrals[f"E_{i + 1}"] = Ei
    return Case("kharlamova", system, {"I": I, "B": B}, integrals,
                f"Kharlamova in SO({n}): V = sum_(i<n) B_i Gamma_i; periodic motions, elliptic in t")


def klebsh_tisserand(I, B, *, allow_general: bool = False) -> Case:
    """n-D Klebsh–Tisserand case: ``V = 1/2 sum_i B_i Gamma_i^2``, diagonal I.

    Integrals: energy and ``F_i = (B_i - B_n) Gamma_i^2 + (I_i + I_n) Omega_in^2``; ``E = (B_n + sum F_i)/2``.

    Parameters
    ----------
    I, B : array_like, shape (n,)
    allow_general : bool
        The invariant tori need ``B_i > B_n`` for i < n (ValueError otherwise); True accepts any B
        (the F_i stay integrals, the tori picture does not hold).
    """
    I = _diagonal_mass(I)
    n = I.shape[0]
    B = as_float_array(B, "B")
    if B.shape != (n,):
        raise ValueError(f"B must have shape ({n},) for I of length {n}, got {B.shape}")
    _flag(allow_general, "allow_general")
    if not allow_general and np.any(B[:-1] <= B[-1]):
        bad = int(np.argmax(B[:-1] <= B[-1])) + 1
        raise ValueError(f"B: the Klebsh–Tisserand tori need B_i > B_n for every i < n, got B_{bad} = "
                         f"{B[bad - 1]} <= B_n = {B[-1]} (pass allow_general=True to accept it)")
    system = SuslovSystem(Inertia.from_mass_tensor(I), potential=QuadraticPotential(B))
    idx = _fk_index(n)
    integrals: dict[str, Integral] = {"energy": _energy(system)}
    for i in range(n - 1):
        def Fi(x, G, i=i):
            return (B[i] - B[-1]) * G[..., i] ** 2 + (I[i] + I[-1]) * x[..., idx[i]] ** 2
        integrals[f"F_{i + 1}"] = Fi
    params = {"I": I, "B": B} | ({"allow_general": True} if allow_general else {})
    return Case("klebsh_tisserand", system, params, integrals,
                f"Klebsh–Tisserand in SO({n}): V = 1/2 sum B_i Gamma_i^2; invariant tori, frequencies "
                "sqrt((B_i - B_n)/(I_i + I_n)) in d tau = Gamma_n dt")


# ====================================================================== registry
def _example_v1(s, r):
    return 0.5 * s ** 3 + 0.3 * s * r


def _example_dv1(s, r):
    return 1.5 * s ** 2 + 0.3 * r, 0.3 * s


def _example_v2(t, q):
    return np.sin(t) * (1.0 + q)


def _example_dv2(t, q):
    return np.cos(t) * (1.0 + q), np.sin(t)


def _entries(*rows) -> Mapping[str, CaseEntry]:
    return MappingProxyType({name: CaseEntry(name, fn, desc, MappingProxyType(ex))
                             for name, fn, desc, ex in rows})


#: name -> :class:`CaseEntry` (constructor, one-line description, example parameters).
CASES: Mapping[str, CaseEntry] = _entries(
    ("suslov3", suslov3, "n = 3, V = 0, a not an eigenvector of J: asymptotic motion (Suslov)",
     {"J": [[2.0, 0.0, 0.3], [0.0, 3.0, 0.4], [0.3, 0.4, 4.0]]}),
    ("lagrange3", lagrange3, "n = 3, J1 = J2, V = B3 Gamma_3: F = <J w, Gamma>, multiplier 0",
     {"J1": 2.0, "J3": 1.5, "B3": 1.0}),
    ("kharlamova3", kharlamova3, "n = 3, V = B1 Gamma_1 + B2 Gamma_2: F = J1 w1 B1 + J2 w2 B2",
     {"J": [1.0, 2.0, 2.5], "B1": 1.0, "B2": 0.5}),
    ("klebsh_tisserand3", klebsh_tisserand3,
     "n = 3, V = eps/2 <J Gamma, Gamma>: F = |Jw|^2/2 - <A Gamma, Gamma>/2",
     {"J": [1.0, 2.0, 2.5], "eps": 0.8}),
    ("family3", family3,
     "n = 3, J1 != J2, V = v1(G1, G2^2+G3^2) + v2(G2, G1^2+G3^2): F = |Jw|^2/2 + J2 v1 + J1 v2",
     {"J": [1.0, 2.0, 2.5], "v1": _example_v1, "dv1": _example_dv1, "v2": _example_v2, "dv2": _example_dv2}),
    ("gyroscopic3", gyroscopic3,
     "n = 3 with gyroscopic force eps Gamma x w (V = 0, linear or diagonal quadratic)",
     {"J": [1.0, 2.0, 2.5], "eps": 0.7, "potential": QuadraticPotential([1.0, 2.0, 0.5])}),
    ("suslov_free", suslov_free,
     "SO(n) Fedorov–Kozlov, V = 0, general I: asymptotic motion, no invariant measure",
     {"I": [[1.0, 0.1, 0.0, 0.2], [0.1, 2.0, 0.1, 0.3], [0.0, 0.1, 3.0, 0.1], [0.2, 0.3, 0.1, 4.0]]}),
    ("lagrange", lagrange,
     "SO(n), I = diag(I1, .., I1, In), V = Bn Gamma_n: spherical pendulum, multipliers 0",
     {"n": 4, "I1": 1.0, "In": 2.0, "Bn": 1.0}),
    ("kharlamova", kharlamova, "SO(n), V = sum B_i Gamma_i (i < n): integrals F_ij, periodic motions",
     {"I": [1.0, 2.0, 3.0, 4.0], "B": [1.0, -0.5, 0.7]}),
    ("klebsh_tisserand", klebsh_tisserand, "SO(n), V = 1/2 sum B_i Gamma_i^2, B_i > B_n: integrals F_i, tori",
     {"I": [1.0, 2.0, 3.0, 4.0], "B": [4.0, 3.0, 2.0, 1.0]}),
)
