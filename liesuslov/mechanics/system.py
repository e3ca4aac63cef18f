"""The nonholonomic body: a scene (algebra, inertia, constraints, potential, gyroscopic term).

On so(n) the equations are (2.2) of the paper (conventions: ``docs/concepts.md``)::

    dM/dt = [M, Omega] + dV/dGamma ∧ Gamma + eps * Gamma x w + sum_i lambda_i a^i,
    dGamma/dt = -Omega Gamma,      <a^i, Omega> = 0,      M = J(Omega),

with ``x ∧ y = x y^T - y x^T`` and the gyroscopic term (n = 3 only) written in the paper's vector
form, ``w = (-Omega_23, Omega_13, -Omega_12)``; in coordinates it is ``eps * vee(w ∧ Gamma)``. On any
other Lie algebra (V = 0) this is the Euler–Poincaré–Suslov system ``dM/dt = ad*_Omega M + lambda a``.

:class:`SuslovSystem` holds the reference (multiplier) form and its diagnostics; :meth:`SuslovSystem.model`
returns the smallest exact model of the scene for the integrators (:mod:`.models`). Its batch methods give a
row the same bits alone or in any batch (products with matrices through :func:`liesuslov._rows.rows_at`, not
BLAS).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._cached import cached_property
from .._rows import rows_at
from .._validation import as_float_array, check_real
from ..algebra import Inertia, SpecialOrthogonalAlgebra, Subspace, omega_coordinates, suslov_distribution
from .forces import gyroscopic_torque, wedge_coordinates
from .models import Model, build_model
from .potentials import Potential, ZeroPotential, real_values

__all__ = ["SuslovSystem", "FORMS", "Reaction", "wedge_coordinates", "gyroscopic_torque"]

#: The forms of the equations, most specialised first (``"auto"`` picks the first that holds).
FORMS = ("symmetric", "eigenspace", "reduced", "multiplier")


class Reaction(NamedTuple):
    """The matrices of the multiplier (reaction) form, :attr:`SuslovSystem.reaction`.

    ``lambda = -(f K^-1 A^T) S^-1`` with ``S = A K^-1 A^T`` keeps ``A dOmega/dt = 0``.
    """

    A: np.ndarray
    """The constraint covectors (rows), shape (r, d)."""
    Kinv: np.ndarray
    """``K^-1``, shape (d, d)."""
    Sinv: np.ndarray
    """``(A K^-1 A^T)^-1``, shape (r, r)."""


class SuslovSystem:
    """A rigid body (or any Euler–Poincaré system) with left-invariant nonholonomic constraints.

    Parameters
    ----------
    inertia : Inertia
        The inertia operator on the algebra (``Inertia.from_mass_tensor(I)`` for a body in SO(n)).
    constraints : Subspace, "none", "fedorov_kozlov" or None
        The fibre ``D = {Omega : <a^i, Omega> = 0}`` of the distribution. None (the default) on so(n):
        the Fedorov–Kozlov ``suslov_distribution(n)`` (``"fedorov_kozlov"`` says so explicitly);
        ``"none"``: no constraints, ``D`` the whole algebra (the free Euler–Poincaré body, any algebra).
        A Subspace is required for other constraints on algebras other than so(n).
    potential : Potential or None
        ``V(Gamma)``; None (or :class:`ZeroPotential`) means V = 0. Only V = 0 on algebras other than so(n).
    gyroscopic : float
        ``eps`` of the gyroscopic force ``eps * Gamma x w`` (so(3) only).

    Attributes
    ----------
    algebra : LieAlgebra
    inertia : Inertia
    constraints : Subspace
        The fibre D.
    potential : Potential
        Never None (:class:`ZeroPotential` for V = 0).
    gyroscopic : float
    n : int or None
        Matrix size of the algebra's representation (n for so(n)).
    needs_gamma : bool
        True iff V != 0 or eps != 0: then ``Gamma`` is part of the dynamics.

    Notes
    -----
    The multipliers are those of the orthonormal constraint covectors ``a^i`` = rows of
    :attr:`covectors` (= ``constraints.covectors``; for the Fedorov–Kozlov D they are the ``E_ij``,
    i < j < n, in lexicographic order).

    ``Omega`` arguments are coordinates ``(..., d)`` or matrices ``(..., n, n)``; an array whose
    trailing block is ``(n, n)`` and lies in the algebra (skew-symmetric on so(n)) is read as matrices
    (so on so(3) a stack of three coordinate vectors that happens to be skew is ambiguous: use
    coordinates with another batch shape, or matrices).

    Examples
    --------
    >>> from liesuslov import Inertia, QuadraticPotential
    >>> sys = SuslovSystem(Inertia.from_mass_tensor([1.0, 2.0, 3.0, 4.0]),
    ...                    potential=QuadraticPotential([4.0, 3.0, 2.0, 1.0]))
    >>> sys.model().form, sys.model().state_dim
    ('symmetric', 7)
    """

    def __init__(self, inertia: Inertia, constraints: Subspace | str | None = None,
                 potential: Potential | None = None, gyroscopic: float = 0.0) -> None:
        if not isinstance(inertia, Inertia):
            raise TypeError(f"inertia must be an Inertia (e.g. ls.Inertia.from_mass_tensor(I)), "
                            f"got {type(inertia).__name__}")
        alg = inertia.algebra
        self.algebra = alg
        self.inertia = inertia
        self.is_so = isinstance(alg, SpecialOrthogonalAlgebra)
        self.n = alg.matrix_size
        # ---- constraints
        if isinstance(constraints, str):
            if constraints == "none":  # the scene files' `constraints = "none"`
                constraints = Subspace(alg, np.eye(alg.dim))
            elif constraints == "fedorov_kozlov":
                if not self.is_so:
                    raise ValueError(f'constraints="fedorov_kozlov" is for so(n), this is {alg.name}: pass a '
                                     "Subspace or constraints=\"none\"")
                constraints = None
            else:
                raise ValueError(f'constraints must be a Subspace, "none" (no constraints), "fedorov_kozlov" '
                                 f"or None (Fedorov–Kozlov on so(n)), got {constraints!r}")
        if constraints is None:
            if not self.is_so:
                raise ValueError(f"constraints are required on {alg.name}: pass the subspace D, e.g. "
                                 "ls.Subspace.annihilator(algebra, covectors), or constraints=\"none\"")
            constraints = suslov_distribution(alg.n)
        if not isinstance(constraints, Subspace):
            raise TypeError(f"constraints must be a Subspace (the fibre D), \"none\", \"fedorov_kozlov\" or None, "
                            f"got {type(constraints).__name__}")
        if constraints.algebra is not alg and (constraints.algebra.dim != alg.dim or not np.allclose(
                constraints.algebra.structure_constants, alg.structure_constants)):
            raise ValueError(f"constraints live in {constraints.algebra.name}, the inertia in {alg.name}")
        if constraints.dim == 0:
            raise ValueError("constraints leave no admissible velocity (D = 0): nothing moves")
        self.constraints = constraints
        # ---- potential
        if potential is None:
            potential = ZeroPotential(self.n if self.is_so else None)
        if not isinstance(potential, Potential):
            raise TypeError(f"potential must be a Potential (e.g. ls.LinearPotential(B)) or None, "
                            f"got {type(potential).__name__}")
        if not potential.is_zero:
            if not self.is_so:
                raise ValueError(f"potential must be None on {alg.name}: a potential V(Gamma) needs a body "
                                 "in SO(n); on other algebras only the Euler–Poincaré–Suslov system (V = 0) "
                                 "is defined")
            if potential.n is not None and potential.n != self.n:
                raise ValueError(f"potential acts on Gamma of dimension {potential.n}, the body is in "
                                 f"SO({self.n})")
            if potential.kind in ("general", "family"):
                _probe_potential(potential, self.n)
        self.potential = potential
        # ---- gyroscopic term
        eps = check_real(gyroscopic, "gyroscopic")
        if eps != 0.0 and not (self.is_so and self.n == 3):
            raise ValueError(f"gyroscopic must be 0 on {alg.name}: the gyroscopic force eps * Gamma x w "
                             "is defined for n = 3 (so(3)) only")
        self.gyroscopic = eps
        self._models: dict = {}

    # ------------------------------------------------------------------ pickling
    def __getstate__(self) -> dict:
        # Models hold closures (they pickle as recipes, see Model.__reduce__): the cache is rebuilt on use.
        state = self.__dict__.copy()
        state["_models"] = {}
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)

    # ------------------------------------------------------------------ data
    @property
    def has_potential(self) -> bool:
        """True iff V != 0."""
        return not self.potential.is_zero

    @property
    def needs_gamma(self) -> bool:
        """True iff ``Gamma`` enters the dynamics (V != 0 or a gyroscopic term)."""
        return self.has_potential or self.gyroscopic != 0.0

    @cached_property
    def covectors(self) -> np.ndarray:
        """Orthonormal constraint covectors ``a^i`` (rows), shape (r, d): the multipliers' basis."""
        return self.constraints.covectors

    @cached_property
    def is_fedorov_kozlov(self) -> bool:
        """True iff D is exactly ``suslov_distribution(n)`` with its basis ``E_in`` in order."""
        if not self.is_so or self.n < 2 or self.constraints.dim != self.n - 1:
            return False
        fk = suslov_distribution(self.n).basis
        return bool(np.allclose(self.constraints.basis, fk, rtol=0, atol=1e-14))

    def __repr__(self) -> str:
        extra = f", potential={self.potential!r}" if self.has_potential else ""
        extra += f", gyroscopic={self.gyroscopic:g}" if self.gyroscopic else ""
        return f"SuslovSystem({self.algebra.name}, dim D = {self.constraints.dim}{extra})"

    # ------------------------------------------------------------------ input helpers
    def coordinates(self, Omega, name: str = "Omega") -> np.ndarray:
        """``Omega`` as coordinates ``(..., d)`` from coordinates or representation matrices.

        See :func:`liesuslov.algebra.omega_coordinates` (the one reader of the package).
        """
        return omega_coordinates(self.algebra, Omega, name)

    def _gamma(self, Gamma, required: bool, name: str = "Gamma", omega: np.ndarray | None = None) -> np.ndarray | None:
        if Gamma is None:
            if required:
                why = "V != 0" if self.has_potential else "the gyroscopic term needs it"
                raise ValueError(f"{name} is required for this system ({why}): pass an array of shape "
                                 f"(..., {self.n})")
            return None
        if not self.is_so:
            raise ValueError(f"{name} must be None on {self.algebra.name} (no potential there)")
        G = as_float_array(Gamma, name, ndim_min=1, tail=(self.n,))
        if omega is not None and omega.shape[:-1] != G.shape[:-1]:
            try:  # (numpy's own error, later, named neither array)
                np.broadcast_shapes(omega.shape[:-1], G.shape[:-1])
            except ValueError:
                raise ValueError(f"the batch axes of Omega {omega.shape[:-1]} and {name} {G.shape[:-1]} do not "
                                 "broadcast") from None
        return G

    def _in_D(self, x: np.ndarray, name: str) -> np.ndarray:
        D = self.constraints
        if not np.all(D.contains(x, 1e-9)):
            raise ValueError(f"{name} is not in D: the constraints <a^i, Omega> = 0 fail (largest violation "
                             f"{float(np.max(np.abs(x @ self.covectors.T))):.3g})")
        return rows_at(x, D.basis.T)

    # ------------------------------------------------------------------ reference terms
    def torque(self, x: np.ndarray, Gamma: np.ndarray | None) -> np.ndarray:
        """The force terms of dM/dt in coordinates, without multipliers: (..., d).

        ``ad*_x J(x) + vee(dV/dGamma ∧ Gamma) + eps * vee(w ∧ Gamma)`` (no input checks).
        """
        f = self.algebra.coad(x, self.inertia(x))
        if self.has_potential:
            f = f + wedge_coordinates(self.potential.grad(Gamma), Gamma)
        if self.gyroscopic != 0.0:
            f = f + gyroscopic_torque(x, Gamma, self.gyroscopic)
        return f

    @cached_property
    def reaction(self) -> Reaction:
        """The matrices ``(A, K^-1, (A K^-1 A^T)^-1)`` of the multiplier form (dense: O(d^2) memory)."""
        A = self.covectors
        Kinv = self.inertia.inverse_matrix
        if A.shape[0] == 0:
            return Reaction(A, Kinv, np.zeros((0, 0)))
        S = A @ Kinv @ A.T
        return Reaction(A, Kinv, np.linalg.inv(S))

    def _multipliers_of(self, f: np.ndarray) -> np.ndarray:
        A, Kinv, Sinv = self.reaction
        return -rows_at(rows_at(rows_at(f, Kinv), A.T), Sinv)  # S symmetric

    # ------------------------------------------------------------------ public reference form
    def energy(self, Omega, Gamma=None) -> np.ndarray:
        """``E = 1/2 <J Omega, Omega> + V(Gamma)``, shape (...).

        Parameters
        ----------
        Omega : array_like, shape (..., d) or (..., n, n)
        Gamma : array_like, shape (..., n)
            Required iff V != 0.
        """
        x = self.coordinates(Omega)
        E = self.inertia.kinetic_energy(x)
        G = self._gamma(Gamma, omega=x, required=self.has_potential)
        if self.has_potential:
            E = E + self.potential.V(G)
        return E

    def multipliers(self, Omega, Gamma=None) -> np.ndarray:
        """Lagrange multipliers ``lambda`` (..., r) of the reference form (2.2).

        ``J(dOmega/dt) = f + sum_i lambda_i a^i`` with ``f`` the force terms (:meth:`torque`) and
        ``a^i`` the rows of :attr:`covectors`; ``lambda = -(A K^-1 A^T)^-1 A K^-1 f`` keeps
        ``A dOmega/dt = 0``.
        """
        x = self.coordinates(Omega)
        G = self._gamma(Gamma, omega=x, required=self.needs_gamma)
        return self._multipliers_of(self.torque(x, G))

    def rhs(self, Omega, Gamma=None) -> tuple[np.ndarray, np.ndarray | None]:
        """The reference multiplier form (2.2): ``(dOmega/dt coordinates (..., d), dGamma/dt (..., n))``.

        ``dGamma/dt = -Omega Gamma`` is None when no ``Gamma`` is given (allowed iff V = 0 and eps = 0).
        """
        x = self.coordinates(Omega)
        G = self._gamma(Gamma, omega=x, required=self.needs_gamma)
        f = self.torque(x, G)
        A, Kinv, _ = self.reaction
        xdot = rows_at(f + rows_at(self._multipliers_of(f), A), Kinv)
        if G is None:
            return xdot, None
        Gdot = -(self.algebra.hat(x) @ G[..., :, None])[..., 0]
        return xdot, Gdot

    def divergence(self, Omega, Gamma=None) -> np.ndarray:
        """Divergence of the reduced vector field in ``(xi, Gamma)`` coordinates, shape (...).

        Exactly ``tr d(xi')/d(xi)``: with ``L = K_D^-1 B`` and ``x = xi B`` it is
        ``sum_c L_c . (ad*_{B_c} K x + ad*_x K B_c + eps vee(w(B_c) ∧ Gamma))``; the ``Gamma`` block adds
        ``-tr Omega = 0``. Zero when D is J-invariant (form (2.3) preserves ``dOmega dGamma``); for a
        general D (e.g. Suslov's problem, ``suslov_free``) it is a nonzero linear function of Omega.

        Parameters
        ----------
        Omega : array_like, in D
        Gamma : array_like, optional
            Needed only with a gyroscopic term.
        """
        x = self.coordinates(Omega)
        self._in_D(x, "Omega")
        G = self._gamma(Gamma, omega=x, required=self.gyroscopic != 0.0)
        B = self.constraints.basis
        K = self.inertia.matrix
        L = np.linalg.solve(B @ K @ B.T, B)  # (k, d)
        xk = x[..., None, :]
        a1, b1 = np.broadcast_arrays(B, rows_at(x, K)[..., None, :])
        a2, b2 = np.broadcast_arrays(xk, B @ K)
        t = self.algebra.coad(a1, b1) + self.algebra.coad(a2, b2)  # (..., k, d)
        if self.gyroscopic != 0.0:
            t = t + gyroscopic_torque(B, G[..., None, :], self.gyroscopic)
        return np.sum(t * L, axis=(-2, -1))

    # ------------------------------------------------------------------ models
    def available_forms(self) -> list[str]:
        """The forms that hold for this scene, most specialised first."""
        return list(self._forms)

    @cached_property
    def _forms(self) -> tuple[str, ...]:
        # the scene does not change: judged once (model(form="auto") reads it on every integrate call)
        return tuple(f for f in FORMS if self.form_obstruction(f) is None)

    def form_obstruction(self, form: str) -> str | None:
        """Why ``form`` does not hold (a sentence), or None if it does."""
        if form not in FORMS:
            raise ValueError(f"form must be one of {('auto',) + FORMS}, got {form!r}")
        if form in ("reduced", "multiplier"):
            return None
        if not self._invariant:
            return "D is not an invariant subspace of the inertia operator (J(D) ⊄ D); use form='reduced'"
        if form == "symmetric" and not self._symmetric:
            return ("D is not the p of a symmetric pair (k ⊕ D with k = D^⊥, [k, k] ⊂ k, [k, D] ⊂ D, "
                    "[D, D] ⊂ k fails), so pr_D[J Omega, Omega] does not vanish; use form='eigenspace'")
        return None

    @cached_property
    def _invariant(self) -> bool:
        return self.inertia.is_invariant(self.constraints)

    @cached_property
    def _symmetric(self) -> bool:
        # the Fedorov–Kozlov D is the p of (so(n), so(n-1)): skip the O(dim^2) bracket test
        return True if self.is_fedorov_kozlov else self.constraints.is_symmetric()

    def model(self, gamma: bool | None = None, form: str = "auto") -> Model:
        """The smallest exact model of the scene, for the integrators.

        Parameters
        ----------
        gamma : bool or None
            None: include ``Gamma`` iff V != 0 or eps != 0; True: include it (so(n) only);
            False: drop it (ValueError when the dynamics needs it).
        form : {"auto", "symmetric", "eigenspace", "reduced", "multiplier"}
            "auto" picks the most specialised form that holds; asking for one that does not hold is a
            ValueError saying why (:meth:`form_obstruction`).

        Returns
        -------
        Model
            See :class:`liesuslov.mechanics.models.Model` (cached per arguments).
        """
        if gamma is not None and not isinstance(gamma, (bool, np.bool_)):
            raise TypeError(f"gamma must be None, True or False, got {type(gamma).__name__}")
        if gamma is None:
            has_gamma = self.needs_gamma
        elif gamma:
            if not self.is_so:
                raise ValueError(f"gamma=True needs a body in SO(n); {self.algebra.name} has no Gamma")
            has_gamma = True
        else:
            if self.needs_gamma:
                why = "V != 0" if self.has_potential else "the gyroscopic term depends on Gamma"
                raise ValueError(f"gamma=False is impossible here: {why}")
            has_gamma = False
        if form == "auto":
            form = self._forms[0]
        else:
            why = self.form_obstruction(form)
            if why is not None:
                raise ValueError(f"form={form!r} does not hold for this system: {why}")
        key = (has_gamma, form)
        if key not in self._models:
            self._models[key] = build_model(self, form, has_gamma)
        return self._models[key]


# ---------------------------------------------------------------------- helpers
def _probe_potential(potential: Potential, n: int) -> None:
    """Evaluate a user potential on a small batch to catch wrong shapes early, naming the callable.

    The batch is (3, 1): two batch axes, as the integrators pass, and no size equal to 2 (a batch of 2 let a
    function returning (..., 2) where a pair is due pass — and mix its rows)."""
    G = np.zeros((3, 1, n))
    G[:, 0, -1] = 1.0
    shape = f"(3, 1, {n})"
    try:
        V = real_values(potential.V(G), "potential.V")
        g = real_values(potential.grad(G), "potential.grad")
    except Exception as exc:  # noqa: BLE001 - re-raised with the context, a wrong type as a TypeError
        kind = TypeError if isinstance(exc, TypeError) else ValueError
        why = " (a potential is given the integrator's Gamma read-only: compute on a copy)" \
            if "read-only" in str(exc) else ""
        raise kind(f"potential could not be evaluated on Gamma of shape {shape}: {exc}{why}") from exc
    if V.shape != (3, 1):
        raise ValueError(f"potential.V must map (..., {n}) to (...): got shape {V.shape} for input {shape}")
    if g.shape != (3, 1, n):
        raise ValueError(f"potential.grad must map (..., {n}) to (..., {n}): got shape {g.shape} "
                         f"for input {shape}")
