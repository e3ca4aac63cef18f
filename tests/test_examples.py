"""The example scripts: each one's ``main(out_dir, quick=True)`` runs and saves a non-empty PNG."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

pytest.importorskip("matplotlib")

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
SCRIPTS = sorted(p for p in EXAMPLES.glob("*.py") if not p.name.startswith("_"))
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def load(path: Path):
    """Import an example by path (the examples are scripts, not a package, sharing ``_common.py``)."""
    if str(EXAMPLES) not in sys.path:
        sys.path.insert(0, str(EXAMPLES))
    spec = importlib.util.spec_from_file_location(f"liesuslov_example_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_there_are_examples():
    assert len(SCRIPTS) >= 6


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_example_saves_its_figure(script, tmp_path, capsys, monkeypatch):
    front = importlib.import_module("liesuslov.integrators.integrate")  # the module (the package exports the function)
    module = load(script)
    chosen = []
    choose = front._choose_solver
    monkeypatch.setattr(front, "_choose_solver", lambda P, backend: chosen.append(choose(P, backend)[1]) or
                        choose(P, backend))
    path = module.main(tmp_path, quick=True)
    # examples/README.md: a --quick run never waits for the compilation of the optional kernel
    assert "numba" not in chosen
    path = Path(path)
    assert path.parent == tmp_path
    assert path.suffix == ".png"
    data = path.read_bytes()
    assert len(data) > 10_000
    assert data[:8] == PNG_MAGIC
    out = capsys.readouterr().out
    assert re.search(r"\d\.\d+e[-+]\d\d", out), "an example prints the numbers that check its physics"


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_example_is_a_runnable_script(script):
    text = script.read_text(encoding="utf-8")
    assert 'if __name__ == "__main__":' in text
    assert "--out" in text and "--quick" in text
    assert "def main(out_dir=None, quick: bool = False) -> Path:" in text


def test_readme_lists_every_example():
    readme = (EXAMPLES / "README.md").read_text(encoding="utf-8")
    for script in SCRIPTS:
        assert f"examples/{script.name}" in readme, f"{script.name} is missing from examples/README.md"
