"""The spherical pendulum as a system the library integrates: :class:`SphericalPendulum`, its model
(:class:`PendulumModel`, an implementation of :class:`~liesuslov.mechanics.ModelProtocol`),
:func:`integrate_pendulum` and :class:`PendulumSolution`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import as_float_array, check_positive, check_real
from ..algebra import Subspace, body_vector, so, space_vector
from ..integrators import integrate
from ._checks import dim_n, tangent, unit
from .maps import axis_rotation, pendulum_energy, pendulum_momentum

__all__ = ["SphericalPendulum", "PendulumModel", "PendulumSolution", "integrate_pendulum"]


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
        self.n = dim_n(n)
        self.m = check_positive(m, "m")
        self.B = check_real(B, "B")
        if gamma is None:
            gam = np.eye(self.n)[-1]
        else:
            gam = unit(as_float_array(gamma, "gamma", ndim_min=1, tail=(self.n,)), "gamma")
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
        """The model that :func:`liesuslov.integrate` runs (an implementation of ``ModelProtocol``).

        A model has one field direction for every trajectory (the integrator advances each trajectory
        on its own, so a model cannot carry per-trajectory parameters): with a batched ``gamma`` this
        is a ValueError, and :func:`integrate_pendulum` instead integrates each trajectory in a frame
        where its field is ``e_n``. ``batch_shape`` is accepted for compatibility and not used.
        """
        if self.gamma.ndim > 1:
            raise ValueError(f"gamma has batch axes {self.gamma.shape[:-1]}: a model has one field direction; "
                             "use integrate_pendulum (it rotates each trajectory so that its field is e_n)")
        return PendulumModel(self.n, self.B / self.m, self.gamma, system=self)

    def integrate(self, q0, v0, t_span, **integrate_kwargs) -> PendulumSolution:
        """Shorthand for :func:`integrate_pendulum` ``(self, q0, v0, t_span, **integrate_kwargs)``."""
        return integrate_pendulum(self, q0, v0, t_span, **integrate_kwargs)


class PendulumModel:
    """The pendulum as a model: an implementation of :class:`~liesuslov.mechanics.ModelProtocol`.

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
    system : SphericalPendulum, optional
        The pendulum this model runs (the protocol's back-reference; None for a bare model).

    Notes
    -----
    The maps are methods over precomputed index arrays (no closures), so the model pickles.
    """

    form = "spherical-pendulum"
    has_gamma = True
    fedorov_kozlov = False

    def __init__(self, n: int, c: float, gamma: np.ndarray, system: SphericalPendulum | None = None) -> None:
        self.n = int(n)
        self.system = system
        self.algebra = so(self.n)
        d = self.algebra.dim
        self.k = d
        self.state_dim = d + self.n
        self.subspace = Subspace(self.algebra, np.eye(d))
        self.reduced_inertia = np.eye(d)
        self.path = "W' = -(B/m) gamma ∧ q, q' = W q"
        self.c = float(c)
        self.gamma = np.ascontiguousarray(gamma, dtype=float)
        self._r, self._c = np.triu_indices(self.n, 1)
        self._gr, self._gc = self.gamma[..., self._r], self.gamma[..., self._c]

    # ------------------------------------------------------------------ the protocol
    def xi_dot(self, xi: np.ndarray, q: np.ndarray) -> np.ndarray:
        """``W' = −(B/m) vee(γ ∧ q)``: (..., d), (..., n) -> (..., d)."""
        return -self.c * (self._gr * q[..., self._c] - q[..., self._r] * self._gc)

    def omega_matrix(self, xi: np.ndarray) -> np.ndarray:
        """``Ω = −hat(xi) = −W``: (..., d) -> (..., n, n)."""
        X = np.zeros(xi.shape[:-1] + (self.n, self.n))
        X[..., self._r, self._c] = -xi
        X[..., self._c, self._r] = xi
        return X

    def omega_coords(self, xi: np.ndarray) -> np.ndarray:
        """``Ω`` in so(n) coordinates, ``−xi``: (..., d) -> (..., d)."""
        return -np.asarray(xi, dtype=float)

    def xi_from_coords(self, x: np.ndarray) -> np.ndarray:
        """``xi = −x``: (..., d) -> (..., d)."""
        return -np.asarray(x, dtype=float)

    def Gamma_dot(self, xi: np.ndarray, q: np.ndarray) -> np.ndarray:
        """``q' = W q = −Ω q`` (reference; the integrator moves q by the group): (..., n)."""
        return -(self.omega_matrix(xi) @ q[..., :, None])[..., 0]

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
    status : int or ndarray of int, shape (...)
        Per trajectory as the integrator reports it: 0 success, −1 failure (``message`` says why; the
        arrays hold what was computed).
    message : str
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    energy: np.ndarray
    W: np.ndarray
    m: float = 1.0
    stats: dict = field(default_factory=dict)
    status: Any = 0
    message: str = ""

    @property
    def success(self) -> bool:
        """True iff every trajectory reached the end of ``t_span`` (``status >= 0`` everywhere)."""
        return bool(np.all(np.asarray(self.status) >= 0))

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
    q = unit(as_float_array(q0, "q0", ndim_min=1, tail=(n,)), "q0")
    v = as_float_array(v0, "v0", ndim_min=1, tail=(n,))
    try:
        shape = np.broadcast_shapes(q.shape[:-1], v.shape[:-1], pendulum.gamma.shape[:-1])
    except ValueError as exc:
        raise ValueError(f"the batch axes of q0 {q.shape[:-1]}, v0 {v.shape[:-1]} and gamma "
                         f"{pendulum.gamma.shape[:-1]} do not broadcast") from exc
    q = np.broadcast_to(q, shape + (n,))
    v = tangent(q, np.broadcast_to(v, shape + (n,)), "q0", "v0")
    R = None
    if pendulum.gamma.ndim > 1:
        # One field per trajectory: the equations are rotation-equivariant, so trajectory b runs in the
        # frame R_b with R_b gamma_b = e_n, all of them through one model with the field e_n.
        R = np.swapaxes(axis_rotation(np.broadcast_to(pendulum.gamma, shape + (n,))), -1, -2)
        q, v = space_vector(R, q), space_vector(R, v)
        model = PendulumModel(n, pendulum.B / pendulum.m, np.eye(n)[-1], system=pendulum)
    else:
        model = pendulum.model()
    P = v[..., :, None] * q[..., None, :]
    Omega0 = np.swapaxes(P, -1, -2) - P  # Omega = -W = q ∧ v, exactly skew
    kwargs = {"method": "rkmk45", **integrate_kwargs}
    sol = integrate(model, Omega0, t_span, Gamma0=q, **kwargs)
    Q = sol.Gamma
    Wm = -sol.Omega  # W = -Omega
    if R is not None:  # back to the space frame: q = R^T q', W = R^T W' R
        Q = body_vector(R, Q)
        Wm = np.swapaxes(R, -1, -2) @ Wm @ R
    Wc = pendulum.algebra.vee(Wm)
    V = np.einsum("...ij,...j->...i", Wm, Q)
    return PendulumSolution(t=sol.t, q=Q, v=V, energy=pendulum.energy(Q, V), W=Wc, m=pendulum.m,
                            stats=dict(sol.stats), status=sol.status, message=sol.message)
