"""Research tools: Poincaré sections, reconstruction phases (period and monodromy), Lyapunov exponents.

What the library's users do with the integrators (``docs/reconstruction.md``): integrability is judged
by sections (curves against a chaotic sea) and by the largest Lyapunov exponent (zero against
positive); the reconstruction studies how the body turns while its reduced motion ``(Omega, Gamma)``
is periodic (the monodromy ``R = g(t0)^{-1} g(t0 + T)``, Montgomery's phase for the free body).

Every tool takes a batch of initial data like :func:`liesuslov.integrate` and its options; without
options they use ``method="rkmk853", rtol=1e-10, atol=1e-12``.
"""

from ._runner import DEFAULT_OPTIONS
from .lyapunov import LyapunovResult, lyapunov_exponent
from .phase import ReconstructionPhase, axis_angle, reconstruction_phase, rotation_angles, solid_angle
from .sections import coordinate_plane, gamma_crossing, plane, poincare_section, return_plane

__all__ = ["poincare_section", "reconstruction_phase", "ReconstructionPhase", "lyapunov_exponent",
           "LyapunovResult", "plane", "coordinate_plane", "gamma_crossing", "return_plane",
           "rotation_angles", "axis_angle", "solid_angle", "DEFAULT_OPTIONS"]
