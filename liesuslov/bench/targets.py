"""The targets of issue 10, measured as ratios (the machine is shared: absolute times drift, ratios less).

* (a) one trajectory, n = 3 and n = 4, RKMK4 with reconstruction, h = 0.005: the library's time per step
  over the floor's (:mod:`.floor`, a plain compiled loop of the same method; goal ≤ 3);
* (b) a batch of 10⁴ free bodies, n = 3: the library's ns per trajectory-step over the single-threaded
  floor's (goal ≤ 1, the library using every core);
* (c) an adaptive run (the default scene of ``liesuslov run``: Klebsh–Tisserand in SO(4), rkmk853,
  rtol 1e-10) with 500 output times: its field evaluations over those of the same run reporting the end
  point only (goal ≤ 1.2);
* (d) Fedorov–Kozlov with reconstruction up to n = 256 with ``backend="numba"``: the growth exponent of
  the cost per step, from the n-scaling sweep (goal about 2);
* (e) work-precision: the fastest liesuslov route over scipy's DOP853 at equal error, worst over every
  scene and level 1e-5 … 1e-10 (goal ≤ 0.1 compiled);
* (f) cold start: ``import liesuslov`` in a fresh process (goal ≤ 0.3 s) and the first compiled call after
  installation in a fresh process with an empty numba cache (goal ≤ 10 s: it loads the kernel the build
  compiled, ``build_backend/``); for comparison the same call compiling the kernel itself, the next process
  (loading numba's cache), and the build's precompile step.

Every comparison with the floor also checks that the two computed the same numbers (to 1e-12): a
ratio to a loop that computes something else would mean nothing.
"""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .scenes import FLOOR_H, FLOOR_SCENES, floor_free_body, floor_klebsh_tisserand, hat3, klebsh_tisserand_rhs
from .timing import affordable_steps, child_env, timed_together

#: The floor and the library must agree to this (largest absolute difference of the state and of g).
AGREEMENT_TOL = 1e-12
#: Steps of a floor timing run at least (its per-step cost is ~0.1 µs: shorter runs time the call).
_FLOOR_MIN_STEPS = 100_000
#: Timed rounds of library and floor in (a) and (b) (the fastest of each is kept: on this shared machine a
#: round of 5 still caught slow spells, 0.33 vs 0.43 µs a step for the same code), and their time budget.
FLOOR_ROUNDS, FLOOR_BUDGET_S = 15, 8.0
#: Seconds one library call of (a) or (b) may take (fewer steps beyond: the numpy path is ~1000x the floor).
MEASURE_BUDGET_S = 5.0
#: Output times of target (c) and its interval.
DENSE_POINTS, DENSE_T1 = 500, 50.0
#: The goals, as the table states them.
GOALS = {"a": 3.0, "b": 1.0, "c": 1.2, "d": 2.0, "e": 0.1, "f-import": 0.3, "f-compile": 10.0}
#: Target (d) is met up to this far above n² (the measured exponent drifts with the machine's caches; n³ is far)
D_MARGIN = 0.3


def have_floor() -> bool:
    """Whether the floor can run (it is compiled by numba, the ``fast`` extra)."""
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def _floor_run(n: int, x0: np.ndarray, coeffs: np.ndarray, Gamma0, steps: int):
    """(vector, g) after ``steps`` floor steps from the identity: one trajectory."""
    from . import floor

    x = np.array(x0, dtype=float)
    g = np.eye(n)
    if n == 3:
        floor.free3_steps(x, g, coeffs, FLOOR_H, steps)
    else:
        # the library's so(4) kind: the so(3) dexp⁻¹ series to ad² on each factor (not the closed form)
        floor.kt4_steps(x, g, np.array(Gamma0, dtype=float), coeffs, FLOOR_H, steps, False)
    return x, g


def _agreement(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> float:
    """Largest absolute difference between two (vector, g) states."""
    return max(float(np.max(np.abs(a[0] - b[0]))), float(np.max(np.abs(a[1] - b[1]))))


def _single_row(n: int, sc, sol, wall: float, steps: int, count: int) -> dict:
    """The library's half of a target (a) row."""
    return {"target": "a", "n": n, "scene": sc.title, "steps": steps, "lib_us_per_step": wall / steps * 1e6,
            "repeats": count, "backend": sol.stats.get("backend", "numpy"),
            "status": "ok" if sol.success else "failed", "message": "" if sol.success else sol.message}


def measure_single(n: int, steps: int, repeats: int, extra_kw: dict) -> dict:
    """Target (a): one trajectory of ``steps`` RKMK4 steps, library against floor (time per step, agreement)."""
    import liesuslov as ls

    sc = FLOOR_SCENES[n]()

    def run(k):
        return ls.integrate(sc.system, sc.Omega0, (0.0, k * FLOOR_H), Gamma0=sc.Gamma0, reconstruct=True,
                            method="rkmk4", h=FLOOR_H, t_eval=[k * FLOOR_H], **extra_kw)
    steps = affordable_steps(run, steps, MEASURE_BUDGET_S)
    if not have_floor():
        ((sol, wall),), count = timed_together((lambda: run(steps),), repeats)
        return {**_single_row(n, sc, sol, wall, steps, count), "floor_status": "numba is not installed"}
    fsteps = max(steps, _FLOOR_MIN_STEPS)
    # library and floor in alternating rounds, so that a slow spell of the machine hits both
    ((sol, wall), (_, fwall)), count = timed_together(
        (lambda: run(steps), lambda: _floor_run(n, sc.x0, sc.coeffs, sc.Gamma0, fsteps)),
        max(repeats, FLOOR_ROUNDS), FLOOR_BUDGET_S)
    row = _single_row(n, sc, sol, wall, steps, count)
    lib_state = (sc.vector(sol.Omega[-1]), sol.g[-1])
    same = _agreement(lib_state, _floor_run(n, sc.x0, sc.coeffs, sc.Gamma0, steps))
    floor_us = fwall / fsteps * 1e6
    return {**row, "floor_us_per_step": floor_us, "ratio": row["lib_us_per_step"] / floor_us, "agreement": same,
            "agrees": bool(same <= AGREEMENT_TOL), "floor_status": "ok"}


def _batch_state(batch: int) -> np.ndarray:
    """Initial angular velocities of the batch: the free body's w0, perturbed (seeded)."""
    w0 = floor_free_body().x0
    return w0 + 0.1 * np.random.default_rng(10).standard_normal((batch, 3))


def measure_batch(batch: int, steps: int, repeats: int, extra_kw: dict) -> dict:
    """Target (b): ``batch`` free bodies, n = 3, ``steps`` RKMK4 steps; ns per trajectory-step, agreement."""
    import liesuslov as ls

    sc = floor_free_body()
    W0 = _batch_state(batch)

    def run(k):
        return ls.integrate(sc.system, hat3(W0), (0.0, k * FLOOR_H), reconstruct=True, method="rkmk4", h=FLOOR_H,
                            t_eval=[k * FLOOR_H], **extra_kw)
    steps = affordable_steps(run, steps, MEASURE_BUDGET_S)
    ts = batch * steps

    def batch_row(sol, wall, count):
        return {"target": "b", "n": 3, "batch": batch, "steps": steps, "lib_ns_per_traj_step": wall / ts * 1e9,
                "repeats": count, "backend": sol.stats.get("backend", "numpy"),
                "status": "ok" if sol.success else "failed", "message": "" if sol.success else sol.message}
    if not have_floor():
        ((sol, wall),), count = timed_together((lambda: run(steps),), repeats)
        return {**batch_row(sol, wall, count), "floor_status": "numba is not installed"}
    from . import floor

    def floor_batch():
        W, G = W0.copy(), np.broadcast_to(np.eye(3), (batch, 3, 3)).copy()
        floor.free3_batch(W, G, sc.coeffs, FLOOR_H, steps)
        return W, G
    ((sol, wall), ((W, G), fwall)), count = timed_together((lambda: run(steps), floor_batch),
                                                           max(repeats, FLOOR_ROUNDS), FLOOR_BUDGET_S)
    row = batch_row(sol, wall, count)
    same = _agreement((sc.vector(sol.Omega[-1]), sol.g[-1]), (W, G))
    floor_ns = fwall / ts * 1e9
    return {**row, "floor_ns_per_traj_step": floor_ns, "ratio": row["lib_ns_per_traj_step"] / floor_ns,
            "agreement": same, "agrees": bool(same <= AGREEMENT_TOL), "floor_status": "ok"}


def _scipy_dense_nfev(sc) -> tuple[int, int]:
    """scipy's DOP853 on the default scene's embedded ODE (xi, vec g), Gamma = g^T gamma, at target (c)'s
    tolerances: (nfev with the 500 output times, nfev with the end point only). Its dense output is Hairer's
    7th-order extension too (three more evaluations on each step with an output inside): the same price."""
    from scipy.integrate import solve_ivp

    rhs = klebsh_tisserand_rhs(sc.coeffs)
    y0 = np.concatenate([sc.x0, np.eye(4).ravel()])  # g(0) = I: gamma = Gamma0

    def nfev(t_eval):
        sol = solve_ivp(rhs, (0.0, DENSE_T1), y0, method="DOP853", rtol=1e-10, atol=1e-12, t_eval=t_eval,
                        args=(sc.Gamma0,))
        return int(sol.nfev) if sol.success else -1
    return nfev(np.linspace(0.0, DENSE_T1, DENSE_POINTS)), nfev([DENSE_T1])


def measure_dense_output(extra_kw: dict) -> dict:
    """Target (c): nfev of the default scene with 500 output times over nfev with the end point only."""
    import liesuslov as ls

    sc = floor_klebsh_tisserand()

    def run(t_eval):
        return ls.integrate(sc.system, sc.Omega0, (0.0, DENSE_T1), Gamma0=sc.Gamma0, reconstruct=True,
                            method="rkmk853", rtol=1e-10, atol=1e-12, t_eval=t_eval, **extra_kw)
    dense = run(np.linspace(0.0, DENSE_T1, DENSE_POINTS))
    end = run([DENSE_T1])
    ok = dense.success and end.success
    scipy_dense, scipy_end = _scipy_dense_nfev(sc)
    scipy_ratio = scipy_dense / scipy_end if min(scipy_dense, scipy_end) > 0 else math.nan
    return {"target": "c", "nfev_dense": int(dense.stats["nfev"]), "nfev_end": int(end.stats["nfev"]),
            "steps_dense": int(dense.stats["steps"]), "steps_end": int(end.stats["steps"]),
            "ratio": dense.stats["nfev"] / end.stats["nfev"], "scipy_nfev_dense": scipy_dense,
            "scipy_nfev_end": scipy_end, "scipy_ratio": scipy_ratio,
            "end_difference": _agreement((dense.omega[-1], dense.g[-1]), (end.omega[-1], end.g[-1])),
            "status": "ok" if ok else "failed", "message": "" if ok else f"{dense.message}; {end.message}"}


_IMPORT_SCRIPT = "import time; t = time.perf_counter(); import liesuslov; print(time.perf_counter() - t)"
# The first compiled call a user makes: the default scene of `liesuslov run` on the compiled backend.
_COMPILE_SCRIPT = """import time
import numpy as np
import liesuslov as ls
I = np.array([1.0, 1.5, 2.0, 0.5]); B = np.array([4.0, 3.0, 2.5, 1.0])
system = ls.cases.klebsh_tisserand(I, B).system
Omega0 = np.zeros((4, 4)); Omega0[:3, 3] = [0.3, -0.2, 0.25]; Omega0[3, :3] = -Omega0[:3, 3]
Gamma0 = np.array([0.2, -0.4, 0.4, 0.8]); Gamma0 /= np.linalg.norm(Gamma0)
t = time.perf_counter()
sol = ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=Gamma0, reconstruct=True, method="rkmk853", rtol=1e-10,
                   atol=1e-12, backend="numba")
print(time.perf_counter() - t, sol.stats.get("backend"))
"""


def _child_seconds(script: str, timeout: float, **env: str) -> tuple[float, str]:
    """(seconds printed by ``script`` run in a fresh interpreter, rest of its line); NaN and the reason on failure."""
    try:
        res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=timeout,
                             env=child_env(**env), check=False)
    except subprocess.TimeoutExpired:
        return math.nan, f"time limit: not done in {timeout:.0f} s"
    if res.returncode != 0 or not res.stdout.strip():
        return math.nan, (res.stderr.strip().splitlines() or [f"exit status {res.returncode}"])[-1][:300]
    first, *rest = res.stdout.strip().splitlines()[-1].split()
    return float(first), " ".join(rest)


def _precompile_seconds(timeout: float) -> tuple[float, str]:
    """Wall seconds of the build's precompile step (``build_backend/``: every family, in parallel processes, into
    the precompiled directory), run on a copy of this package; NaN and the reason on failure."""
    from ..integrators.kernel.common import PRECOMPILED_ENV

    package = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory(prefix="liesuslov-precompile-") as tmp:
        shutil.copytree(package, Path(tmp, "src", package.name),
                        ignore=shutil.ignore_patterns("__pycache__", "_precompiled"))
        env = {**child_env(NUMBA_CACHE_DIR=str(Path(tmp, "numba")), **{PRECOMPILED_ENV: "write"}),
               "PYTHONPATH": str(Path(tmp, "src"))}
        start = time.perf_counter()
        try:
            # (in tmp: -m puts the working directory first on the path, which may hold another liesuslov)
            res = subprocess.run([sys.executable, "-m", "liesuslov.integrators.kernel.warm"], capture_output=True,
                                 text=True, timeout=timeout, env=env, cwd=tmp, check=False)
        except subprocess.TimeoutExpired:
            return math.nan, f"time limit: not done in {timeout:.0f} s"
    if res.returncode != 0:
        return math.nan, (res.stderr.strip().splitlines() or [f"exit status {res.returncode}"])[-1][:300]
    return time.perf_counter() - start, ""


def measure_cold_start(compile_first_call: bool, timeout: float, repeats: int = 3) -> dict:
    """Target (f): ``import liesuslov`` in fresh processes (the fastest of ``repeats``) and, if asked, the first
    compiled call in a fresh process with an empty numba cache — as installed (``precompiled``: whether it loaded
    the kernel the build compiled, i.e. compiled nothing into numba's cache), with the precompiled kernel
    switched off (the compilation itself, then the next process loading numba's cache), and the build's
    precompile step itself (what the installation paid)."""
    from ..integrators.kernel.common import PRECOMPILED_ENV

    imports = [_child_seconds(_IMPORT_SCRIPT, timeout)[0] for _ in range(repeats)]
    row = {"target": "f", "import_s": min(imports), "import_runs": len(imports)}
    if not compile_first_call:
        return {**row, "compile_status": "not measured (--quick)"}
    if not have_floor():
        return {**row, "compile_status": "numba is not installed"}
    with (tempfile.TemporaryDirectory(prefix="liesuslov-numba-cache-") as installed,
          tempfile.TemporaryDirectory(prefix="liesuslov-numba-cache-") as own):
        first, why = _child_seconds(_COMPILE_SCRIPT, timeout, NUMBA_CACHE_DIR=installed)
        precompiled = math.isfinite(first) and not any(Path(installed).rglob("loop._solve_one-*.nbi"))
        off = {PRECOMPILED_ENV: "off"}
        if precompiled:  # the compilation itself, in another empty cache
            cold, why2 = _child_seconds(_COMPILE_SCRIPT, timeout, NUMBA_CACHE_DIR=own, **off)
        else:  # the first call compiled already
            cold, why2, own = first, why, installed
        warm, why3 = _child_seconds(_COMPILE_SCRIPT, timeout, NUMBA_CACHE_DIR=own, **off)
    build, why4 = _precompile_seconds(timeout)
    failed = [w for x, w in ((first, why), (cold, why2), (warm, why3), (build, why4)) if not math.isfinite(x)]
    return {**row, "first_call_s": first, "precompiled": precompiled, "first_call_compiling_s": cold,
            "first_call_cached_s": warm, "precompile_s": build,
            "compile_status": f"failed: {failed[0]}" if failed else "ok", "compiled_backend": why if not failed else ""}


def run_targets(config, extra_kw: dict, tick: Callable[[], None]) -> list[dict]:
    """Measure targets (a), (b), (c) and (f) (rows of :func:`measure_single` etc.); (d), (e) come from the sweeps."""
    rows = []
    for n in (3, 4):
        rows.append(_safe(lambda n=n: measure_single(n, config.target_steps, config.repeats, extra_kw),
                          {"target": "a", "n": n}))
        tick()
    rows.append(_safe(lambda: measure_batch(config.target_batch, config.target_batch_steps, config.repeats, extra_kw),
                      {"target": "b", "n": 3, "batch": config.target_batch}))
    tick()
    rows.append(_safe(lambda: measure_dense_output(extra_kw), {"target": "c"}))
    tick()
    # A cold compilation on a loaded machine can take minutes (issue 10 saw 48 s): a longer limit than a measurement.
    rows.append(_safe(lambda: measure_cold_start(config.cold_compile, 4 * config.isolated_timeout,
                                                      config.import_runs), {"target": "f"}))
    tick()
    return rows


def _safe(measure: Callable[[], dict], head: dict) -> dict:
    """A measurement's row, or ``head`` with a failed status naming the exception (one target never stops the rest)."""
    try:
        return measure()
    except (ValueError, RuntimeError, MemoryError, np.linalg.LinAlgError) as exc:
        return {**head, "status": "failed", "message": f"{type(exc).__name__}: {exc}"}


def summary(target_rows: list[dict], scaling_exponent: dict, scaling: list[dict], ratios: list[dict]) -> list[dict]:
    """One row per target: what, the measured ratio (or seconds), the goal and whether it is met."""
    by = {(r["target"], r.get("n")): r for r in target_rows}
    out = []

    def add(key: str, what: str, value: float, goal: float, detail: str, met: bool | None = None,
            why: str = "") -> None:
        if met is None:
            met = bool(value <= goal) if np.isfinite(value) else None  # None: not measured
        if not np.isfinite(value):
            why = why or "not measured"
        out.append({"target": key, "what": what, "value": value, "goal": goal, "met": met, "detail": detail,
                    "why": why if not np.isfinite(value) else ""})

    for n in (3, 4):
        r = by.get(("a", n), {})
        add(f"a (n = {n})", f"one trajectory, n = {n}, RKMK4 + g, h = {FLOOR_H}: library / floor per step",
            r.get("ratio", math.nan), GOALS["a"],
            f"{_num(r.get('lib_us_per_step'))} µs vs {_num(r.get('floor_us_per_step'), '.3g')} µs per step "
            f"({r.get('backend', '?')}, {r.get('steps', '?')} steps); floor = library to "
            f"{_num(r.get('agreement'), '.1e')}" + _status(r), why=_why(r))
    r = by.get(("b", 3), {})
    add("b", f"batch of {r.get('batch', '?')}, n = 3: library / single-threaded floor per trajectory-step",
        r.get("ratio", math.nan), GOALS["b"],
        f"{_num(r.get('lib_ns_per_traj_step'))} ns vs {_num(r.get('floor_ns_per_traj_step'))} ns "
        f"({r.get('backend', '?')}); floor = library to {_num(r.get('agreement'), '.1e')}" + _status(r), why=_why(r))
    r = by.get(("c", None), {})
    add("c", f"adaptive, {DENSE_POINTS} output times: nfev / nfev of the end point only", r.get("ratio", math.nan),
        GOALS["c"], f"{r.get('nfev_dense', '?')} vs {r.get('nfev_end', '?')} evaluations, {r.get('steps_dense', '?')} "
        f"vs {r.get('steps_end', '?')} steps (rkmk853, rtol 1e-10, default scene); scipy DOP853 on the embedded ODE: "
        f"{_num(r.get('scipy_ratio'), '.3g')} ({r.get('scipy_nfev_dense', '?')} vs {r.get('scipy_nfev_end', '?')})"
        + _status(r), why=_why(r))
    fit = scaling_exponent.get("numba/exp") or scaling_exponent.get("exp")
    ran = [x for x in scaling if x.get("requested") == "numba" and x.get("chart") == "exp" and x.get("status") == "ok"]
    nmax = max((x["n"] for x in ran), default=None)
    reached = nmax is not None and nmax >= 256
    add("d", "Fedorov–Kozlov + g, backend numba, to n = 256: exponent of the cost per step",
        fit["exponent"] if fit else math.nan, GOALS["d"],
        (f"fit over n = {fit['sizes']}, slope between the two largest {fit['last_slope']:.2f}; " if fit else
         "no fit; ") + f"largest n on numba: {nmax or '—'}; met when ≤ {GOALS['d'] + D_MARGIN:g} (n², not n³)",
        met=bool(reached and fit["exponent"] <= GOALS["d"] + D_MARGIN) if fit else None,
        why=("numba is not installed" if not have_floor() else
             "fewer than two sizes ran on numba" if any(x.get("requested") == "numba" for x in scaling) else
             "the n-sweep ran on numpy only (--quick or --backend numpy)"))
    finite = [x for x in ratios if np.isfinite(x.get("ratio_dop853", math.nan))]
    worst = max(finite, key=lambda x: x["ratio_dop853"], default=None)
    add("e", "work-precision: fastest liesuslov / scipy DOP853 at equal error, worst of 1e-5 … 1e-10",
        worst["ratio_dop853"] if worst else math.nan, GOALS["e"],
        (f"worst at {worst['scene']} {worst['level']:.0e}; best "
         f"{min(x['ratio_dop853'] for x in finite):.3f}" + _adaptive_only(ratios) if worst else
         "no level reached by both"),
        why="no error level reached by both liesuslov and scipy")
    r = by.get(("f", None), {})
    add("f (import)", "`import liesuslov` in a fresh process (s)", r.get("import_s", math.nan), GOALS["f-import"],
        f"fastest of {r.get('import_runs', '?')} processes" + _status(r), why=_why(r))
    loaded = ("loaded the kernel compiled at install (the build's precompile step: every family, in parallel "
              f"processes, {_num(r.get('precompile_s'), '.3g')} s)" if r.get("precompiled") else
              "no kernel compiled at install beside the package (installed with LIESUSLOV_PRECOMPILE=0, or kernel "
              "sources changed since): compiled it")
    add("f (compile)", "first compiled call after install, fresh process, empty numba cache (s)",
        r.get("first_call_s", math.nan), GOALS["f-compile"],
        f"{loaded}; compiling it in the call instead (LIESUSLOV_PRECOMPILED=off): "
        f"{_num(r.get('first_call_compiling_s'), '.3g')} s, then {_num(r.get('first_call_cached_s'))} s in the next "
        f"process (numba's cache); {r.get('compile_status', '')}", why=r.get("compile_status") or _why(r))
    return out


def _adaptive_only(ratios: list[dict]) -> str:
    """Target (e) for liesuslov's adaptive routes alone (the fastest routes are often fixed-step ones, whose step
    sweep is set per scene): the worst ratio to scipy's DOP853 and where."""
    finite = [x for x in ratios if np.isfinite(x.get("ratio_adaptive", math.nan))]
    if not finite:
        return ""
    w = max(finite, key=lambda x: x["ratio_adaptive"])
    return (f"; adaptive routes only (rtol sweeps, as scipy's): worst {w['ratio_adaptive']:.3f} at {w['scene']} "
            f"{w['level']:.0e} ({w['adaptive_route']})")


def _num(x, spec: str = ".4g") -> str:
    """A number for the detail column, a dash when missing."""
    return format(float(x), spec) if isinstance(x, (int, float, np.floating)) and np.isfinite(x) else "—"


def _why(r: dict) -> str:
    """Why a target has no value (its measurement failed, or the floor could not run), for the console."""
    bad = [str(r[k]) for k in ("status", "floor_status") if r.get(k) not in (None, "ok")]
    return "; ".join(bad + ([r["message"]] if r.get("message") else []))


def _status(r: dict) -> str:
    """What went wrong in a measurement, for the detail column (empty when all is well)."""
    bad = [r[k] for k in ("status", "floor_status") if r.get(k) not in (None, "ok")]
    return f"; {'; '.join(str(b) for b in bad)}{': ' + r['message'] if r.get('message') else ''}" if bad else ""
