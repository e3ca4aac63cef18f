"""The consistency harness: a Lagrange scene integrated against the spherical pendulum,
:func:`check_lagrange_reduction` and its report :class:`ReductionCheck`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validation import as_float_array, check_rotations
from ..algebra import space_vector
from ..integrators import integrate
from ..mechanics import Case
from ._checks import ORTHO_TOL, unit
from .lagrange import LagrangeParameters, lagrange_parameters
from .maps import momentum_map, to_spherical_pendulum
from .pendulum import SphericalPendulum, integrate_pendulum

__all__ = ["ReductionCheck", "check_lagrange_reduction"]


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
        dist = float(np.max(D.distance(x0)))
        raise ValueError("Omega0 is not in the constraint subspace D (Omega_ij = 0 for i, j <= n-1); "
                         f"distance {dist:.3g}: project it first, D.project(omega) with "
                         "D = system.constraints")
    if Gamma0 is None:
        if params.Bn != 0.0:
            raise ValueError("Gamma0 is required: the potential Bn Gamma_n is not zero")
        Gamma0 = np.eye(n)[-1]
    G0 = unit(as_float_array(Gamma0, "Gamma0", ndim_min=1, tail=(n,)), "Gamma0")
    if g0 is None:
        gi = np.eye(n)
    else:
        gi = as_float_array(g0, "g0", ndim_min=2, tail=(n, n))
        check_rotations(gi, "g0", tol=ORTHO_TOL)
    try:
        shape = np.broadcast_shapes(x0.shape[:-1], G0.shape[:-1], gi.shape[:-2])
    except ValueError as exc:
        raise ValueError(f"the batch axes of Omega0 {x0.shape[:-1]}, Gamma0 {G0.shape[:-1]} and g0 "
                         f"{gi.shape[:-2]} do not broadcast") from exc
    alg = system.algebra
    gamma = space_vector(gi, G0)  # the vertical in space
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
