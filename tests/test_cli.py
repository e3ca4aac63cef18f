"""The command line, called in-process: run, cases, check, bench delegation, clean errors."""

from __future__ import annotations

import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

import liesuslov as ls
from liesuslov import cli
from liesuslov.scene import DEFAULT_SCENE, scene_from_text

SCENES = Path(__file__).resolve().parents[1] / "examples" / "scenes"


def _has_matplotlib() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def test_run_default_scene(tmp_path, capsys):
    out = tmp_path / "out"
    assert cli.main(["run", "--out", str(out), "--no-figures", "--t-end", "2"]) == 0
    text = capsys.readouterr().out
    for expected in ("scene: Klebsh–Tisserand, n = 4", "model: symmetric form on so(4)", "state: 7 + g (4x4) = 23",
                     "field evaluations", "energy", "F_1", "F_3", "max |g^T g - I|", "max ||Gamma| - 1|",
                     "max |<a^i, Omega>|"):
        assert expected in text, expected
    assert sorted(p.name for p in out.iterdir()) == ["report.txt", "scene.toml", "trajectory.npz"]
    sol = ls.Solution.load(out / "trajectory.npz")
    assert sol.success and sol.t[-1] == 2.0 and sol.g.shape[1:] == (4, 4)
    saved = scene_from_text((out / "scene.toml").read_text(), source="saved")
    assert saved.t_span == (0.0, 2.0) and not saved.figures  # the overrides are recorded
    assert "first integrals" in (out / "report.txt").read_text()


@pytest.mark.skipif(not _has_matplotlib(), reason="matplotlib not installed")
def test_run_scene_writes_figures_and_removes_stale_files(tmp_path, capsys):
    out = tmp_path / "sleigh"
    out.mkdir()
    (out / "gamma.png").write_bytes(b"stale")
    (out / "notes.txt").write_text("mine")
    assert cli.main(["run", str(SCENES / "chaplygin_sleigh_se2.toml"), "--out", str(out), "--t-end", "3"]) == 0
    names = {p.name for p in out.iterdir()}
    assert {"trajectory.npz", "omega.png", "path.png", "energy.png", "report.txt", "scene.toml"} <= names
    assert "gamma.png" not in names and "notes.txt" in names  # only our own stale outputs are removed
    assert not [p for p in out.iterdir() if p.name.startswith(".liesuslov-")]  # no temporary left
    assert (out / "omega.png").read_bytes()[:4] == b"\x89PNG"
    assert "model: reduced form on se(2)" in capsys.readouterr().out


def test_print_default(capsys):
    assert cli.main(["run", "--print-default"]) == 0
    assert capsys.readouterr().out == DEFAULT_SCENE


def test_cases_table(capsys):
    assert cli.main(["cases"]) == 0
    text = capsys.readouterr().out
    for name, entry in ls.CASES.items():
        assert f"{name}: {entry.description}" in text
    assert "integrals   energy, F_1, F_2, F_3" in text  # klebsh_tisserand
    assert "I1 = 1, In = 2, Bn = 1" in text  # lagrange's example parameters


@pytest.mark.parametrize("name", ["kharlamova", "gyroscopic3", "family3"])
def test_case_template_is_a_runnable_scene(name, capsys):
    assert cli.main(["cases", name]) == 0
    text = capsys.readouterr().out
    assert text.startswith(f"# {name}: ")  # the whole output is a scene file (prose as comments)
    scene = scene_from_text(text, source="template").with_options(t_end=0.5)
    assert scene.case.name == name and scene.run().success


def test_check_lagrange3_passes_with_the_reduction_report(capsys):
    # the scene asks for backend = "numpy", which reaches both integrations of the reduction check
    assert cli.main(["check", str(SCENES / "lagrange3.toml"), "--t-end", "3"]) == 0
    text = capsys.readouterr().out
    assert "Lagrange reduction check: SO(3) -> S^2" in text
    assert "reduction consistent within tol = 1e-08" in text and "check passed" in text


def test_check_fails_above_tolerance(capsys):
    assert cli.main(["check", str(SCENES / "kharlamova5.toml"), "--t-end", "2", "--tol", "1e-18"]) == 1
    assert "check FAILED" in capsys.readouterr().out


@pytest.mark.parametrize("argv", [["run"], ["check"]])
def test_bad_file_exit_2_one_line(tmp_path, capsys, argv):
    bad = tmp_path / "bad.toml"
    bad.write_text(DEFAULT_SCENE.replace("B = [4.0, 3.0, 2.5, 1.0]", "B = [4.0, 3.0, 2.5]"))
    out = tmp_path / "out"
    extra = ["--out", str(out)] if argv == ["run"] else []
    assert cli.main(argv + [str(bad)] + extra) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("liesuslov: error: ") and "[case.parameters].B" in err
    assert not out.exists()


def test_missing_file_and_usage_errors(tmp_path, capsys):
    assert cli.main(["run", str(tmp_path / "nope.toml")]) == 2
    assert "scene file not found" in capsys.readouterr().err
    assert cli.main(["frobnicate"]) == 2
    assert cli.main(["run", "--t-end", "x"]) == 2
    assert cli.main(["cases", "nope"]) == 2
    assert "unknown case 'nope'" in capsys.readouterr().err


def test_debug_shows_the_traceback(tmp_path):
    with pytest.raises(FileNotFoundError):
        cli.main(["--debug", "run", str(tmp_path / "nope.toml")])


def test_failed_integration_exit_1_nothing_written(tmp_path, capsys):
    scene = tmp_path / "blowup.toml"
    scene.write_text("[body]\nprincipal_moments = [[2.0, 0.0, 0.3], [0.0, 3.0, 0.4], [0.3, 0.4, 4.0]]\n"
                     "[initial]\nw = [100.0, 1000.0, 0.0]\n"
                     "[integrate]\nt_span = [0.0, 10.0]\nmethod = \"rkmk4\"\nh = 1.0\nt_eval = \"steps\"\n"
                     "backend = \"numpy\"\n")
    out = tmp_path / "out"
    assert cli.main(["run", str(scene), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "the integration failed: non-finite state at t = " in err and "nothing written" in err
    assert not out.exists()


def test_bench_unavailable_is_a_clear_error(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "liesuslov.bench", None)  # makes the import fail
    assert cli.main(["bench", "--quick"]) == 2
    err = capsys.readouterr().err
    assert "the bench command is unavailable" in err and "Traceback" not in err
    assert cli.main(["run", "--print-default"]) == 0  # the other commands never import it


def test_bench_delegates(monkeypatch):
    seen = {}
    fake = types.ModuleType("liesuslov.bench")

    def add_arguments(parser):
        parser.add_argument("--quick", action="store_true")

    def run_from_args(args):
        seen["quick"] = args.quick
        return 0
    fake.add_arguments, fake.run_from_args = add_arguments, run_from_args
    monkeypatch.setitem(sys.modules, "liesuslov.bench", fake)
    assert cli.main(["bench", "--quick"]) == 0 and seen == {"quick": True}


def test_python_dash_m(tmp_path):
    r = subprocess.run([sys.executable, "-m", "liesuslov", "--version"], capture_output=True, text=True,
                       cwd=tmp_path, check=False)
    assert r.returncode == 0 and r.stdout.startswith("liesuslov ")


def test_import_stays_light():
    code = ("import sys, liesuslov, liesuslov.scene, liesuslov.cli; "
            "print(any(m in sys.modules for m in ('matplotlib', 'tqdm', 'numba', 'geomstats')))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout.strip() == "False"


def test_scene_run_matches_cli_trajectory(tmp_path, capsys):
    out = tmp_path / "o"
    assert cli.main(["run", str(SCENES / "suslov3.toml"), "--out", str(out), "--no-figures", "--t-end", "1"]) == 0
    saved = ls.Solution.load(out / "trajectory.npz")
    from liesuslov.scene import load_scene

    sol = load_scene(SCENES / "suslov3.toml").with_options(t_end=1.0).run()
    np.testing.assert_array_equal(saved.omega, sol.omega)


# ---------------------------------------------------------------------------- ensemble
def test_ensemble_command_writes_a_store_reproducible_across_workers(tmp_path, capsys):
    base = [str(SCENES / "suslov3.toml"), "--n", "12", "--t-end", "0.3", "--seed", "4", "--chunk-size", "5"]
    assert cli.main(["ensemble", *base, "--workers", "0", "--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert "12/12 trajectories reached t = 0.3" in out and "open_ensemble" in out
    assert cli.main(["ensemble", *base, "--workers", "1", "--executor", "process", "--final",
                     "--out", str(tmp_path / "b")]) == 0
    a, b = ls.open_ensemble(tmp_path / "a"), ls.open_ensemble(tmp_path / "b")
    assert a.omega.shape == (2, 12, 3) and b.omega.shape == (1, 12, 3) and a.g.shape == (2, 12, 3, 3)
    assert np.array_equal(a.omega[-1:], b.omega) and np.all(a.status == 0)
    # the draws are around the scene's state, inside the constraint subspace
    scene = ls.load_scene(SCENES / "suslov3.toml")
    D = scene.system.constraints
    assert np.allclose(D.project(a.omega[0]), a.omega[0], rtol=0, atol=1e-14)
    assert 0 < np.abs(a.omega[0] - scene.omega0).max() < 0.1


def test_max_steps_option_bounds_every_integrating_command(tmp_path, capsys):
    """--max-steps reaches integrate from run, check and ensemble: a scene that needs more steps fails
    at once with the reason (exit 1), where it would otherwise grind through 10^7 steps."""
    scene = str(SCENES / "suslov3.toml")
    assert cli.main(["run", scene, "--max-steps", "3", "--out", str(tmp_path / "r")]) == 1
    assert "the integration failed: max_steps reached at t = " in capsys.readouterr().err
    assert cli.main(["check", scene, "--max-steps", "3"]) == 1
    assert "max_steps reached" in capsys.readouterr().err
    assert cli.main(["ensemble", scene, "--n", "3", "--max-steps", "3", "--out", str(tmp_path / "e")]) == 1
    err = capsys.readouterr().err
    assert "3 of 3 trajectories failed; the first (index 0): max_steps reached" in err
    assert np.all(ls.open_ensemble(tmp_path / "e").status == -1)
    assert cli.main(["run", scene, "--max-steps", "0"]) == 2
    assert "max_steps must be a positive integer, got 0" in capsys.readouterr().err


def test_ensemble_command_bad_arguments_exit_2(tmp_path, capsys):
    assert cli.main(["ensemble", str(SCENES / "suslov3.toml"), "--n", "0", "--out", str(tmp_path)]) == 2
    assert "--n must be >= 1" in capsys.readouterr().err
    assert cli.main(["ensemble", str(SCENES / "suslov3.toml"), "--workers", "-1", "--out", str(tmp_path)]) == 2


# ---------------------------------------------------------------------------- section, phase (research tools)
FREE_BODY = """description = "free rigid body"
constraints = "none"
[body]
principal_moments = [1.0, 2.0, 3.0]
[initial]
w = [0.3, 0.2, 1.0]
[integrate]
t_span = [0.0, 10.0]
method = "rkmk853"
"""


def test_phase_command_free_body_matches_the_elliptic_period(tmp_path, capsys):
    from liesuslov.analytic.euler_top import EulerTop

    scene = tmp_path / "free.toml"
    scene.write_text(FREE_BODY)
    assert cli.main(["phase", str(scene), "--out", str(tmp_path / "ph"), "--no-figures"]) == 0
    text = (tmp_path / "ph" / "phase.txt").read_text()
    assert text in capsys.readouterr().out
    T = float(text.split("period T = ")[1].split()[0])
    assert abs(T - float(EulerTop([1.0, 2.0, 3.0], [0.3, 0.2, 1.0]).period)) < 1e-8
    assert "axis (momentum)" in text and "free body (Montgomery)" in text


def test_phase_command_no_return_exits_1(tmp_path):
    out = tmp_path / "ph"
    assert cli.main(["phase", str(SCENES / "suslov3.toml"), "--t-max", "20", "--out", str(out), "--no-figures"]) == 1
    assert "t_max = 20" in (out / "phase.txt").read_text()


def test_section_command_writes_crossings_and_integral_drift(tmp_path, capsys):
    out = tmp_path / "sec"
    assert cli.main(["section", str(SCENES / "lagrange3.toml"), "--n", "3", "--t-end", "20", "--out", str(out),
                     "--no-figures"]) == 0
    data = np.load(out / "section.npz")
    assert data["t"].size > 0 and np.max(np.abs(data["Gamma"][:, -1])) < 1e-10
    assert set(np.unique(data["index"])) <= {0, 1, 2}
    text = (out / "section.txt").read_text()
    drifts = [float(line.rsplit(":", 1)[1]) for line in text.splitlines() if line.startswith("max |")]
    assert drifts and max(drifts) < 1e-7
    assert cli.main(["section", str(SCENES / "lagrange3.toml"), "--index", "7", "--out", str(out)]) == 2
    assert "--index" in capsys.readouterr().err


def test_section_and_phase_commands_take_max_steps_and_leave_no_stale_figure(tmp_path, capsys):
    """An audit: section and phase ignored the scene's max_steps (and had no --max-steps); a section never
    crossed said nothing and left the previous run's section.png beside a report of 0 crossings."""
    out = tmp_path / "sec"
    scene = str(SCENES / "lagrange3.toml")
    assert cli.main(["section", scene, "--n", "2", "--t-end", "20", "--out", str(out)]) == 0
    capsys.readouterr()
    if _has_matplotlib():
        assert (out / "section.png").is_file()
    assert cli.main(["section", scene, "--n", "2", "--t-end", "20", "--value", "5", "--out", str(out)]) == 0
    text = (out / "section.txt").read_text()
    assert "crossings: 0" in text and "(no crossing: Gamma[-1] = 5 is not crossed" in text
    assert not (out / "section.png").exists()
    assert cli.main(["section", scene, "--n", "2", "--max-steps", "3", "--out", str(out), "--no-figures"]) == 1
    captured = capsys.readouterr()
    assert "failed: 2 of 2 trajectories failed; the first (index 0): max_steps reached" in captured.out
    assert "Warning" not in captured.err
    free = tmp_path / "free.toml"
    free.write_text(FREE_BODY + "max_steps = 3\n")  # the scene's own bound reaches the tool
    assert cli.main(["phase", str(free), "--out", str(tmp_path / "ph"), "--no-figures"]) == 1
    assert "max_steps reached" in (tmp_path / "ph" / "phase.txt").read_text()
    assert cli.main(["phase", str(free), "--max-steps", "100000", "--out", str(tmp_path / "ph"), "--no-figures"]) == 0
    assert "|T - T'| = " in (tmp_path / "ph" / "phase.txt").read_text()


@pytest.mark.parametrize("argv,says", [
    (["section", "--value", "nan"], "--value must be a finite number"),
    (["section", "--scale", "nan"], "--scale must be a finite number"),
    (["ensemble", "--seed", "-1", "--n", "4"], "--seed must be >= 0"),
])
def test_bad_options_are_named(tmp_path, capsys, argv, says):
    """The audit's cases: --value nan was reported as '--index: LinearEvent offset must be finite', --scale nan
    as 'Gamma contains NaN', --seed -1 as numpy's 'expected non-negative integer'."""
    assert cli.main(argv + ["--out", str(tmp_path / "o"), str(SCENES / "lagrange3.toml")]) == 2
    assert says in capsys.readouterr().err


def test_bench_refuses_an_unknown_backend(capsys):
    """--backend gpu was ignored (exit 0, the summary said 'numpy')."""
    assert cli.main(["bench", "--quick", "--backend", "gpu"]) == 2
    assert "invalid choice" in capsys.readouterr().err


def test_run_refuses_an_output_folder_it_cannot_make_before_integrating(tmp_path, capsys, monkeypatch):
    """An impossible [output].dir was found only after the whole integration (an OSError at the end)."""
    called = []
    monkeypatch.setattr(cli, "_integrate_and_report", lambda *a, **k: called.append(1))
    (tmp_path / "afile").write_text("x")
    assert cli.main(["run", "--out", str(tmp_path / "afile" / "out"), "--no-figures"]) == 2
    assert "cannot be created" in capsys.readouterr().err and not called
    assert cli.main(["run", "--out", str(tmp_path / "afile"), "--no-figures"]) == 2
    assert "exists and is not a folder" in capsys.readouterr().err and not called
    fresh = tmp_path / "new" / "out"
    assert cli.main(["run", "--out", str(fresh), "--no-figures"]) == 1  # (the stub reports a failed run)
    assert called and not fresh.exists()  # probed, then left as it was


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX file modes")
def test_atomic_files_get_the_umask_mode_without_changing_the_umask(tmp_path, monkeypatch):
    """Files written atomically get the mode an ordinary open() would (mkstemp makes 0o600), read without
    setting the umask to 0 for a moment (a file another thread created then was world-writable)."""
    import os

    from liesuslov import _io

    calls = []
    real_umask = os.umask
    monkeypatch.setattr(os, "umask", lambda m: calls.append(m) or real_umask(m))
    old = real_umask(0o027)
    try:
        path = _io.write_text(tmp_path / "a.txt", "x")
        created = _io.atomic_create(tmp_path / "b.txt", b"y")
        assert (path.stat().st_mode & 0o777) == (created.stat().st_mode & 0o777) == 0o640
        if Path("/proc/self/status").is_file():
            assert calls == []
        with pytest.raises(FileExistsError):
            _io.atomic_create(tmp_path / "b.txt", b"z")
        assert created.read_bytes() == b"y" and sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]
    finally:
        real_umask(old)


def test_dir_lists_the_lazy_names_without_importing_them():
    """dir(liesuslov) lists every public name, the lazily imported ones too (tab completion missed
    ls.ensemble, ls.poincare_section, ...), and listing them imports nothing."""
    code = ("import sys, liesuslov as ls; names = dir(ls); "
            "print(sorted(set(ls.__all__) - set(names)), 'liesuslov.research' in sys.modules, "
            "'liesuslov.ensembles' in sys.modules, 'ensemble' in names and 'poincare_section' in names)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout.strip() == "[] False False True"
