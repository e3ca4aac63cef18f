"""Scene files: :func:`load_scene`, :func:`scene_from_text`, the built-in :data:`DEFAULT_SCENE`."""

from __future__ import annotations

from pathlib import Path

from .build import scene_from_dict
from .core import Scene
from .toml import tomllib

__all__ = ["DEFAULT_SCENE", "load_scene", "scene_from_text", "default_scene"]

#: The built-in scene of ``liesuslov run`` (TOML text): the n = 4 Klebsh–Tisserand body with reconstruction.
DEFAULT_SCENE = '''\
# The built-in scene of `liesuslov run`: the n = 4 Klebsh–Tisserand body, with its attitude on SO(4).
# `liesuslov run --print-default > my_scene.toml` writes this text; edit it, then `liesuslov run my_scene.toml`.
description = "Klebsh–Tisserand case in SO(4): V = 1/2 sum B_i Gamma_i^2, motion on invariant tori"

[case]
name = "klebsh_tisserand"          # `liesuslov cases` lists the named cases
[case.parameters]
I = [1.0, 1.5, 2.0, 0.5]           # diagonal of the mass tensor
B = [4.0, 3.0, 2.5, 1.0]           # B_i > B_n: the trajectories wind on tori

[initial]
xi = [0.3, -0.2, 0.25]             # (Omega_14, Omega_24, Omega_34): the coordinates in D
Gamma = [0.2, -0.4, 0.4, 0.8]      # the vertical in the body frame, a unit vector

[integrate]
t_span = [0.0, 50.0]
method = "rkmk853"                 # adaptive Dormand–Prince 8(5,3) on the group
chart = "exp"
rtol = 1e-10
atol = 1e-12
n_out = 501                        # output times, evenly spaced
reconstruct = true                 # also integrate g in SO(4); then Gamma = g^T gamma
backend = "numpy"                  # "auto" uses the compiled kernel (liesuslov[fast]) when installed: worth it
                                   # for long runs and batches; its first use on a machine compiles it (~30 s, once)

[output]
name = "Klebsh–Tisserand, n = 4"
dir = "liesuslov-out"
figures = true

[check]
tol = 1e-8                         # `liesuslov check`: largest admissible drift and defect
'''

def load_scene(path) -> Scene:
    """Read and validate a scene file.

    Parameters
    ----------
    path : str or Path
        A TOML file (format: the module docstring and ``docs/quickstart.md``).

    Returns
    -------
    Scene

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError, TypeError
        For a file that is not valid TOML or not a valid scene; the message starts with the path and
        names the field.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"scene file not found: {p}")
    if p.is_dir():
        raise IsADirectoryError(f"{p} is a directory, not a scene file")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{p}: not a UTF-8 text file ({exc.reason})") from exc
    return scene_from_text(text, source=str(p), name=p.stem)


def scene_from_text(text: str, source: str = "<scene>", name: str | None = None) -> Scene:
    """Parse TOML text and validate it as a scene (see :func:`scene_from_dict`)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{source}: not valid TOML: {exc}") from exc
    return scene_from_dict(data, source=source, name=name)


def default_scene() -> Scene:
    """The built-in scene of ``liesuslov run`` (:data:`DEFAULT_SCENE`)."""
    return scene_from_text(DEFAULT_SCENE, source="<default scene>", name="default")
