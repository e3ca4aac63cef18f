"""Mechanics: potentials, the nonholonomic system, its models and the integrable cases of the paper."""

from .cases import (
           CASES,
           Case,
           CaseEntry,
           family3,
           gyroscopic3,
           kharlamova,
           kharlamova3,
           klebsh_tisserand,
           klebsh_tisserand3,
           lagrange,
           lagrange3,
           suslov3,
           suslov_free,
)
from .models import Model
from .potentials import (
           FamilyPotential,
           GradientCheck,
           LinearPotential,
           Potential,
           QuadraticPotential,
           ZeroPotential,
           check_gradient,
)
from .protocol import ModelProtocol
from .system import FORMS, SuslovSystem

__all__ = ["Potential", "ZeroPotential", "LinearPotential", "QuadraticPotential", "FamilyPotential",
           "GradientCheck", "check_gradient", "SuslovSystem", "FORMS", "Model", "ModelProtocol", "Case",
           "CaseEntry", "CASES",
           "suslov3", "lagrange3", "kharlamova3", "klebsh_tisserand3", "family3", "gyroscopic3",
           "suslov_free", "lagrange", "kharlamova", "klebsh_tisserand"]
