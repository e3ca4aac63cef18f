"""The build backend (build_backend/liesuslov_build.py): setuptools', and the kernel compiled at install."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
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

    def run(cmd, **kw):
        seen.update(cmd=cmd, env=kw["env"], stale=(target / "stale.nbi").exists())
        target.mkdir(parents=True, exist_ok=True)
        (target / "half.nbi").write_text("a family compiled before the failure")
        return subprocess.CompletedProcess(cmd, 1, "", "numba.core.errors.TypingError: something\n")

    monkeypatch.setattr(backend.subprocess, "run", run)
    backend._precompile(None)
    assert seen["cmd"][1:] == ["-m", "liesuslov.integrators.kernel.warm"]
    assert seen["env"]["LIESUSLOV_PRECOMPILED"] == "write" and not seen["stale"]
    assert seen["env"]["PYTHONPATH"].split(":")[0] == str(tmp_path)
    assert not target.exists()
    assert "not compiled at install (numba.core.errors.TypingError: something)" in capsys.readouterr().err

    def compiled(cmd, **kw):
        target.mkdir(parents=True)
        (target / "new.nbi").write_text("compiled")
        return subprocess.CompletedProcess(cmd, 0, "all 1 s", "")

    monkeypatch.setattr(backend.subprocess, "run", compiled)
    backend._precompile(None)
    assert (target / "new.nbi").exists() and "kernel compiled" in capsys.readouterr().err
    seen.clear()
    monkeypatch.setattr(backend.subprocess, "run", lambda cmd, **kw: seen.update(called=True))
    backend._precompile({"precompile": "false"})
    assert not seen and (target / "new.nbi").exists()  # switched off: nothing run, nothing removed
