"""Scene files: one experiment (body, constraints, potential, initial data, numerics, output) in TOML.

A scene file is read with :func:`load_scene` (stdlib ``tomllib``; ``tomli`` on Python 3.10) and
validated completely before anything is integrated: every mistake is a ``ValueError`` (a wrong value
or shape) or ``TypeError`` (a wrong type) whose message starts with the file and the field path,
e.g. ``scene.toml: [potential].B must be a list of 4 numbers, got a list of 3 numbers``, and says
what is expected. Unknown keys are rejected with the list of valid ones, so a typo never passes
silently. The format is documented field by field in ``docs/quickstart.md``; in short::

    description = "free text"        # optional
    gyroscopic = 0.0                 # optional, so(3) only: the force eps * Gamma x w

    [body]                           # either [body] (+ [constraints], [potential]) ...
    algebra = "so"                   # "so" (with n), "se2", "se3", or "custom" (structure_constants)
    n = 4
    mass_tensor = [1.0, 2.0, 3.0, 4.0]   # or its n×n matrix; or principal_moments (n = 3); or inertia

    [constraints]                    # default on so(n): Fedorov–Kozlov; or annihilator / span / "none"
    annihilator = [[0, 0, 1]]

    [potential]
    kind = "quadratic"               # "linear" or "quadratic"
    B = [4.0, 3.0, 2.0, 1.0]

    [case]                           # ... or a named case of ls.CASES with its parameters
    name = "klebsh_tisserand"
    [case.parameters]
    I = [1.0, 2.0, 3.0, 4.0]
    B = [4.0, 3.0, 2.0, 1.0]

    [initial]
    xi = [0.3, -0.2, 0.25]           # or omega (algebra coordinates), Omega (matrix), w (so(3))
    Gamma = [0.2, -0.4, 0.4, 0.8]    # unit vector (within 1e-8), needed when V != 0
    # g = [[...]]                    # initial attitude, with reconstruct = true

    [integrate]
    t_span = [0.0, 50.0]
    method = "rkmk853"               # a key of ls.METHODS
    chart = "exp"                    # or "cayley"
    rtol = 1e-10                     # atol, h (fixed-step methods), form
    n_out = 501                      # or t_eval = [...] or t_eval = "steps"
    reconstruct = true
    progress = false
    backend = "auto"                 # "numpy" or "numba" (the compiled kernel, liesuslov[fast])

    [output]
    name = "my scene"
    dir = "liesuslov-out"
    figures = true

    [check]
    tol = 1e-8                       # the tolerance of ``liesuslov check``

:data:`DEFAULT_SCENE` is the built-in scene of ``liesuslov run`` (``liesuslov run --print-default``).

The package: :mod:`.core` (the :class:`Scene`), :mod:`.files` (reading files, the default scene),
:mod:`.build` (validating and building), :mod:`.schema` (reading tables field by field), :mod:`.toml`
(TOML in and out).
"""

from .build import scene_from_dict
from .core import Scene
from .files import DEFAULT_SCENE, default_scene, load_scene, scene_from_text
from .schema import _fmt_list  # noqa: F401 - used by the command line
from .toml import to_toml

__all__ = ["Scene", "load_scene", "scene_from_dict", "scene_from_text", "default_scene", "DEFAULT_SCENE",
           "to_toml"]
