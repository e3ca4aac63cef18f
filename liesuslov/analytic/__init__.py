"""Analytic references: closed forms of the integrable cases, used to verify the integrators.

Depends on numpy and scipy only. Every reference is batched over its initial data (leading axes)
and over the evaluation times; state arrays put the time axes first, then the batch axes.

* :class:`SphericalPendulumMotion` — the ``SO(n-1)`` reduction of the n-D Lagrange case, by Jacobi
  elliptic functions (height, period, precession, full state in any dimension).
* :class:`KharlamovaMotion` and the coordinates (4.6), the quartic ``P4``, the integrals ``F_ij``.
* :class:`KlebshTisserandMotion` — the motion on the invariant tori in ``tau`` and in ``t``; the
  integrals ``F_i``, the energy in terms of them, the two-tori condition, angles and frequencies.
* Suslov with ``V = 0``: asymptotic points ``w_+-`` (n = 3 and n-D), which one is the limit, the
  explicit 3-D solution :class:`Suslov3Free`.
* First integrals of the 3-D cases (:mod:`.integrals3d`), including the gyroscopic ones.

The paper's misprints found while deriving these are listed in ``docs/errata.md``.
"""

from .euler_top import EulerTop
from .integrals3d import (
                          family3_integral,
                          gyroscopic3_free_integrals,
                          gyroscopic3_linear_integral,
                          gyroscopic3_quadratic_integral,
                          kharlamova3_integral,
                          klebsh_tisserand3_integral,
                          lagrange3_integral,
)
from .kharlamova import (
                          KharlamovaMotion,
                          kharlamova_coordinates,
                          kharlamova_from_coordinates,
                          kharlamova_integrals,
                          kharlamova_partial_energies,
                          kharlamova_quartic,
)
from .klebsh_tisserand import (
                          KlebshTisserandMotion,
                          klebsh_tisserand_angles,
                          klebsh_tisserand_energy,
                          klebsh_tisserand_frequencies,
                          klebsh_tisserand_integrals,
                          klebsh_tisserand_two_tori,
)
from .pendulum import SphericalPendulumMotion
from .suslov import (
                          Suslov3Free,
                          suslov3_asymptotic_points,
                          suslov3_energy,
                          suslov_asymptotic_points,
                          suslov_energy,
                          suslov_limits,
                          suslov_lyapunov,
                          suslov_reduced_field,
)

__all__ = [
    "SphericalPendulumMotion", "EulerTop",
    "KharlamovaMotion", "kharlamova_coordinates", "kharlamova_from_coordinates", "kharlamova_integrals",
    "kharlamova_partial_energies", "kharlamova_quartic",
    "KlebshTisserandMotion", "klebsh_tisserand_angles", "klebsh_tisserand_energy",
    "klebsh_tisserand_frequencies", "klebsh_tisserand_integrals", "klebsh_tisserand_two_tori",
    "Suslov3Free", "suslov3_asymptotic_points", "suslov3_energy", "suslov_asymptotic_points",
    "suslov_energy", "suslov_limits", "suslov_lyapunov", "suslov_reduced_field",
    "family3_integral", "gyroscopic3_free_integrals", "gyroscopic3_linear_integral",
    "gyroscopic3_quadratic_integral", "kharlamova3_integral", "klebsh_tisserand3_integral",
    "lagrange3_integral",
]


def __getattr__(name: str):
    # The closed form was called SphericalPendulum, the name of the pendulum *system* of
    # liesuslov.reduction (ls.SphericalPendulum): one name, one meaning, so it is SphericalPendulumMotion
    # (like KharlamovaMotion); the old name keeps working with a warning.
    if name == "SphericalPendulum":
        import warnings

        warnings.warn("liesuslov.analytic.SphericalPendulum is now SphericalPendulumMotion (the closed-form "
                      "motion); ls.SphericalPendulum is the pendulum system of liesuslov.reduction",
                      DeprecationWarning, stacklevel=2)
        return SphericalPendulumMotion
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
