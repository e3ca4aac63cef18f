"""liesuslov's build backend: setuptools' (``setuptools.build_meta``), and the compiled kernel compiled at install.

The compiled kernel (numba, the ``fast`` extra) is compiled on a machine's first compiled call: 20–90 s on a
2-core machine, one family of kinds at a time (:mod:`liesuslov.integrators.kernel.warm`). Building a wheel or an
editable install compiles every family first, in parallel processes, into
``liesuslov/integrators/kernel/_precompiled`` (shipped in the wheel, or read in place by an editable install),
which the kernel reads before numba's own cache (:class:`liesuslov.integrators.kernel.common._KernelCacheFile`):
the first compiled call then loads it (< 1 s). pip builds a local project on the machine it installs it on,
with the numba release the install takes, so the compiled code fits; where it does not (another CPU, another
numba release, changed kernel sources), the kernel finds nothing there and compiles as before.

The build environment gets numba and the package's own dependencies for this (read from ``pyproject.toml``:
one source). It is on by default; ``LIESUSLOV_PRECOMPILE=0`` in the environment or ``pip install
--config-settings precompile=false`` skips it (a build without numba, or without the minute it takes). A
failure of the step (no numba for this platform, a compiler error) is reported on standard error and the build
goes on without it. An sdist never holds compiled code (``MANIFEST.in``).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

from setuptools import build_meta as _setuptools

if sys.version_info >= (3, 11):
    import tomllib
else:  # (the static build requirements carry tomli there)
    import tomli as tomllib

__all__ = ["build_editable", "build_sdist", "build_wheel", "get_requires_for_build_editable",
           "get_requires_for_build_sdist", "get_requires_for_build_wheel", "prepare_metadata_for_build_editable",
           "prepare_metadata_for_build_wheel"]

#: The extra whose packages the compilation needs besides the dependencies.
_EXTRA = "fast"
#: Where the kernel's compiled code goes (:data:`liesuslov.integrators.kernel.common.PRECOMPILED_DIR`).
_PRECOMPILED = Path("liesuslov", "integrators", "kernel", "_precompiled")
#: Seconds the whole step may take (every family, on a loaded machine; ~1 minute on a quiet 2-core one).
_TIMEOUT = 1800.0

build_sdist = _setuptools.build_sdist
get_requires_for_build_sdist = _setuptools.get_requires_for_build_sdist
prepare_metadata_for_build_wheel = _setuptools.prepare_metadata_for_build_wheel
prepare_metadata_for_build_editable = _setuptools.prepare_metadata_for_build_editable


def _wanted(config_settings: dict | None) -> bool:
    """Whether to compile the kernel: ``precompile`` of the config settings, else ``LIESUSLOV_PRECOMPILE``, else yes."""
    value = (config_settings or {}).get("precompile", os.environ.get("LIESUSLOV_PRECOMPILE", "1"))
    value = str(value).strip().lower()
    if value in ("1", "true", "yes", "on"):
        return True
    if value in ("0", "false", "no", "off"):
        return False
    raise ValueError(f"precompile (LIESUSLOV_PRECOMPILE) must be true or false, got {value!r}")


def _requirements() -> list[str]:
    """The package's dependencies and its ``fast`` extra, as ``pyproject.toml`` lists them."""
    with open("pyproject.toml", "rb") as f:
        project = tomllib.load(f)["project"]
    return [*project["dependencies"], *project["optional-dependencies"][_EXTRA]]


def get_requires_for_build_wheel(config_settings=None):
    extra = _requirements() if _wanted(config_settings) else []
    return [*_setuptools.get_requires_for_build_wheel(config_settings), *extra]


def get_requires_for_build_editable(config_settings=None):
    extra = _requirements() if _wanted(config_settings) else []
    return [*_setuptools.get_requires_for_build_editable(config_settings), *extra]


def _precompile(config_settings) -> None:
    """Compile every family of the kernel into :data:`_PRECOMPILED` (emptied first: no stale files), in child
    processes of this build environment's interpreter that import the package from this source tree."""
    if not _wanted(config_settings):
        return
    target = Path.cwd() / _PRECOMPILED
    shutil.rmtree(target, ignore_errors=True)
    root = str(Path.cwd())
    with tempfile.TemporaryDirectory(prefix="liesuslov-build-numba-") as scratch:
        # numba's own cache (functions outside the kernel) goes to scratch, not into the source tree
        # (LIESUSLOV_PRECOMPILED: liesuslov.integrators.kernel.common.PRECOMPILED_ENV, not importable here)
        env = {**os.environ, "LIESUSLOV_PRECOMPILED": "write", "NUMBA_CACHE_DIR": scratch,
               "PYTHONPATH": os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH", "")) if p)}
        print("liesuslov: compiling the kernel (numba; LIESUSLOV_PRECOMPILE=0 skips this) ...", file=sys.stderr)
        try:
            res = _run([sys.executable, "-m", "liesuslov.integrators.kernel.warm"], cwd=root, env=env)
        except (OSError, subprocess.TimeoutExpired) as exc:
            res, why = None, str(exc)
        else:
            why = (res.stderr.strip().splitlines() or [f"exit status {res.returncode}"])[-1]
    if res is not None and res.returncode == 0:
        print(f"liesuslov: kernel compiled\n{res.stdout.strip()}", file=sys.stderr)
        return
    shutil.rmtree(target, ignore_errors=True)
    print(f"liesuslov: the kernel was not compiled at install ({why}); its first call will compile it",
          file=sys.stderr)


def _run(cmd: list[str], cwd: str, env: dict) -> subprocess.CompletedProcess:
    """``cmd`` to its end, or killed with every process it started (the compilers of :mod:`.warm`) after
    :data:`_TIMEOUT` seconds (TimeoutExpired)."""
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # (its own process group: killed as a whole)
    try:
        out, err = proc.communicate(timeout=_TIMEOUT)
    except subprocess.TimeoutExpired:
        if hasattr(os, "killpg"):
            os.killpg(proc.pid, signal.SIGKILL)
        else:
            proc.kill()
        proc.communicate()
        raise
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    _precompile(config_settings)
    return _setuptools.build_wheel(wheel_directory, config_settings, metadata_directory)


def build_editable(wheel_directory, config_settings=None, metadata_directory=None):
    _precompile(config_settings)
    return _setuptools.build_editable(wheel_directory, config_settings, metadata_directory)
