"""The work-precision benchmark's machinery, on a tiny configuration (the numbers are not asserted)."""

from __future__ import annotations

import argparse
import csv
import inspect
import math

import numpy as np
import pytest

import liesuslov as ls
from liesuslov import bench
from liesuslov.bench import targets

# The numpy path: a fresh clone must not wait for the one-off compilation of an optional kernel.
BACKEND = "numpy" if "backend" in inspect.signature(ls.integrate).parameters else None
TINY = bench.BenchConfig(
    scenes=("lagrange",), methods=("rkmk4", "rkmk853"), charts=("exp", "cayley"), scipy_methods=("DOP853",),
    fixed_factors={"rkmk4": (0.5, 4)}, tolerances={"rkmk853": (1e-5, 1e-10), "DOP853": (1e-5, 1e-10)},
    repeats=1, batch_sizes=(1, 10), throughput_work=100, batch_dims=(3,), scaling_sizes=(3, 4), long_run_steps=0,
    plots=False, backend=BACKEND, targets=False, preset="test")
# The targets of issue 10 at a small size (every measurement runs, the floor included).
TARGETS = bench.BenchConfig(
    scenes=("lagrange",), methods=("rkmk4",), charts=("exp",), scipy_methods=("DOP853",),
    fixed_factors={"rkmk4": (0.5, 4)}, tolerances={"DOP853": (1e-5, 1e-10)}, repeats=1, batch_sizes=(),
    scaling_sizes=(), long_run_steps=0, plots=False, backend=BACKEND, target_steps=200, target_batch=50,
    target_batch_steps=5, import_runs=1, cold_compile=False, preset="test")


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    docs = out / "docs" / "performance.md"
    report = bench.run_bench(out, config=TINY, progress=False, docs=docs)
    with open(out / "results.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    return out, report, rows


def _f(x: str) -> float:
    return float(x) if x not in ("", None) else math.nan


def test_results_csv_columns_and_rows(tiny):
    out, report, rows = tiny
    with open(out / "results.csv", newline="", encoding="utf-8") as fh:
        header = next(csv.reader(fh))
    assert tuple(header) == bench.RESULT_COLUMNS
    # rkmk4 and rkmk853 in two charts at two settings, DOP853 at two settings
    assert len(rows) == 2 * 2 * 2 + 2 == len(report.rows)
    assert {r["route"] for r in rows} == {"liesuslov rkmk4/exp", "liesuslov rkmk4/cayley", "liesuslov rkmk853/exp",
                                          "liesuslov rkmk853/cayley", "scipy DOP853"}
    assert all(r["status"] == "ok" for r in rows)
    for r in rows:
        assert _f(r["wall_time"]) > 0 and int(r["nfev"]) > 0 and int(r["steps"]) > 0
        assert r["backend"] == ("scipy" if r["library"] == "scipy" else "numpy")
        assert np.isfinite(_f(r["err_pendulum"]))  # the Lagrange scene is checked against the pendulum
        assert _f(r["error"]) >= max(_f(r["err_Omega"]), _f(r["err_Gamma"]), _f(r["err_g"]))


def test_errors_fall_with_the_setting(tiny):
    _, _, rows = tiny
    by_route: dict[str, list] = {}
    for r in rows:
        by_route.setdefault(r["route"], []).append(r)
    for route, rs in by_route.items():
        coarse, fine = sorted(rs, key=lambda r: -_f(r["setting"]))
        assert _f(fine["error"]) < 1e-2 * _f(coarse["error"]), route


def test_structure_exact_for_liesuslov_and_reported_for_scipy(tiny):
    _, report, rows = tiny
    for r in rows:
        if r["library"] == "liesuslov":
            for key in ("orth_defect", "sphere_defect", "constraint_defect"):
                assert _f(r[key]) <= 1e-12, (r["route"], key)
        else:
            assert np.isfinite(_f(r["orth_defect"]))
            assert np.isfinite(_f(r["sphere_defect"]))
    loose = [r for r in rows if r["library"] == "scipy" and _f(r["setting"]) == 1e-5]
    assert _f(loose[0]["orth_defect"]) > 1e-12  # the embedded ODE drifts off SO(3)
    assert report.references["lagrange"]["uncertainty"] < 1e-10


def test_ratio_table_and_outputs(tiny):
    out, report, _ = tiny
    assert [r["level"] for r in report.ratios] == list(bench.LEVELS)
    for r in report.ratios:
        if np.isfinite(r["ratio"]):
            assert r["ratio"] == pytest.approx(r["liesuslov_time"] / r["scipy_time"])
    assert len(report.throughput) == 2 and all(r["status"] == "ok" for r in report.throughput)
    assert len(report.scaling) == 4 and len(report.scaling_exponent) == 2  # two charts
    summary = (out / "summary.md").read_text(encoding="utf-8")
    assert "## Ratio table" in summary and "| CPU |" in summary
    page = (out / "docs" / "performance.md").read_text(encoding="utf-8")
    assert "python -m liesuslov.bench --docs docs/performance.md" in page and "## Ratio table" in page
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no staging or temporary files left behind
    assert set(report.paths) >= {"results", "ratios", "throughput", "nscaling", "summary", "docs"}
    assert not list(out.glob("*.png"))  # plots=False


def test_time_to_reach_interpolates_in_log_log():
    pts = [(1e-4, 1.0), (1e-6, 100.0)]
    assert bench.time_to_reach(pts, 1e-5) == pytest.approx(10.0)
    assert bench.time_to_reach(pts, 1e-3) == pytest.approx(1.0)  # already below at the coarsest setting
    assert bench.time_to_reach(pts, 1e-8) == math.inf
    assert bench.time_to_reach([(1e-4, 1.0), (float("nan"), 2.0), (1e-7, 4.0)], 1e-6) < 4.0


def test_unknown_scene_is_a_value_error_naming_the_valid_ones(tmp_path):
    with pytest.raises(ValueError, match="unknown scene") as info:
        bench.run_bench(tmp_path / "out", scenes=["nope"], progress=False)
    for name in bench.SCENES:
        assert name in str(info.value)
    assert not (tmp_path / "out").exists()  # nothing written
    with pytest.raises(ValueError, match="repeats"):
        bench.run_bench(tmp_path / "out", config=TINY, repeats=0, progress=False)
    with pytest.raises(ValueError, match="valid methods"):
        bench.run_bench(tmp_path / "out", config=bench.BenchConfig(methods=("rk99",)), progress=False)


def test_command_line(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    bench.add_arguments(parser)
    args = parser.parse_args([])
    assert args.out == "liesuslov-bench" and not args.quick and args.scenes is None and args.repeats is None
    assert bench.main(["--scenes", "klebsh-tisserand,nope", "--out", str(tmp_path / "x"), "--no-progress"]) == 2
    assert "valid scenes" in capsys.readouterr().err
    assert bench.build_scene("euler_top").key == "euler-top"


def test_a_failure_while_writing_leaves_nothing_behind(tmp_path, monkeypatch):
    cfg = bench.BenchConfig(scenes=("suslov3",), methods=("rkmk853",), scipy_methods=("DOP853",),
                            tolerances={"rkmk853": (1e-6,), "DOP853": (1e-6,)}, repeats=1, batch_sizes=(),
                            scaling_sizes=(), long_run_steps=0, plots=False, backend=BACKEND, targets=False)

    def fail(*args, **kwargs):
        raise OSError("disk full")
    monkeypatch.setattr(bench.tables, "summary_sections", fail)
    with pytest.raises(OSError, match="disk full"):
        bench.run_bench(tmp_path, config=cfg, progress=False, docs=tmp_path / "performance.md")
    assert list(tmp_path.iterdir()) == []


def test_target_without_a_value_says_why():
    rows = [{"target": "a", "n": 3, "lib_us_per_step": 120.0, "status": "ok", "floor_status": "numba is not installed"},
            {"target": "b", "n": 3, "batch": 100, "status": "failed", "message": "ValueError: boom"}]
    summary = targets.summary(rows, {}, [], [])
    by = {t["target"]: t for t in summary}
    assert by["a (n = 3)"]["why"] == "numba is not installed" and by["a (n = 3)"]["met"] is None
    assert by["b"]["why"] == "failed; ValueError: boom"
    assert by["d"]["why"] in ("numba is not installed", "the n-sweep ran on numpy only (--quick or --backend numpy)")
    assert by["e"]["why"] == "no error level reached by both liesuslov and scipy"


def test_presets():
    quick, full = bench.BenchConfig.quick().validated(), bench.BenchConfig.full().validated()
    assert quick.methods == ("rkmk4", "rkmk45", "rkmk853") and quick.long_run_steps == 0
    assert max(quick.batch_sizes) == 100 and max(quick.scaling_sizes) == 64
    assert set(full.methods) == set(ls.METHODS) and full.long_run_steps == 1_000_000
    assert max(full.batch_sizes) == 100_000 and max(full.scaling_sizes) == 256


@pytest.mark.slow
def test_targets_are_reported_as_ratios(tmp_path):
    docs = tmp_path / "docs" / "performance.md"
    report = bench.run_bench(tmp_path, config=TARGETS, progress=False, docs=docs)
    names = [t["target"] for t in report.target_summary]
    assert names == ["a (n = 3)", "a (n = 4)", "b", "c", "d", "e", "f (import)", "f (compile)"]
    by = {t["target"]: t for t in report.target_summary}
    assert by["c"]["value"] >= 1.0  # output times never save evaluations
    assert 0.0 < by["f (import)"]["value"] < 60.0
    assert by["f (compile)"]["met"] is None and math.isnan(by["f (compile)"]["value"])  # not measured here
    page = docs.read_text(encoding="utf-8")
    assert "## Targets" in page and "floor" in page
    assert "targets" in report.paths
    if targets.have_floor():
        assert by["a (n = 3)"]["value"] > 0 and by["b"]["value"] > 0
        assert all(r["agrees"] for r in report.targets if "agreement" in r)


def test_target_summary_from_measurements():
    rows = [{"target": "a", "n": 3, "ratio": 2.0, "lib_us_per_step": 0.3, "floor_us_per_step": 0.15,
             "agreement": 1e-15, "agrees": True, "status": "ok", "floor_status": "ok", "steps": 10},
            {"target": "a", "n": 4, "ratio": 5.0, "status": "ok", "floor_status": "ok"},
            {"target": "b", "n": 3, "batch": 100, "ratio": 0.8, "status": "ok", "floor_status": "ok"},
            {"target": "c", "ratio": 1.1, "nfev_dense": 11, "nfev_end": 10, "status": "ok"},
            {"target": "f", "import_s": 0.2, "import_runs": 1, "compile_status": "not measured (--quick)"}]
    scaling = [{"n": n, "chart": "exp", "requested": "numba", "status": "ok", "us_per_step": n ** 2 / 100}
               for n in (64, 128, 256)]
    ratios = [{"scene": "s", "level": 1e-6, "ratio_dop853": 0.05, "ratio_adaptive": 0.12, "adaptive_route": "r853"},
              {"scene": "s", "level": 1e-7, "ratio_dop853": 0.2, "ratio_adaptive": 0.3, "adaptive_route": "r45"}]
    summary = targets.summary(rows, bench.metrics.fit_exponent(scaling), scaling, ratios)
    by = {t["target"]: t for t in summary}
    assert by["a (n = 3)"]["met"] and not by["a (n = 4)"]["met"] and by["b"]["met"] and by["c"]["met"]
    assert by["d"]["value"] == pytest.approx(2.0) and by["d"]["met"]
    assert by["e"]["value"] == 0.2 and not by["e"]["met"]
    # the fastest routes may be fixed-step ones: the detail says what adaptive routes alone reach
    assert "adaptive routes only (rtol sweeps, as scipy's): worst 0.300 at s 1e-07 (r45)" in by["e"]["detail"]
    assert "slope between the two largest 2.00" in by["d"]["detail"] and "met when ≤ 2.3" in by["d"]["detail"]
    assert by["f (import)"]["met"] and by["f (compile)"]["met"] is None
    # a target without a value says why (the console prints it), a measured one says nothing
    assert by["f (compile)"]["why"] == "not measured (--quick)" and by["a (n = 3)"]["why"] == ""
    text = bench.tables.targets_section(bench.BenchReport(targets=rows, target_summary=summary))
    assert "## Targets" in text and "max |floor − library| = 1.0e-15" in text


def test_the_cold_start_target_says_whether_the_kernel_was_compiled_at_install():
    """(f): the first compiled call after installation is the measured value; the detail says whether it loaded
    the kernel the build compiled (and what that step took) or compiled it, and what compiling it costs."""
    row = {"target": "f", "import_s": 0.1, "import_runs": 3, "first_call_s": 0.5, "precompiled": True,
           "first_call_compiling_s": 28.0, "first_call_cached_s": 0.5, "precompile_s": 61.0, "compile_status": "ok"}
    by = {t["target"]: t for t in targets.summary([row], {}, [], [])}
    f = by["f (compile)"]
    assert f["value"] == 0.5 and f["met"]
    assert "loaded the kernel compiled at install" in f["detail"] and "61 s" in f["detail"]
    assert "compiling it in the call instead (LIESUSLOV_PRECOMPILED=off): 28 s" in f["detail"]
    row.update(first_call_s=28.0, precompiled=False, first_call_compiling_s=28.0)
    f = {t["target"]: t for t in targets.summary([row], {}, [], [])}["f (compile)"]
    assert not f["met"] and "no kernel compiled at install" in f["detail"]


def test_floor_runs_the_librarys_so4_dexpinv():
    """The n = 4 floor ran the closed-form so(3) dexp⁻¹ on each factor where the library's so(4) kind runs the
    series to ad² (an audit: 1.84 -> 2.22 of the floor). At h = 0.005 the two differ below the agreement tolerance,
    so the check here takes big steps, where the truncation shows."""
    pytest.importorskip("numba")
    from liesuslov.bench import floor
    from liesuslov.bench.scenes import floor_klebsh_tisserand

    sc = floor_klebsh_tisserand()
    h, steps = 0.4, 10
    sol = ls.integrate(sc.system, sc.Omega0, (0.0, h * steps), Gamma0=sc.Gamma0, reconstruct=True, method="rkmk4",
                       h=h, t_eval=[h * steps], backend="numba")
    gaps = {}
    for exact in (False, True):
        x, g = np.array(sc.x0, dtype=float), np.eye(4)
        floor.kt4_steps(x, g, np.array(sc.Gamma0, dtype=float), sc.coeffs, h, steps, exact)
        gaps[exact] = max(np.abs(x - sc.vector(sol.Omega[-1])).max(), np.abs(g - sol.g[-1]).max())
    assert gaps[False] < 1e-13 < 1e3 * gaps[False] < gaps[True]
    # and target (a)'s floor is that one
    x, g = np.array(sc.x0, dtype=float), np.eye(4)
    floor.kt4_steps(x, g, np.array(sc.Gamma0, dtype=float), sc.coeffs, targets.FLOOR_H, 50, False)
    fx, fg = targets._floor_run(4, sc.x0, sc.coeffs, sc.Gamma0, 50)
    assert np.array_equal(fx, x) and np.array_equal(fg, g)


@pytest.mark.parametrize("n", [3, 4])
def test_floor_agrees_with_the_library(n):
    pytest.importorskip("numba")
    kw = {} if BACKEND is None else {"backend": BACKEND}
    row = targets.measure_single(n, 300, 1, kw)
    assert row["status"] == "ok" and row["floor_status"] == "ok"
    assert row["agreement"] <= 1e-12, row
    assert row["floor_us_per_step"] > 0 and row["ratio"] > 0


def test_batch_floor_agrees_with_the_library():
    pytest.importorskip("numba")
    kw = {} if BACKEND is None else {"backend": BACKEND}
    row = targets.measure_batch(20, 10, 1, kw)
    assert row["status"] == "ok" and row["agreement"] <= 1e-12, row


def test_timed_together_alternates_the_calls_and_keeps_each_minimum():
    from liesuslov.bench.timing import timed_together

    calls: list[str] = []

    def make(name, value):
        def fn():
            calls.append(name)
            return value
        return fn
    (ra, ta), (rb, tb) = timed_together((make("a", 1), make("b", 2)), 3)[0]
    count = (len(calls) - 2) // 2
    # one warm-up call each, then rounds a, b, a, b, ...: a slow spell of the machine hits both sides
    assert calls == ["a", "b"] + ["a", "b"] * count and count == 3
    assert (ra, rb) == (1, 2) and 0.0 <= ta < math.inf and 0.0 <= tb < math.inf


def test_a_scene_is_timed_in_rounds_over_both_libraries_and_a_failing_run_is_recorded(monkeypatch):
    """execute_tasks: one warm-up call of each run (its result measured), then rounds calling every working
    run once each, liesuslov and scipy alternating; a run that raises is a failed row, the others are timed."""
    from liesuslov.bench import runners
    from liesuslov.bench.scenes import build_scene

    scene = build_scene("suslov3")
    ref = runners.build_reference(scene, {} if BACKEND is None else {"backend": BACKEND})
    tasks = [runners._Task("suslov3", "liesuslov", "rkmk4", "-", "h", 0.5),
             runners._Task("suslov3", "scipy", "DOP853", "-", "rtol", 1e-6),
             runners._Task("suslov3", "liesuslov", "rkmk4", "-", "h", -1.0)]  # h < 0: a ValueError
    calls: list[str] = []
    real_ls, real_sp = runners._run_liesuslov, runners._run_scipy
    monkeypatch.setattr(runners, "_run_liesuslov", lambda *a: (calls.append("ls"), real_ls(*a))[1])
    monkeypatch.setattr(runners, "_run_scipy", lambda *a: (calls.append("sp"), real_sp(*a))[1])
    rows = runners.execute_tasks(tasks, scene, ref, 3, {} if BACKEND is None else {"backend": BACKEND})
    assert [r["status"] for r in rows] == ["ok", "ok", "failed"]
    assert "ValueError" in rows[2]["message"] and math.isnan(rows[2]["wall_time"])
    assert rows[0]["repeats"] == rows[1]["repeats"] == 3
    assert calls == ["ls", "sp", "ls"] + ["ls", "sp"] * 3  # warm-ups (the failing one too), then rounds
    assert _f(rows[0]["error"]) < 1e-3 and _f(rows[1]["error"]) < 1e-4
