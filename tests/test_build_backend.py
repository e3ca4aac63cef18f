"""The build backend (build_backend/liesuslov_build.py): setuptools', and the kernel compiled at install."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def backend(monkeypatch):
    pytest.importorskip("setuptools")
    if sys.version_info < (3, 11):
        pytest.importorskip("tomli")
    spec = importlib.util.spec_from_file_location("liesuslov_build", ROOT / "build_backend" / "liesuslov_build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.delenv("LIESUSLOV_PRECOMPILE", raising=False)
    return module


def test_precompiling_is_on_unless_switched_off(backend, monkeypatch):
    assert backend._wanted(None) and backend._wanted({})
    monkeypatch.setenv("LIESUSLOV_PRECOMPILE", "0")
    assert not backend._wanted(None)
    assert backend._wanted({"precompile": "true"})  # the config setting over the environment
    monkeypatch.setenv("LIESUSLOV_PRECOMPILE", "1")
    assert not backend._wanted({"precompile": "False"})
    with pytest.raises(ValueError, match="precompile.*true or false.*'maybe'"):
        backend._wanted({"precompile": "maybe"})


def test_the_build_environment_gets_numba_and_the_dependencies_to_precompile(backend, monkeypatch):
    """The requirements come from pyproject.toml (its dependencies and the fast extra), only when precompiling."""
    monkeypatch.chdir(ROOT)
    monkeypatch.setattr(backend._setuptools, "get_requires_for_build_wheel", lambda cs=None: ["wheel"])
    monkeypatch.setattr(backend._setuptools, "get_requires_for_build_editable", lambda cs=None: ["wheel"])
    for hook in (backend.get_requires_for_build_wheel, backend.get_requires_for_build_editable):
        names = [r.split(">")[0].split("=")[0].split(";")[0].strip() for r in hook(None)]
        assert {"wheel", "numpy", "scipy", "numba"} <= set(names)
        assert hook({"precompile": "false"}) == ["wheel"]


def test_a_failed_precompile_step_leaves_no_compiled_code_and_the_build_goes_on(backend, monkeypatch, tmp_path,
                                                                                   capsys):
    """The step runs the kernel's warm module from this source tree (on PYTHONPATH) writing into the precompiled
    directory (LIESUSLOV_PRECOMPILED=write), which it empties first; a failure is reported and removes it."""
    monkeypatch.chdir(tmp_path)
    target = tmp_path / backend._PRECOMPILED
    target.mkdir(parents=True)
    (target / "stale.nbi").write_text("from an earlier build")
    seen = {}

    def run(cmd, cwd, env):
        seen.update(cmd=cmd, env=env, stale=(target / "stale.nbi").exists())
        target.mkdir(parents=True, exist_ok=True)
        (target / "half.nbi").write_text("a family compiled before the failure")
        return subprocess.CompletedProcess(cmd, 1, "", "numba.core.errors.TypingError: something\n")

    monkeypatch.setattr(backend, "_run", run)
    backend._precompile(None)
    assert seen["cmd"][1:] == ["-m", "liesuslov.integrators.kernel.warm"]
    assert seen["env"]["LIESUSLOV_PRECOMPILED"] == "write" and not seen["stale"]
    assert seen["env"]["PYTHONPATH"].split(":")[0] == str(tmp_path)
    assert not target.exists()
    assert "not compiled at install (numba.core.errors.TypingError: something)" in capsys.readouterr().err

    def compiled(cmd, cwd, env):
        target.mkdir(parents=True)
        (target / "new.nbi").write_text("compiled")
        return subprocess.CompletedProcess(cmd, 0, "all 1 s", "")

    monkeypatch.setattr(backend, "_run", compiled)
    backend._precompile(None)
    assert (target / "new.nbi").exists() and "kernel compiled" in capsys.readouterr().err
    seen.clear()
    monkeypatch.setattr(backend, "_run", lambda cmd, cwd, env: seen.update(called=True))
    backend._precompile({"precompile": "false"})
    assert not seen and (target / "new.nbi").exists()  # switched off: nothing run, nothing removed


def test_a_precompile_step_beyond_its_time_is_killed_with_the_processes_it_started(backend, monkeypatch, tmp_path):
    """_run: past the time limit the step's whole process group goes (warm's compilers with it), no hang."""
    monkeypatch.setattr(backend, "_TIMEOUT", 1.0)
    marker = tmp_path / "grandchild-alive"
    grandchild = tmp_path / "grandchild.py"
    grandchild.write_text(f"import time\ntime.sleep(3)\nopen({str(marker)!r}, 'w').close()\n")
    child = tmp_path / "child.py"
    child.write_text(f"import subprocess, sys, time\nsubprocess.Popen([sys.executable, {str(grandchild)!r}])\n"
                     "time.sleep(60)\n")
    script = str(child)
    with pytest.raises(subprocess.TimeoutExpired):
        backend._run([sys.executable, script], cwd=str(tmp_path), env=dict(os.environ))
    time.sleep(4)
    assert not marker.exists()  # the grandchild was killed with its parent
