"""liesuslov: nonholonomic rigid-body dynamics on Lie groups with structure-exact integrators.

The public names are listed in ``docs/api.md``; the conventions in ``docs/concepts.md``.
"""

from .algebra import (Inertia, LieAlgebra, SpecialOrthogonalAlgebra, Subspace, hat3, is_symmetric_pair,
                      pairing, se, so, suslov_distribution, vee3, wedge)

__version__ = "0.1.0"

__all__ = ["LieAlgebra", "se", "so", "SpecialOrthogonalAlgebra", "wedge", "pairing", "hat3", "vee3",
           "Subspace", "is_symmetric_pair", "suslov_distribution", "Inertia", "__version__"]
