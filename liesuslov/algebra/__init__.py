"""The Lie-algebra layer: algebras, subspaces (constraint distributions), inertia operators."""

from .elements import body_vector, omega_coordinates, space_vector
from .inertia import Inertia
from .lie import LieAlgebra, se
from .so import SpecialOrthogonalAlgebra, hat3, pairing, so, vee3, wedge
from .subspace import Subspace, is_symmetric_pair, suslov_distribution

__all__ = ["LieAlgebra", "se", "so", "SpecialOrthogonalAlgebra", "wedge", "pairing", "hat3", "vee3",
           "Subspace", "is_symmetric_pair", "suslov_distribution", "Inertia",
           "omega_coordinates", "body_vector", "space_vector"]
