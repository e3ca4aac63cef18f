"""liesuslov: nonholonomic rigid-body dynamics on Lie groups with structure-exact integrators.

Layers (lower never import higher): :mod:`.algebra` → :mod:`.groups` → :mod:`.mechanics` →
:mod:`.integrators` → :mod:`.reduction`, :mod:`.analytic` → :mod:`.bench`, :mod:`.cli`.
The conventions are in ``docs/concepts.md``; the public names in ``docs/api.md``.
"""

from .algebra import (
                      Inertia,
                      LieAlgebra,
                      SpecialOrthogonalAlgebra,
                      Subspace,
                      hat3,
                      is_symmetric_pair,
                      pairing,
                      se,
                      so,
                      suslov_distribution,
                      vee3,
                      wedge,
)
from .integrators import METHODS, Solution, integrate
from .mechanics import (
                      CASES,
                      FORMS,
                      Case,
                      CaseEntry,
                      FamilyPotential,
                      GradientCheck,
                      LinearPotential,
                      Model,
                      ModelProtocol,
                      Potential,
                      QuadraticPotential,
                      SuslovSystem,
                      ZeroPotential,
                      cases,
                      check_gradient,
)
from .reduction import (
                      LagrangeParameters,
                      PendulumSolution,
                      ReductionCheck,
                      SphericalPendulum,
                      check_lagrange_reduction,
                      integrate_pendulum,
                      lagrange_parameters,
                      lift,
                      momentum_map,
                      pendulum_energy,
                      pendulum_momentum,
                      to_spherical_pendulum,
)
from .scene import Scene, load_scene

__version__ = "0.1.0"

# The closed forms (scipy.special), geomstats interop, research tools and ensembles load on first use:
# ``import liesuslov`` stays light. A value None means the name is a submodule.
_LAZY = {"analytic": None, "interop": None, "poincare_section": ".research", "reconstruction_phase": ".research",
         "lyapunov_exponent": ".research", "ReconstructionPhase": ".research", "ensemble": ".ensembles",
         "open_ensemble": ".ensembles",
         "Ensemble": ".ensembles", "EventRecord": ".integrators"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        if _LAZY[name] is None:  # a submodule
            return importlib.import_module(f".{name}", __name__)
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    """The module's names with the lazy ones (tab completion lists ``ls.ensemble`` before its first use)."""
    return sorted({*globals(), *_LAZY})

__all__ = ["LieAlgebra", "se", "so", "SpecialOrthogonalAlgebra", "wedge", "pairing", "hat3", "vee3",
           "Subspace", "is_symmetric_pair", "suslov_distribution", "Inertia",
           "Potential", "LinearPotential", "QuadraticPotential", "FamilyPotential", "ZeroPotential",
           "check_gradient", "GradientCheck", "SuslovSystem", "Model", "ModelProtocol", "FORMS", "Case", "CaseEntry",
           "CASES",
           "cases", "integrate", "METHODS", "Solution", "interop", "analytic",
           "to_spherical_pendulum", "pendulum_energy", "pendulum_momentum", "momentum_map", "lift",
           "SphericalPendulum", "integrate_pendulum", "PendulumSolution", "LagrangeParameters",
           "lagrange_parameters", "ReductionCheck", "check_lagrange_reduction", "Scene", "load_scene", "__version__",
           "poincare_section", "reconstruction_phase", "lyapunov_exponent", "ReconstructionPhase", "ensemble",
           "open_ensemble", "Ensemble", "EventRecord"]
