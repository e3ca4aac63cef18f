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

The package reads as the data flow: :mod:`.maps` (the reduction and lift maps, Φ), :mod:`.pendulum`
(the pendulum as an integrable system and its model), :mod:`.lagrange` (recognising the case),
:mod:`.check` (the consistency harness).
"""

from .check import ReductionCheck, check_lagrange_reduction
from .lagrange import LagrangeParameters, lagrange_parameters
from .maps import lift, momentum_map, pendulum_energy, pendulum_momentum, to_spherical_pendulum
from .pendulum import PendulumModel, PendulumSolution, SphericalPendulum, integrate_pendulum

__all__ = ["to_spherical_pendulum", "pendulum_energy", "pendulum_momentum", "momentum_map",
           "SphericalPendulum", "PendulumModel", "PendulumSolution", "integrate_pendulum", "lift",
           "LagrangeParameters", "lagrange_parameters", "ReductionCheck", "check_lagrange_reduction"]
