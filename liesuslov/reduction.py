"""The SO(n−1) reduction of the multidimensional Lagrange case to the spherical pendulum.

The Lagrange case (``liesuslov.cases.lagrange``): mass tensor ``I = diag(I1, …, I1, In)``,
``V = Bn Γn``, Fedorov–Kozlov constraints (``Ω = u e_nᵀ − e_n uᵀ``, ``Ω_ij = 0`` for i, j ≤ n−1),
reconstruction ``g⁻¹ ġ = Ω`` and ``Γ = gᵀ γ`` with ``γ`` fixed in space. The right action of
SO(n−1) (rotations fixing the symmetry axis ``e_n``) has the momentum map ``Φ`` (the so(n−1)
block of ``M = J(Ω)``), which vanishes on every Suslov state; the quotient
``Φ⁻¹(0)/SO(n−1) = T*S^{n−1}`` carries the spherical pendulum (Jovanović 2003, Lemma of §4.1)::

    q = g e_n ∈ S^{n−1},   v = q̇ = g Ω e_n,   m = I1 + In,
    H(q, v) = ½ m |v|² + Bn ⟨γ, q⟩ = E(Ω, Γ)   (the Suslov energy, identically),
    m v̇ = −Bn (γ − ⟨γ, q⟩ q) − m |v|² q.

The pendulum is integrated on ``so(n) × S^{n−1}`` (``docs/reduction.md`` has the derivation):
``W = v ∧ q`` (``x ∧ y = x yᵀ − y xᵀ``) obeys ``Ẇ = −(Bn/m) γ ∧ q`` and ``q̇ = W q``; the
library's RKMK integrator advances ``W`` classically and moves ``q`` by orthogonal matrices, so
``|q| = 1`` and ``⟨q, v⟩ = ⟨q, W q⟩ = 0`` hold to rounding along the numerical solution.

Public names: :func:`to_spherical_pendulum`, :func:`pendulum_energy`, :func:`pendulum_momentum`,
:func:`momentum_map`, :class:`SphericalPendulum`, :func:`integrate_pendulum`,
:class:`PendulumSolution`, :func:`lift`, :func:`lagrange_parameters`, :class:`LagrangeParameters`,
:func:`check_lagrange_reduction`, :class:`ReductionCheck`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._validation import as_float_array, check_positive, check_real
from .algebra import Inertia, SpecialOrthogonalAlgebra, Subspace, so, suslov_distribution
from .integrators import integrate
from .mechanics import Case, SuslovSystem

__all__ = ["to_spherical_pendulum", "pendulum_energy", "pendulum_momentum", "momentum_map",
           "SphericalPendulum", "PendulumModel", "PendulumSolution", "integrate_pendulum", "lift",
           "LagrangeParameters", "lagrange_parameters", "ReductionCheck", "check_lagrange_reduction"]

_UNIT_TOL = 1e-8  # |q| = 1, |gamma| = 1 (as integrate's check of Gamma0)
_TANGENT_TOL = 1e-8  # |<q, v>| <= tol * max(1, |v|)
_ORTHO_TOL = 1e-8  # |g^T g - I| for attitudes (as integrate's check of g0)
_SKEW_TOL = 1e-12  # relative, as integrate's reading of Omega0


# ====================================================================== input helpers
def _skew_or_coords(Omega, n: int, name: str) -> np.ndarray:
    """``Omega`` as skew matrices (..., n, n), from matrices or so(n) coordinates (..., d)."""
    X = as_float_array(Omega, name, ndim_min=1)
    d = n * (n - 1) // 2
    if X.ndim >= 2 and X.shape[-2:] == (n, n):
        scale = max(1.0, float(np.max(np.abs(X), initial=0.0)))
        if np.allclose(X, -np.swapaxes(X, -1, -2), rtol=0, atol=_SKEW_TOL * scale):
            return 0.5 * (X - np.swapaxes(X, -1, -2))
        if d != n:  # n = 3: a (3, 3) block that is not skew may be three coordinate vectors
            raise ValueError(f"{name} given as ({n}, {n}) matrices must be skew-symmetric "
                             f"(max |{name} + {name}^T| = {np.max(np.abs(X + np.swapaxes(X, -1, -2))):.3g})")
    if X.shape[-1] != d:
        raise ValueError(f"{name} must be skew matrices (..., {n}, {n}) or so({n}) coordinates (..., {d}), "
                         f"got shape {X.shape}")
    return so(n).hat(X)


def _check_rotations(g: np.ndarray, name: str, tol: float = _ORTHO_TOL) -> None:
    """ValueError unless every ``g`` (..., k, k) is in SO(k) to ``tol``."""
    k = g.shape[-1]
    if g.size == 0:
        return
    err = float(np.max(np.abs(np.swapaxes(g, -1, -2) @ g - np.eye(k))))
    if err > tol:
        raise ValueError(f"{name} must be in SO({k}): max |{name}^T {name} - I| = {err:.3g} > {tol:g}")
    if np.any(np.linalg.det(g) < 0):
        raise ValueError(f"{name} must be in SO({k}): some {name} have det = -1 (reflections)")


def _unit(x: np.ndarray, name: str) -> np.ndarray:
    """``x / |x|`` after checking ``| |x| - 1 | <= _UNIT_TOL``."""
    nrm = np.linalg.norm(x, axis=-1)
    if x.size and np.any(np.abs(nrm - 1.0) > _UNIT_TOL):
        raise ValueError(f"{name} must be a unit vector (|{name}| = 1); got norms in "
                         f"[{nrm.min():.6g}, {nrm.max():.6g}]: pass {name} / |{name}|")
    return x / nrm[..., None]


def _tangent(q: np.ndarray, v: np.ndarray, name_q: str, name_v: str) -> np.ndarray:
    """``v - <q, v> q`` after checking that ``v`` is tangent to the sphere at the unit ``q``."""
    dot = np.sum(q * v, axis=-1)
    scale = np.maximum(1.0, np.linalg.norm(v, axis=-1))
    if dot.size and np.any(np.abs(dot) > _TANGENT_TOL * scale):
        raise ValueError(f"{name_v} must be tangent to the sphere at {name_q} (<{name_q}, {name_v}> = 0); "
                         f"got |<{name_q}, {name_v}>| up to {np.max(np.abs(dot)):.3g}: pass "
                         f"{name_v} - <{name_q}, {name_v}> {name_q}")
    return v - dot[..., None] * q


def _dim_n(n: Any) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise TypeError(f"n must be an integer >= 2, got {type(n).__name__}")
    if n < 2:
        raise ValueError(f"n must be >= 2 (the pendulum lives on S^(n-1)), got {n}")
    return int(n)


# ====================================================================== the projection and its energy
def to_spherical_pendulum(g, Omega) -> tuple[np.ndarray, np.ndarray]:
    """The reduction map ``(g, Ω) ↦ (q, v)`` of the Lagrange case onto the spherical pendulum.

    ``q = g e_n`` (the symmetry axis in space, a point of S^{n−1}) and ``v = q̇ = g Ω e_n`` (its
    velocity, tangent: ``⟨q, v⟩ = (gᵀg)_{n·} Ω e_n = Ω_nn = 0``). It is the tangent map of the
    bundle projection ``SO(n) → SO(n)/SO(n−1) = S^{n−1}``, so it is defined for any Ω; on
    Suslov states (Ω in the Fedorov–Kozlov D) it is the SO(n−1) quotient map.

    Parameters
    ----------
    g : array_like, shape (..., n, n)
        Attitudes in SO(n) (checked: ``|gᵀg − I| <= 1e-8``, ``det g = +1``).
    Omega : array_like, shape (..., n, n) or (..., d)
        Body angular velocities ``g⁻¹ ġ``: skew matrices or so(n) coordinates (``d = n(n−1)/2``;
        a trailing skew (n, n) block is read as a matrix). Batch axes broadcast with those of g.

    Returns
    -------
    q : ndarray, shape (..., n)
        ``g[..., :, n−1]``.
    v : ndarray, shape (..., n)
        ``g Ω e_n = g @ Omega[..., :, n−1]``.

    Raises
    ------
    ValueError
        ``g`` not square, not in SO(n); ``Omega`` not skew or of the wrong shape; batch axes
        that do not broadcast; non-finite values.

    Examples
    --------
    >>> import numpy as np, liesuslov as ls
    >>> q, v = ls.to_spherical_pendulum(np.eye(4), ls.wedge([1.0, 0, 0, 0], [0, 0, 0, 1.0]))
    >>> q, v
    (array([0., 0., 0., 1.]), array([1., 0., 0., 0.]))
    """
    G = as_float_array(g, "g", ndim_min=2)
    n = G.shape[-1]
    if G.shape[-2] != n or n < 2:
        raise ValueError(f"g must be square rotation matrices (..., n, n) with n >= 2, got shape {G.shape}")
    _check_rotations(G, "g")
    X = _skew_or_coords(Omega, n, "Omega")
    try:
        shape = np.broadcast_shapes(G.shape[:-2], X.shape[:-2])
    except ValueError as exc:
        raise ValueError(f"the batch axes of g {G.shape[:-2]} and Omega {X.shape[:-2]} "
                         "do not broadcast") from exc
    q = np.broadcast_to(G[..., :, -1], shape + (n,)).copy()
    v = np.einsum("...ij,...j->...i", G, X[..., :, -1])
    return q, np.broadcast_to(v, shape + (n,)).copy()


def pendulum_energy(q, v, m, B, gamma) -> np.ndarray:
    """Energy of the spherical pendulum ``H = ½ m |v|² + B ⟨γ, q⟩``.

    For the Lagrange case, ``m = I1 + In``, ``B = Bn``, ``γ = g Γ`` (the vertical in space), and
    ``H(q, v)`` equals the Suslov energy ``½⟨J Ω, Ω⟩ + Bn Γn`` at every state: ``⟨J Ω, Ω⟩ =
    Σ_i (I1 + In) Ω_in² = m |g Ω e_n|²`` and ``Γn = ⟨gᵀγ, e_n⟩ = ⟨γ, q⟩``.

    Parameters
    ----------
    q, v : array_like, shape (..., n)
        Point and velocity (not checked to lie on T S^{n−1}).
    m : float
        Mass (positive).
    B : float
        Potential coefficient.
    gamma : array_like, shape (..., n)
        The direction of the field; batch axes broadcast.

    Returns
    -------
    ndarray, shape (...)
    """
    q = as_float_array(q, "q", ndim_min=1)
    n = q.shape[-1]
    v = as_float_array(v, "v", ndim_min=1, tail=(n,))
    gam = as_float_array(gamma, "gamma", ndim_min=1, tail=(n,))
    m = check_positive(m, "m")
    B = check_real(B, "B")
    return 0.5 * m * np.sum(v * v, axis=-1) + B * np.sum(gam * q, axis=-1)


def pendulum_momentum(v, m) -> np.ndarray:
    """The cotangent (Legendre) image ``p = m v`` of a pendulum velocity, shape (..., n).

    ``T*S^{n−1}`` is identified with ``T S^{n−1} ⊂ R^n × R^n`` by the round metric; under the
    reduction ``p`` is the image of the body momentum ``M = J(Ω)``: ``p = g M e_n`` (the last
    column of M is ``(I1 + In) Ω e_n`` on Suslov states).
    """
    v = as_float_array(v, "v", ndim_min=1)
    return check_positive(m, "m") * v


# ====================================================================== the momentum map
def momentum_map(Omega, inertia, *, as_matrix: bool = False) -> np.ndarray:
    """The momentum map Φ of the right SO(n−1) action: the so(n−1) block of ``M = J(Ω)``.

    ``Φ(Ω) = (M_ij)_{i, j ≤ n−1}`` with ``M = I Ω + Ω I`` (or ``K x`` for a general inertia in
    coordinates), a left-invariant function on ``T*SO(n)``. For a diagonal mass tensor and Ω in
    the Fedorov–Kozlov D (``Ω_ij = 0`` for i, j ≤ n−1), ``M_ij = (I_i + I_j) Ω_ij = 0``: every
    Suslov state lies on ``Φ⁻¹(0)``, where the Lagrange case reduces to the spherical pendulum.

    Parameters
    ----------
    Omega : array_like, shape (..., n, n) or (..., d)
        Body angular velocities (skew matrices or so(n) coordinates), any Ω in so(n).
    inertia : Inertia or array_like
        An :class:`~liesuslov.algebra.Inertia` on so(n), or a mass tensor (n, n) or its diagonal (n,).
    as_matrix : bool
        Return the (n−1)×(n−1) skew block instead of its so(n−1) coordinates.

    Returns
    -------
    ndarray, shape (..., (n−1)(n−2)/2) or (..., n−1, n−1)
        Coordinates in the basis ``E_ij`` of so(n−1) (i < j ≤ n−1, lexicographic: the entries
        ``M_ij`` of the block's upper triangle), or the block itself. For n = 3, the single
        coordinate ``M_12``.
    """
    if not isinstance(inertia, Inertia):
        inertia = Inertia.from_mass_tensor(as_float_array(inertia, "inertia"))
    alg = inertia.algebra
    if not isinstance(alg, SpecialOrthogonalAlgebra) or alg.n < 3:
        raise ValueError(f"inertia must act on so(n) with n >= 3, got {alg.name}")
    n = alg.n
    X = _skew_or_coords(Omega, n, "Omega")
    M = alg.hat(inertia(alg.vee(X)))
    block = M[..., : n - 1, : n - 1]
    return block if as_matrix else so(n - 1).vee(block)


# ====================================================================== the pendulum as a system
class SphericalPendulum:
    """The spherical pendulum on ``T S^{n−1} ⊂ R^n × R^n``: ``L = ½ m |q̇|² − B ⟨γ, q⟩``, ``|q| = 1``.

    Equations of motion (the constraint force keeps ``|q| = 1``)::

        q̇ = v,   m v̇ = −B (γ − ⟨γ, q⟩ q) − m |v|² q.

    Integrated on ``so(n) × S^{n−1}`` as ``Ẇ = −(B/m) γ ∧ q``, ``q̇ = W q`` with ``W = v ∧ q``
    (:class:`PendulumModel`, :func:`integrate_pendulum`).

    Parameters
    ----------
    n : int >= 2
        Ambient dimension (the sphere is S^{n−1}).
    m : float > 0
        Mass; ``I1 + In`` for the Lagrange case.
    B : float
        Field strength; ``Bn`` for the Lagrange case. ``B = 0`` gives geodesic (great-circle) motion.
    gamma : array_like, shape (..., n), optional
        Unit direction of the field (default ``e_n``); batch axes allowed (one field per
        trajectory, broadcast against the initial data).

    Attributes
    ----------
    n, m, B : int, float, float
    gamma : ndarray, shape (..., n)
    """

    def __init__(self, n: int, m: float, B: float, gamma=None) -> None:
        self.n = _dim_n(n)
        self.m = check_positive(m, "m")
        self.B = check_real(B, "B")
        if gamma is None:
            gam = np.eye(self.n)[-1]
        else:
            gam = _unit(as_float_array(gamma, "gamma", ndim_min=1, tail=(self.n,)), "gamma")
        gam.setflags(write=False)
        self.gamma = gam
        self.algebra = so(self.n)

    def __repr__(self) -> str:
        g = self.gamma if self.gamma.ndim == 1 else f"batch {self.gamma.shape[:-1]}"
        return f"SphericalPendulum(n={self.n}, m={self.m:g}, B={self.B:g}, gamma={g})"

    # ------------------------------------------------------------------ functions on T S^{n-1}
    def energy(self, q, v) -> np.ndarray:
        """``H = ½ m |v|² + B ⟨γ, q⟩``, shape (...)."""
        return pendulum_energy(q, v, self.m, self.B, self.gamma)

    def momentum(self, v) -> np.ndarray:
        """``p = m v``, shape (..., n)."""
        return pendulum_momentum(v, self.m)

    def rhs(self, q, v) -> tuple[np.ndarray, np.ndarray]:
        """The reference field ``(q̇, v̇) = (v, −(B/m)(γ − ⟨γ, q⟩ q) − |v|² q)``, each (..., n)."""
        q = as_float_array(q, "q", ndim_min=1, tail=(self.n,))
        v = as_float_array(v, "v", ndim_min=1, tail=(self.n,))
        gq = np.sum(self.gamma * q, axis=-1, keepdims=True)
        vdot = -(self.B / self.m) * (self.gamma - gq * q) - np.sum(v * v, axis=-1, keepdims=True) * q
        return v.copy(), vdot

    def angular_momentum(self, q, v) -> np.ndarray:
        """``L = m q ∧ v`` (..., n, n); ``L̇ = B γ ∧ q``."""
        q = as_float_array(q, "q", ndim_min=1, tail=(self.n,))
        v = as_float_array(v, "v", ndim_min=1, tail=(self.n,))
        P = q[..., :, None] * v[..., None, :]
        return self.m * (P - np.swapaxes(P, -1, -2))

    def momentum_about_vertical(self, q, v) -> np.ndarray:
        """The conserved part ``P L P`` of ``L = m q ∧ v``, ``P = I − γγᵀ``: shape (..., n, n).

        ``P (γ ∧ q) P = 0`` since ``Pγ = 0``, so ``d(P L P)/dt = 0``: the components of the angular
        momentum in the planes orthogonal to γ are first integrals (n = 3: the one component
        about the vertical; together with H they make the pendulum integrable).
        """
        L = self.angular_momentum(q, v)
        P = np.eye(self.n) - self.gamma[..., :, None] * self.gamma[..., None, :]
        return P @ L @ P

    def state(self, q, v) -> np.ndarray:
        """so(n) coordinates of ``W = v ∧ q`` (..., d): the vector part of the integrated state."""
        q = as_float_array(q, "q", ndim_min=1, tail=(self.n,))
        v = as_float_array(v, "v", ndim_min=1, tail=(self.n,))
        r, c = np.triu_indices(self.n, 1)
        return v[..., r] * q[..., c] - v[..., c] * q[..., r]

    # ------------------------------------------------------------------ integration
    def model(self, batch_shape: tuple[int, ...] = ()) -> PendulumModel:
        """The model object that :func:`liesuslov.integrate` runs, for a batch of ``batch_shape``.

        A batched ``gamma`` is broadcast to ``batch_shape`` and flattened in the integrator's order.
        """
        gam = self.gamma
        if gam.ndim > 1:
            try:
                gam = np.broadcast_to(gam, tuple(batch_shape) + (self.n,)).reshape(-1, self.n)
            except ValueError as exc:
                raise ValueError(f"gamma's batch axes {self.gamma.shape[:-1]} do not broadcast to "
                                 f"{tuple(batch_shape)}") from exc
        return PendulumModel(self.n, self.B / self.m, gam)

    def integrate(self, q0, v0, t_span, **integrate_kwargs) -> PendulumSolution:
        """Shorthand for :func:`integrate_pendulum` ``(self, q0, v0, t_span, **integrate_kwargs)``."""
        return integrate_pendulum(self, q0, v0, t_span, **integrate_kwargs)


class PendulumModel:
    """The pendulum in the model protocol of :class:`liesuslov.mechanics.Model` (duck-typed).

    State ``(xi, q)``: ``xi = vee(W)`` (all of so(n), ``k = d``) advanced classically, and ``q``
    (the integrator's "Gamma") moved by the group. The integrator moves Gamma by
    ``Γ̇ = −Ω Γ``; here ``Ω = −W`` (``omega_matrix(xi) = −hat(xi)``), so ``q̇ = W q``::

        xi_dot(xi, q) = −(B/m) vee(γ ∧ q),     omega_coords(xi) = −xi,     xi_from_coords(x) = −x.

    Parameters
    ----------
    n : int
    c : float
        ``B / m``.
    gamma : ndarray, shape (n,) or (batch, n)
        The field direction (flattened batch, as the integrator passes states).
    """

    form = "spherical-pendulum"
    has_gamma = True
    fedorov_kozlov = False

    def __init__(self, n: int, c: float, gamma: np.ndarray) -> None:
        self.n = int(n)
        self.algebra = so(self.n)
        d = self.algebra.dim
        self.k = d
        self.state_dim = d + self.n
        self.subspace = Subspace(self.algebra, np.eye(d))
        self.reduced_inertia = np.eye(d)
        self.path = "W' = -(B/m) gamma ∧ q, q' = W q"
        self.c = float(c)
        self.gamma = np.ascontiguousarray(gamma, dtype=float)
        r, col = np.triu_indices(self.n, 1)
        self._r, self._c = r, col
        nn = self.n
        negc = -self.c
        gam = self.gamma
        gr, gc = gam[..., r], gam[..., col]

        def xi_dot(xi, q):
            return negc * (gr * q[..., col] - q[..., r] * gc)

        def omega_matrix(xi):
            X = np.zeros(xi.shape[:-1] + (nn, nn))
            X[..., r, col] = -xi
            X[..., col, r] = xi
            return X

        def omega_coords(xi):
            return -np.asarray(xi, dtype=float)

        def xi_from_coords(x):
            return -np.asarray(x, dtype=float)

        def Gamma_dot(xi, q):  # W q = -Omega q
            return -(omega_matrix(xi) @ q[..., :, None])[..., 0]

        self.xi_dot = xi_dot
        self.omega_matrix = omega_matrix
        self.omega_coords = omega_coords
        self.xi_from_coords = xi_from_coords
        self.Gamma_dot = Gamma_dot

    def vector_field(self, t, y) -> np.ndarray:
        """``dy/dt`` for the flat state ``y = concat(vee W, q)`` (reference, for scipy's solvers)."""
        y = np.asarray(y, dtype=float)
        xi, q = y[..., : self.k], y[..., self.k:]
        return np.concatenate([self.xi_dot(xi, q), self.Gamma_dot(xi, q)], axis=-1)

    def description(self) -> str:
        """One line: the form and the state."""
        return (f"spherical-pendulum form on {self.algebra.name} [{self.path}]: state W ({self.k}) "
                f"+ q ({self.n}) = {self.state_dim}")

    def __repr__(self) -> str:
        return f"PendulumModel({self.description()})"


@dataclass(frozen=True, eq=False)
class PendulumSolution:
    """What :func:`integrate_pendulum` returns; time axis first, then the batch axes.

    Attributes
    ----------
    t : ndarray, shape (N,)
    q : ndarray, shape (N, ..., n)
        Points of S^{n−1} (``|q| = 1`` to rounding).
    v : ndarray, shape (N, ..., n)
        Velocities ``v = W q`` (``⟨q, v⟩ = 0`` to rounding).
    energy : ndarray, shape (N, ...)
        ``½ m |v|² + B ⟨γ, q⟩``.
    W : ndarray, shape (N, ..., d)
        so(n) coordinates of the integrated ``W`` (``= v ∧ q`` up to the method's error).
    m : float
        The pendulum's mass (for :attr:`p` ``= m v``).
    stats : dict
        The integrator's statistics.
    status : int
        0 success, −1 failure (``message`` says why; the arrays hold what was computed).
    message : str
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    energy: np.ndarray
    W: np.ndarray
    m: float = 1.0
    stats: dict = field(default_factory=dict)
    status: int = 0
    message: str = ""

    @property
    def success(self) -> bool:
        return self.status == 0

    @property
    def p(self) -> np.ndarray:
        """Momenta ``p = m v``, shape (N, ..., n)."""
        return self.m * self.v


_FORBIDDEN = ("Gamma0", "g0", "reconstruct", "form")


def integrate_pendulum(pendulum: SphericalPendulum, q0, v0, t_span, **integrate_kwargs) -> PendulumSolution:
    """Integrate the spherical pendulum by the library's RKMK integrator on ``so(n) × S^{n−1}``.

    The state is ``W = v ∧ q ∈ so(n)`` (advanced by the classical RK formulas) and ``q`` (moved by
    the exponential or Cayley image of the stage combination, an orthogonal matrix), with
    ``Ẇ = −(B/m) γ ∧ q`` and ``q̇ = W q``; the output velocity is ``v = W q``. Hence ``|q| = 1``
    and ``⟨q, v⟩ = 0`` hold to rounding at every step, whatever the step size.

    Parameters
    ----------
    pendulum : SphericalPendulum
    q0 : array_like, shape (..., n)
        Initial points (unit vectors, checked to 1e-8 and normalised).
    v0 : array_like, shape (..., n)
        Initial velocities, tangent: ``|⟨q0, v0⟩| <= 1e-8 max(1, |v0|)`` (the residue is projected out).
    t_span : (t0, t1)
    **integrate_kwargs
        Passed to :func:`liesuslov.integrate`: ``method`` (default ``"rkmk45"`` here), ``chart``,
        ``h``, ``rtol``, ``atol``, ``t_eval``, ``first_step``, ``max_steps``, ``progress``.
        ``Gamma0``, ``g0``, ``reconstruct`` and ``form`` are not accepted.

    Returns
    -------
    PendulumSolution
        ``t (N,)``, ``q (N, ..., n)``, ``v (N, ..., n)``, ``energy (N, ...)``, ``W (N, ..., d)``, stats.

    Examples
    --------
    >>> import numpy as np, liesuslov as ls
    >>> P = ls.SphericalPendulum(3, m=2.0, B=1.0, gamma=[0, 0, 1.0])
    >>> sol = ls.integrate_pendulum(P, [1.0, 0, 0], [0, 0.5, 0.2], (0, 5), method="rkmk853", rtol=1e-10)
    >>> bool(np.all(np.abs(np.linalg.norm(sol.q, axis=-1) - 1) < 1e-14))
    True
    """
    if not isinstance(pendulum, SphericalPendulum):
        raise TypeError(f"pendulum must be a SphericalPendulum, got {type(pendulum).__name__}")
    bad = [k for k in _FORBIDDEN if k in integrate_kwargs]
    if bad:
        raise TypeError(f"integrate_pendulum does not take {', '.join(bad)}: the state is (q0, v0)")
    n = pendulum.n
    q = _unit(as_float_array(q0, "q0", ndim_min=1, tail=(n,)), "q0")
    v = as_float_array(v0, "v0", ndim_min=1, tail=(n,))
    try:
        shape = np.broadcast_shapes(q.shape[:-1], v.shape[:-1], pendulum.gamma.shape[:-1])
    except ValueError as exc:
        raise ValueError(f"the batch axes of q0 {q.shape[:-1]}, v0 {v.shape[:-1]} and gamma "
                         f"{pendulum.gamma.shape[:-1]} do not broadcast") from exc
    q = np.broadcast_to(q, shape + (n,))
    v = _tangent(q, np.broadcast_to(v, shape + (n,)), "q0", "v0")
    P = v[..., :, None] * q[..., None, :]
    Omega0 = np.swapaxes(P, -1, -2) - P  # Omega = -W = q ∧ v, exactly skew
    kwargs = {"method": "rkmk45", **integrate_kwargs}
    model = pendulum.model(shape)
    sol = integrate(model, Omega0, t_span, Gamma0=q, **kwargs)
    Q = sol.Gamma
    Wc = sol.xi
    Wm = pendulum.algebra.hat(Wc)
    V = np.einsum("...ij,...j->...i", Wm, Q)
    return PendulumSolution(t=sol.t, q=Q, v=V, energy=pendulum.energy(Q, V), W=Wc, m=pendulum.m,
                            stats=dict(sol.stats), status=sol.status, message=sol.message)


# ====================================================================== the lift
def _axis_rotation(q: np.ndarray) -> np.ndarray:
    """A deterministic ``g_q ∈ SO(n)`` with ``g_q e_n = q`` for unit ``q`` (..., n).

    ``q_n >= 0``: the rotation in the plane span{e_n, q} taking e_n to q and fixing its orthogonal
    complement, ``R(q) = I + K + K² / (1 + q_n)`` with ``K = q e_nᵀ − e_n qᵀ`` (identity at q = e_n).
    ``q_n < 0``: ``R(−q) F`` with ``F = diag(−1, 1, …, 1, −1)`` (the half-turn in the (e_1, e_n)
    plane), which avoids the singularity of ``R`` at ``q = −e_n``.
    """
    n = q.shape[-1]
    neg = q[..., -1] < 0
    s = np.where(neg, -1.0, 1.0)[..., None]
    p = s * q  # p_n >= 0
    e = np.zeros(n)
    e[-1] = 1.0
    K = p[..., :, None] * e - e[:, None] * p[..., None, :]
    R = np.eye(n) + K + (K @ K) / (1.0 + p[..., -1])[..., None, None]
    F = np.ones(n)
    F[0] = F[-1] = -1.0
    return np.where(neg[..., None, None], R * F, R)  # R F scales the columns of R


def lift(q, v, fibre=None) -> tuple[np.ndarray, np.ndarray]:
    """A Suslov state ``(g, Ω)`` over a pendulum state ``(q, v)``: a right inverse of the reduction.

    ``g = g_q · diag(R, 1)`` with ``g_q`` a deterministic rotation taking ``e_n`` to ``q`` and
    ``R = fibre ∈ SO(n−1)`` the point of the fibre (the SO(n−1) orbit), and ``Ω = ū ∧ e_n =
    ū e_nᵀ − e_n ūᵀ ∈ D`` with ``ū = gᵀ v`` (whose last entry ``⟨q, v⟩`` is 0). Then
    ``to_spherical_pendulum(g, Ω) == (q, v)`` for every fibre. To start the Suslov system, take
    ``Γ0 = gᵀ γ``.

    Parameters
    ----------
    q : array_like, shape (..., n)
        Unit vectors (checked to 1e-8, normalised).
    v : array_like, shape (..., n)
        Tangent vectors at q (``|⟨q, v⟩| <= 1e-8 max(1, |v|)``, the residue projected out).
    fibre : array_like, shape (..., n−1, n−1), optional
        Rotations in SO(n−1) (checked); default the identity.

    Returns
    -------
    g : ndarray, shape (..., n, n)
        In SO(n), ``g e_n = q``. For the default fibre: the rotation in the plane span{e_n, q}
        when ``q_n >= 0`` (the identity at q = e_n); ``R(−q) diag(−1, 1, …, 1, −1)`` when ``q_n < 0``.
    Omega : ndarray, shape (..., n, n)
        In the Fedorov–Kozlov D, with ``g Ω e_n = v``.
    """
    qa = as_float_array(q, "q", ndim_min=1)
    n = qa.shape[-1]
    if n < 2:
        raise ValueError(f"q must have shape (..., n) with n >= 2, got {qa.shape}")
    qa = _unit(qa, "q")
    va = as_float_array(v, "v", ndim_min=1, tail=(n,))
    shapes = [qa.shape[:-1], va.shape[:-1]]
    Rf = None
    if fibre is not None:
        Rf = as_float_array(fibre, "fibre", ndim_min=2, tail=(n - 1, n - 1))
        _check_rotations(Rf, "fibre")
        shapes.append(Rf.shape[:-2])
    try:
        shape = np.broadcast_shapes(*shapes)
    except ValueError as exc:
        raise ValueError(f"the batch axes of q, v and fibre do not broadcast: {shapes}") from exc
    qa = np.broadcast_to(qa, shape + (n,))
    va = _tangent(qa, np.broadcast_to(va, shape + (n,)), "q", "v")
    g = _axis_rotation(qa)
    if Rf is not None:
        g = g.copy()
        g[..., :, : n - 1] = g[..., :, : n - 1] @ Rf
    u = np.einsum("...ji,...j->...i", g, va)
    u[..., -1] = 0.0
    Omega = np.zeros(shape + (n, n))
    Omega[..., :, -1] = u
    Omega[..., -1, :] = -u
    return g, Omega


# ====================================================================== recognising the Lagrange case
@dataclass(frozen=True)
class LagrangeParameters:
    """The parameters of a Lagrange scene: ``I = diag(I1, …, I1, In)``, ``V = Bn Γn``; ``m = I1 + In``."""

    n: int
    I1: float
    In: float
    Bn: float

    @property
    def m(self) -> float:
        """The pendulum's mass ``I1 + In``."""
        return self.I1 + self.In


def _mass_tensor(inertia: Inertia) -> np.ndarray:
    """The mass tensor of an inertia on so(n); recovered from K = diag(I_i + I_j) when not stored."""
    if inertia.mass_tensor is not None:
        return np.asarray(inertia.mass_tensor, dtype=float)
    alg = inertia.algebra
    n = alg.n
    K = inertia.matrix
    r, c = np.triu_indices(n, 1)
    A = np.zeros((alg.dim, n))
    A[np.arange(alg.dim), r] = 1.0
    A[np.arange(alg.dim), c] = 1.0
    Id = np.linalg.lstsq(A, np.diag(K), rcond=None)[0]
    K2 = Inertia.from_mass_tensor(Id).matrix
    if not np.allclose(K, K2, rtol=1e-10, atol=1e-12 * float(np.max(np.abs(K)))):
        raise ValueError("the inertia is not that of a rigid body with a diagonal mass tensor "
                         "(K is not diag(I_i + I_j)); the Lagrange case needs I = diag(I1, ..., I1, In)")
    return np.diag(Id)


def lagrange_parameters(system_or_case) -> LagrangeParameters:
    """Check that a scene is the multidimensional Lagrange case and return its parameters.

    The Lagrange case: a body in SO(n), n >= 3, with mass tensor ``I = diag(I1, …, I1, In)``,
    potential ``V = Bn Γn`` (a :class:`~liesuslov.LinearPotential` with ``B = (0, …, 0, Bn)``, or
    V = 0 meaning Bn = 0), the Fedorov–Kozlov constraints (``Ω_ij = 0`` for i, j ≤ n−1) and no
    gyroscopic term.

    Parameters
    ----------
    system_or_case : SuslovSystem or Case
        E.g. ``ls.cases.lagrange(n, I1, In, Bn)`` or ``ls.cases.lagrange3(J1, J3, B3)``.

    Returns
    -------
    LagrangeParameters

    Raises
    ------
    TypeError
        Not a SuslovSystem or Case.
    ValueError
        Saying what differs from the Lagrange case.
    """
    system = system_or_case.system if isinstance(system_or_case, Case) else system_or_case
    if not isinstance(system, SuslovSystem):
        raise TypeError("system_or_case must be a SuslovSystem or a Case (e.g. ls.cases.lagrange(4, 1, 2, 1))"
                        f", got {type(system_or_case).__name__}")
    alg = system.algebra
    if not isinstance(alg, SpecialOrthogonalAlgebra) or alg.n < 3:
        raise ValueError(f"not the Lagrange case: the body must be in SO(n) with n >= 3, got {alg.name}")
    n = alg.n
    I = _mass_tensor(system.inertia)
    scale = float(np.max(np.abs(I)))
    off = I - np.diag(np.diag(I))
    if np.max(np.abs(off)) > 1e-12 * scale:
        i, j = np.unravel_index(int(np.argmax(np.abs(off))), off.shape)
        raise ValueError("not the Lagrange case: the mass tensor must be diagonal, I = diag(I1, ..., I1, In);"
                         f" got I[{i + 1},{j + 1}] = {I[i, j]:.6g}")
    diag = np.diag(I)
    dev = np.abs(diag[: n - 1] - diag[0])
    if np.max(dev) > 1e-10 * scale:
        i = int(np.argmax(dev > 1e-10 * scale))  # the first that differs
        raise ValueError("not the Lagrange case: the mass tensor must be diag(I1, ..., I1, In) (symmetric "
                         f"about e_n); got I_{i + 1} = {diag[i]:.10g} != I_1 = {diag[0]:.10g}")
    D = system.constraints
    fk = suslov_distribution(n).basis
    if D.dim != n - 1 or not np.allclose(D.basis.T @ D.basis, fk.T @ fk, rtol=0, atol=1e-10):
        raise ValueError(f"not the Lagrange case: the constraints must be the Fedorov–Kozlov ones "
                         f"(Omega_ij = 0 for i, j <= n-1, ls.suslov_distribution({n})); got a D of dimension "
                         f"{D.dim} that differs from it")
    if system.gyroscopic != 0.0:
        raise ValueError(f"not the Lagrange case: there is a gyroscopic term (eps = {system.gyroscopic:g})")
    pot = system.potential
    if pot.is_zero:
        Bn = 0.0
    elif pot.kind == "linear":
        b = np.asarray(pot.B, dtype=float)
        bscale = float(np.max(np.abs(b)))
        if np.max(np.abs(b[: n - 1])) > 1e-12 * bscale:
            i = int(np.argmax(np.abs(b[: n - 1]) > 1e-12 * bscale))
            raise ValueError("not the Lagrange case: the potential must be V = Bn Gamma_n (centre of mass "
                             f"on the symmetry axis e_n); got B_{i + 1} = {b[i]:.6g} != 0")
        Bn = float(b[-1])
    else:
        raise ValueError("not the Lagrange case: the potential must be V = Bn Gamma_n (a LinearPotential "
                         f"with B = (0, ..., 0, Bn)), got a {pot.kind} potential {pot!r}")
    return LagrangeParameters(n=n, I1=float(diag[0]), In=float(diag[-1]), Bn=Bn)


# ====================================================================== the consistency harness
@dataclass(frozen=True, eq=False)
class ReductionCheck:
    """The result of :func:`check_lagrange_reduction`: the Suslov image against the pendulum.

    Attributes
    ----------
    parameters : LagrangeParameters
    t : ndarray, shape (N,)
    q_suslov, v_suslov : ndarray, shape (N, ..., n)
        ``to_spherical_pendulum(g, Ω)`` along the Suslov solution (with reconstruction).
    q_pendulum, v_pendulum : ndarray, shape (N, ..., n)
        The pendulum integrated independently from the mapped initial point.
    energy_suslov, energy_pendulum : ndarray, shape (N, ...)
        ``E(Ω, Γ)`` along the Suslov solution; ``H(q, v)`` along the pendulum solution.
    gamma : ndarray, shape (..., n)
        The vertical in space ``g0 Γ0``.
    max_dq, max_dv : float
        ``max |q_suslov − q_pendulum|``, ``max |v_suslov − v_pendulum|`` over times and the batch.
    energy_mismatch : float
        ``max |E(Ω, Γ) − H(q_suslov, v_suslov)|``: the energy identity of the reduction (rounding).
    energy_drift_suslov, energy_drift_pendulum : float
        ``max |E(t) − E(t0)|`` of each integration (the exact flows conserve both).
    max_phi : float
        ``max |Φ(Ω)|`` (the so(n−1) momentum map, 0 on Suslov states) along the Suslov solution.
    in_plane_defect : float
        Largest distance of ``q(t)`` (both images) from the invariant space ``span{γ, q0, v0}``
        (of dimension <= 3; for n = 3 it is generically all of R³ and the defect is 0).
    stats : dict
        ``{"suslov": ..., "pendulum": ...}``, the integrators' statistics.
    """

    parameters: LagrangeParameters
    t: np.ndarray
    q_suslov: np.ndarray
    v_suslov: np.ndarray
    q_pendulum: np.ndarray
    v_pendulum: np.ndarray
    energy_suslov: np.ndarray
    energy_pendulum: np.ndarray
    gamma: np.ndarray
    max_dq: float
    max_dv: float
    energy_mismatch: float
    energy_drift_suslov: float
    energy_drift_pendulum: float
    max_phi: float
    in_plane_defect: float
    stats: dict = field(default_factory=dict, repr=False)

    def ok(self, tol: float = 1e-8) -> bool:
        """True iff every defect (distances, energy mismatch and drifts, |Φ|, plane) is <= ``tol``."""
        vals = (self.max_dq, self.max_dv, self.energy_mismatch, self.energy_drift_suslov,
                self.energy_drift_pendulum, self.max_phi, self.in_plane_defect)
        return bool(all(np.isfinite(v) and v <= tol for v in vals))

    def __str__(self) -> str:
        p = self.parameters
        batch = self.q_suslov.shape[1:-1]
        lines = [
            f"Lagrange reduction check: SO({p.n}) -> S^{p.n - 1}, I1 = {p.I1:g}, In = {p.In:g}, "
            f"Bn = {p.Bn:g} (pendulum mass m = {p.m:g})",
            f"  times: {self.t.size} in [{self.t[0]:g}, {self.t[-1]:g}]"
            + (f", batch {batch}" if batch else ""),
            f"  max |q_suslov - q_pendulum|        {self.max_dq:.3e}",
            f"  max |v_suslov - v_pendulum|        {self.max_dv:.3e}",
            f"  max |E_suslov - H(q_s, v_s)|       {self.energy_mismatch:.3e}   (the energy identity)",
            f"  energy drift: Suslov {self.energy_drift_suslov:.3e}, "
            f"pendulum {self.energy_drift_pendulum:.3e}",
            f"  max |Phi| (so(n-1) momentum map)   {self.max_phi:.3e}",
            f"  distance from span(gamma, q0, v0)  {self.in_plane_defect:.3e}",
        ]
        for name in ("suslov", "pendulum"):
            s = self.stats.get(name, {})
            if s:
                lines.append(f"  {name}: {s.get('method')} ({s.get('chart')}), {s.get('steps')} steps, "
                             f"{s.get('rejected')} rejected, {s.get('nfev')} field evaluations, "
                             f"{s.get('wall_time', 0.0):.3f} s")
        return "\n".join(lines)


def _plane_distance(q: np.ndarray, span: np.ndarray) -> float:
    """Largest distance of ``q`` (N, ..., n) from the column span of ``span`` (..., n, 3)."""
    U, s, _ = np.linalg.svd(span, full_matrices=False)
    keep = s > 1e-10 * np.maximum(s[..., :1], np.finfo(float).tiny)
    U = U * keep[..., None, :]
    coeff = np.einsum("...ji,t...j->t...i", U, q)
    proj = np.einsum("...ij,t...j->t...i", U, coeff)
    return float(np.max(np.linalg.norm(q - proj, axis=-1), initial=0.0))


def check_lagrange_reduction(system_or_case, Omega0, Gamma0, t_span, g0=None, method: str = "rkmk853",
                             rtol: float = 1e-12, atol: float = 1e-12, t_eval=None,
                             pendulum_method: str | None = None, *, h: float | None = None,
                             chart: str = "exp", backend: str = "auto") -> ReductionCheck:
    """Integrate a Lagrange scene and the spherical pendulum independently, and compare them.

    1. Check that the scene is the Lagrange case (:func:`lagrange_parameters`).
    2. Integrate the Suslov system with reconstruction from ``(Ω0, Γ0, g0)`` and map it,
       ``(q_s, v_s) = to_spherical_pendulum(g, Ω)``.
    3. Integrate :class:`SphericalPendulum` ``(n, I1 + In, Bn, γ = g0 Γ0)`` from
       ``(q0, v0) = (g0 e_n, g0 Ω0 e_n)`` at the Suslov output times.
    4. Report the distances, the energy identity and drifts, ``max |Φ|`` and the distance of
       ``q(t)`` from ``span{γ, q0, v0}``.

    Parameters
    ----------
    system_or_case : SuslovSystem or Case
        A Lagrange scene (``ls.cases.lagrange(n, I1, In, Bn)``, ``ls.cases.lagrange3(...)``, or an
        equivalent SuslovSystem).
    Omega0 : array_like, shape (..., n, n) or (..., d)
        Initial angular velocities in D.
    Gamma0 : array_like, shape (..., n) or None
        Initial verticals in the body frame (unit); None only when ``Bn = 0`` (then ``Γ0 = e_n``).
    t_span : (t0, t1)
    g0 : array_like, shape (..., n, n), optional
        Initial attitudes (default the identity).
    method : str
        Method of the Suslov integration (``liesuslov.METHODS``).
    rtol, atol : float
        Tolerances of adaptive methods (both integrations).
    t_eval : array_like, optional
        Output times (default: the Suslov integration's steps; the pendulum is evaluated there).
    pendulum_method : str, optional
        Method of the pendulum integration (default: ``method``).
    h : float, optional
        Step of fixed-step methods (both integrations).
    chart : {"exp", "cayley"}
        Chart of both integrations.
    backend : {"auto", "numpy", "numba"}
        Backend of both integrations (see :func:`liesuslov.integrate`).

    Returns
    -------
    ReductionCheck
        Frozen; ``print(result)`` gives a report, ``result.ok(tol)`` a verdict.

    Raises
    ------
    ValueError
        A scene that is not the Lagrange case (saying what differs), invalid initial data.
    RuntimeError
        An integration that failed (its message is included).

    Examples
    --------
    >>> import numpy as np, liesuslov as ls
    >>> case = ls.cases.lagrange(4, I1=1.0, In=2.0, Bn=1.5)
    >>> Om = ls.so(4).hat([0, 0, 0.3, 0, -0.2, 0.5])  # Omega_14, Omega_24, Omega_34
    >>> G = np.array([0.3, -0.2, 0.4, 0.8]); G /= np.linalg.norm(G)
    >>> r = ls.check_lagrange_reduction(case, Om, G, (0.0, 5.0))
    >>> r.ok(1e-8)
    True
    """
    params = lagrange_parameters(system_or_case)
    system = system_or_case.system if isinstance(system_or_case, Case) else system_or_case
    n = params.n
    x0 = system.coordinates(Omega0, "Omega0")
    D = system.constraints
    if not np.all(D.contains(x0, 1e-9)):
        dist = float(np.max(np.linalg.norm(x0 - D.project(x0), axis=-1)))
        raise ValueError("Omega0 is not in the constraint subspace D (Omega_ij = 0 for i, j <= n-1); "
                         f"distance {dist:.3g}: project it first, D.project(omega) with "
                         "D = system.constraints")
    if Gamma0 is None:
        if params.Bn != 0.0:
            raise ValueError("Gamma0 is required: the potential Bn Gamma_n is not zero")
        Gamma0 = np.eye(n)[-1]
    G0 = _unit(as_float_array(Gamma0, "Gamma0", ndim_min=1, tail=(n,)), "Gamma0")
    if g0 is None:
        gi = np.eye(n)
    else:
        gi = as_float_array(g0, "g0", ndim_min=2, tail=(n, n))
        _check_rotations(gi, "g0")
    try:
        shape = np.broadcast_shapes(x0.shape[:-1], G0.shape[:-1], gi.shape[:-2])
    except ValueError as exc:
        raise ValueError(f"the batch axes of Omega0 {x0.shape[:-1]}, Gamma0 {G0.shape[:-1]} and g0 "
                         f"{gi.shape[:-2]} do not broadcast") from exc
    alg = system.algebra
    gamma = np.einsum("...ij,...j->...i", gi, G0)
    gamma = np.broadcast_to(gamma, shape + (n,))
    q0, v0 = to_spherical_pendulum(np.broadcast_to(gi, shape + (n, n)), alg.hat(x0))
    q0 = np.broadcast_to(q0, shape + (n,))
    v0 = np.broadcast_to(v0, shape + (n,))

    common = {"rtol": rtol, "atol": atol, "chart": chart, "backend": backend}
    if h is not None:
        common["h"] = h
    sus = integrate(system, x0, t_span, Gamma0=G0, g0=gi, reconstruct=True, method=method, t_eval=t_eval,
                    **common)
    if not sus.success:
        raise RuntimeError(f"the Suslov integration failed: {sus.message}")
    qs, vs = to_spherical_pendulum(sus.g, sus.Omega)
    E_s = system.energy(sus.omega, sus.Gamma)
    phi = momentum_map(sus.omega, system.inertia)

    pend = SphericalPendulum(n, params.m, params.Bn, gamma)
    psol = integrate_pendulum(pend, q0, v0, t_span, method=pendulum_method or method, t_eval=sus.t, **common)
    if not psol.success:
        raise RuntimeError(f"the pendulum integration failed: {psol.message}")
    if psol.t.shape != sus.t.shape or np.any(psol.t != sus.t):
        raise RuntimeError("internal error: the pendulum was not evaluated at the Suslov output times")
    H_s = pend.energy(qs, vs)
    E_p = psol.energy
    E0_s = system.energy(x0, G0)  # at t0 (t_eval need not contain it)
    E0_p = pend.energy(q0, v0)

    def mx(a) -> float:
        return float(np.max(np.abs(a), initial=0.0))

    span = np.stack([gamma, q0, v0], axis=-1)
    defect = max(_plane_distance(qs, span), _plane_distance(psol.q, span))
    return ReductionCheck(
        parameters=params, t=sus.t, q_suslov=qs, v_suslov=vs, q_pendulum=psol.q, v_pendulum=psol.v,
        energy_suslov=E_s, energy_pendulum=E_p, gamma=np.array(gamma),
        max_dq=float(np.max(np.linalg.norm(qs - psol.q, axis=-1), initial=0.0)),
        max_dv=float(np.max(np.linalg.norm(vs - psol.v, axis=-1), initial=0.0)),
        energy_mismatch=mx(E_s - H_s), energy_drift_suslov=mx(E_s - E0_s),
        energy_drift_pendulum=mx(E_p - E0_p),
        max_phi=float(np.max(np.linalg.norm(phi, axis=-1), initial=0.0)), in_plane_defect=defect,
        stats={"suslov": dict(sus.stats), "pendulum": dict(psol.stats)})
