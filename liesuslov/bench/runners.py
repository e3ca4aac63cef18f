"""The measurements: the reference runs, the work-precision sweeps of both libraries, the batch
throughput, the cost per step against n and the long run."""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .config import (
    ADAPTIVE,
    ATOL_FACTOR,
    FIXED_FACTORS,
    REF_ATOL,
    REF_RTOL,
    TOLERANCES,
    BenchConfig,
    has_backend_option,
)
from .metrics import Reference, max_abs, nan_row, run_metrics
from .scenes import BenchScene, scaling_scene, throughput_case
from .timing import ISOLATE_BATCH, ISOLATE_N, affordable_steps, guarded, timed, timed_together

#: Seconds one call of a throughput measurement may take (fewer steps beyond).
THROUGHPUT_BUDGET_S = 3.0
#: Seconds the long run may take: a path slower than that (numpy) is reported as skipped.
LONG_RUN_BUDGET_S = 120.0


def _run_liesuslov(scene: BenchScene, method: str, chart: str, kind: str, value: float, extra_kw: dict):
    """One liesuslov run of a scene at step ``value`` (kind "h") or rtol ``value``."""
    import liesuslov as ls

    kw: dict = {"h": value} if kind == "h" else {"rtol": value, "atol": ATOL_FACTOR * value}
    return ls.integrate(scene.system, scene.omega0, (0.0, scene.t1), Gamma0=scene.Gamma0,
                        reconstruct=scene.reconstruct, method=method, chart=chart, **kw, **extra_kw)


def _run_scipy(scene: BenchScene, method: str, rtol: float):
    """One scipy ``solve_ivp`` run of a scene's embedded ODE."""
    from scipy.integrate import solve_ivp

    return solve_ivp(scene.rhs, (0.0, scene.t1), scene.y0, method=method, rtol=rtol, atol=ATOL_FACTOR * rtol)


def trajectory_liesuslov(sol) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(omega (N, d), Gamma or None, g or None) of a liesuslov solution."""
    om = sol.omega.reshape(sol.omega.shape[0], -1)
    return om, sol.Gamma, sol.g


def trajectory_scipy(scene: BenchScene, sol) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(omega (N, d), Gamma or None, g or None) of a scipy solution, through the scene's unpacker."""
    return scene.unpack(np.ascontiguousarray(sol.y.T))


def build_reference(scene: BenchScene, extra_kw: dict) -> Reference:
    """Two independent high-accuracy runs and the closed form where there is one; their spread."""
    import liesuslov as ls

    lie = ls.integrate(scene.system, scene.omega0, (0.0, scene.t1), Gamma0=scene.Gamma0,
                       reconstruct=scene.reconstruct, method="rkmk853", chart="exp", rtol=REF_RTOL,
                       atol=REF_ATOL, **extra_kw)
    if not lie.success:
        raise RuntimeError(f"{scene.key}: the liesuslov reference run failed: {lie.message}")
    from scipy.integrate import solve_ivp

    sp = solve_ivp(scene.rhs, (0.0, scene.t1), scene.y0, method="DOP853", rtol=REF_RTOL, atol=REF_ATOL)
    if not sp.success:
        raise RuntimeError(f"{scene.key}: the scipy reference run failed: {sp.message}")
    lo, lG, lg = (a[-1] if a is not None else None for a in trajectory_liesuslov(lie))
    so_, sG, sg = (a[-1] if a is not None else None for a in trajectory_scipy(scene, sp))
    details = {"liesuslov vs scipy (Omega)": max_abs(lo, so_)}
    if lG is not None:
        details["liesuslov vs scipy (Gamma)"] = max_abs(lG, sG)
    if lg is not None:
        details["liesuslov vs scipy (g)"] = max_abs(lg, sg)
    # Without a closed form: the mean of the two independent runs (no swept run coincides with it).
    omega = 0.5 * (lo + so_)
    Gamma = None if lG is None else 0.5 * (lG + sG)
    g = None if lg is None else 0.5 * (lg + sg)
    if scene.analytic is not None:
        an = scene.analytic()
        if "omega" in an:
            details["closed form vs numeric (Omega)"] = max(max_abs(an["omega"], lo), max_abs(an["omega"], so_))
            omega = np.asarray(an["omega"], dtype=float)
        if "Gamma" in an and lG is not None:
            details["closed form vs numeric (Gamma)"] = max(max_abs(an["Gamma"], lG), max_abs(an["Gamma"], sG))
            Gamma = np.asarray(an["Gamma"], dtype=float)
    extra: dict = {}
    if scene.extra is not None and scene.extra_ref is not None:
        extra = {k: np.asarray(v, dtype=float) for k, v in scene.extra_ref().items()}
        for name, (a, b) in {"liesuslov": (lo, lg), "scipy": (so_, sg)}.items():
            got = scene.extra(a, None, b)
            details[f"closed form vs {name} ({', '.join(extra)})"] = max(max_abs(got[k], extra[k]) for k in extra)
    unc = max(details.values())
    return Reference(omega, Gamma, g, extra, unc, details)


@dataclass(frozen=True)
class _Task:
    """One work-precision run to make: a route (library, method, chart) at one setting (h or rtol)."""

    scene: str
    library: str
    method: str
    chart: str
    kind: str
    value: float

    @property
    def route(self) -> str:
        if self.library == "scipy":
            return f"scipy {self.method}"
        return f"liesuslov {self.method}" + (f"/{self.chart}" if self.chart != "-" else "")


def _spread(values: Sequence[float], k: int | None) -> tuple[float, ...]:
    """At most k values evenly spread over the sequence (ends kept)."""
    if k is None or len(values) <= k:
        return tuple(values)
    if k == 1:
        return (values[len(values) // 2],)
    idx = np.unique(np.round(np.linspace(0, len(values) - 1, k)).astype(int))
    return tuple(values[i] for i in idx)


def plan_tasks(config: BenchConfig, scene: BenchScene) -> list[_Task]:
    """Every run of a scene's sweep: each liesuslov method × chart, then each scipy method."""
    import liesuslov as ls

    tasks = []
    fixed_f = config.fixed_factors if config.fixed_factors is not None else FIXED_FACTORS
    tols = config.tolerances if config.tolerances is not None else TOLERANCES
    charts = config.charts if scene.has_group else ("-",)
    for method in config.methods or ():
        adaptive = bool(getattr(ls.METHODS[method], "adaptive", method in ADAPTIVE))
        for chart in charts:
            if adaptive:
                for tol in _spread(tols.get(method, ()), config.max_settings):
                    tasks.append(_Task(scene.key, "liesuslov", method, chart, "rtol", float(tol)))
            else:
                for f in _spread(fixed_f.get(method, ()), config.max_settings):
                    N = max(1, int(round(f * scene.n_base)))
                    tasks.append(_Task(scene.key, "liesuslov", method, chart, "h", scene.t1 / N))
    for method in config.scipy_methods:
        for tol in _spread(tols.get(method, ()), config.max_settings):
            tasks.append(_Task(scene.key, "scipy", method, "-", "rtol", float(tol)))
    return tasks


def execute_tasks(tasks: Sequence[_Task], scene: BenchScene, ref: Reference, repeats: int, extra_kw: dict,
                  tick: Callable[[_Task], None] = lambda task: None) -> list[dict]:
    """Time a scene's runs and measure them against the reference: rows of ``results.csv`` (failures recorded).

    Every run is made once (the warm-up, whose result is measured; a run that raises is a failed row), then
    the working runs of both libraries are timed together in rounds, each round calling each run once
    (:func:`~.timing.timed_together`): a slow spell of the shared machine lasting seconds slows both
    libraries' runs alike instead of whichever was being timed then (scipy's time for one run of the same
    scene once varied 0.76–1.35 ms between two benchmark runs timed one run after the other).
    """
    errors = (ValueError, RuntimeError, FloatingPointError, MemoryError, np.linalg.LinAlgError)
    rows, fns, sols, live = [], [], [], []
    for task in tasks:
        row: dict = {"scene": task.scene, "library": task.library, "route": task.route, "method": task.method,
                     "chart": task.chart, "setting_kind": task.kind, "setting": task.value, "t_final": scene.t1,
                     "ref_uncertainty": ref.uncertainty}
        chart = "exp" if task.chart == "-" else task.chart
        if task.library == "liesuslov":
            fn = functools.partial(_run_liesuslov, scene, task.method, chart, task.kind, task.value, extra_kw)
        else:
            fn = functools.partial(_run_scipy, scene, task.method, task.value)
        try:
            sol = fn()
        except errors as exc:
            row.update(nan_row(), wall_time=float("nan"), repeats=0, status="failed",
                       message=f"{type(exc).__name__}: {exc}", backend="")
        else:
            fns.append(fn)
            sols.append(sol)
            live.append(len(rows))
        rows.append(row)
        tick(task)
    timings, count = timed_together(tuple(fns), repeats, warmed=sols) if fns else ([], 0)
    for i, (sol, wall) in zip(live, timings, strict=True):
        task, row = tasks[i], rows[i]
        if task.library == "liesuslov":
            row.update(backend=sol.stats.get("backend", "numpy"), nfev=sol.stats.get("nfev"),
                       steps=sol.stats.get("steps"), rejected=sol.stats.get("rejected"))
            traj = trajectory_liesuslov(sol)
        else:
            row.update(backend="scipy", nfev=sol.nfev, steps=len(sol.t) - 1, rejected="")
            traj = trajectory_scipy(scene, sol)
        ok = bool(sol.success)
        row.update(wall_time=wall, repeats=count, status="ok" if ok else "failed", message=str(sol.message))
        try:
            with np.errstate(all="ignore"):
                row.update(run_metrics(scene, ref, *traj) if ok else nan_row())
        except errors as exc:
            row.update(nan_row(), status="failed", message=f"{type(exc).__name__}: {exc}")
    return rows


def measure_throughput(n: int, batch: int, steps: int, repeats: int, extra_kw: dict) -> dict:
    """RKMK4 with reconstruction on a batch of random initial data in D: the timing row."""
    import liesuslov as ls

    h = 0.01
    case = throughput_case(n)
    omega, Gamma = case.random_state(np.random.default_rng(batch), batch=(batch,), scale=0.5)

    def run(steps):
        return ls.integrate(case.system, omega, (0.0, steps * h), Gamma0=Gamma, reconstruct=True, method="rkmk4",
                            h=h, t_eval=[steps * h], **extra_kw)
    steps = affordable_steps(run, steps, THROUGHPUT_BUDGET_S)
    sol, wall, count = timed(lambda: run(steps), repeats)
    ts = batch * steps
    return {"steps": steps, "wall_time": wall, "repeats": count, "backend": sol.stats.get("backend", "numpy"),
            "traj_steps_per_s": ts / wall, "ns_per_traj_step": wall / ts * 1e9, "us_per_step": wall / steps * 1e6,
            "status": "ok" if sol.success else "failed", "message": "" if sol.success else sol.message}


def measure_scaling(n: int, chart: str, repeats: int, extra_kw: dict) -> dict:
    """RKMK4 with reconstruction on SO(n), Klebsh–Tisserand with the Fedorov–Kozlov D: the timing row."""
    import liesuslov as ls

    h = 0.01
    system, Omega0, Gamma0 = scaling_scene(n)

    def run(steps):
        return ls.integrate(system, Omega0, (0.0, steps * h), Gamma0=Gamma0, reconstruct=True, method="rkmk4",
                            chart=chart, h=h, t_eval=[steps * h], **extra_kw)
    run(1)  # compiles / warms caches
    start = time.perf_counter()
    run(2)
    probe = (time.perf_counter() - start) / 2
    steps = int(min(200, max(3, 0.3 / max(probe, 1e-9))))
    sol, wall, count = timed(lambda: run(steps), repeats)
    if not sol.success:
        raise RuntimeError(sol.message)
    g = sol.g[-1]
    return {"steps": steps, "wall_time": wall, "repeats": count, "us_per_step": wall / steps * 1e6,
            "backend": sol.stats.get("backend", "numpy"), "form": sol.stats.get("form", ""),
            "orth_defect": float(np.max(np.abs(g.T @ g - np.eye(n)))), "status": "ok", "message": ""}


def throughput_sweep(config: BenchConfig, extra_kw: dict, tick: Callable[[], None]) -> list[dict]:
    """The batch-throughput rows: each n of ``batch_dims`` × each size of ``batch_sizes``."""
    rows = []
    work = config.throughput_work
    for n in config.batch_dims:
        for batch in config.batch_sizes:
            steps = int(min(1000, max(5, round(work / batch))))
            row: dict = {"n": n, "scene": "Lagrange" if n == 3 else "Klebsh–Tisserand", "batch": int(batch),
                         "steps": steps, "method": "rkmk4", "chart": "exp"}
            kwargs = {"n": n, "batch": int(batch), "steps": steps, "repeats": config.repeats, "extra_kw": extra_kw}
            row.update(guarded(measure_throughput, kwargs,
                                isolate=batch > ISOLATE_BATCH, timeout=config.isolated_timeout))
            rows.append(row)
            tick()
    return rows


def scaling_backends(config: BenchConfig) -> tuple[str | None, ...]:
    """Backends of the n-scaling sweep: the configured one, else numpy and the compiled one (numba, target (d))."""
    if config.backend is not None or not has_backend_option():
        return (config.backend,)
    from .targets import have_floor

    # Asked for by name, not "auto": target (d) is the compiled path's growth, and a fallback to numpy
    # would hide where it stops (the row records the reason instead).
    return ("numpy", "numba") if have_floor() else ("numpy",)


def scaling_sweep(config: BenchConfig, extra_kw: dict, tick: Callable[[], None]) -> list[dict]:
    """The cost-per-step rows: backend × chart × n; after a size fails, the larger ones are skipped."""
    rows = []
    for backend in scaling_backends(config):
        kw = dict(extra_kw) if backend is None else {**extra_kw, "backend": backend}
        for chart in config.charts:
            stop = ""
            for n in config.scaling_sizes:
                row: dict = {"n": int(n), "chart": chart, "requested": backend or "default", "method": "rkmk4",
                             "h": 0.01}
                if stop:
                    row.update(status="skipped", message=stop)
                else:
                    row.update(guarded(measure_scaling, {"n": int(n), "chart": chart, "repeats": config.repeats,
                                                    "extra_kw": kw},
                                        isolate=n > ISOLATE_N, timeout=config.isolated_timeout))
                    if row.get("status") != "ok":
                        stop = f"after n = {n} failed"
                rows.append(row)
                tick()
    return rows


def long_run(config: BenchConfig, extra_kw: dict, tick: Callable[[], None]) -> list[dict]:
    """One trajectory of ``long_run_steps`` RKMK4 steps: wall time, structure and energy error."""
    import liesuslov as ls

    if not config.long_run_steps:
        return []
    steps = int(config.long_run_steps)
    h = 0.01
    t1 = steps * h
    case = throughput_case(3)
    omega, Gamma = case.random_state(np.random.default_rng(7), scale=0.5)
    row: dict = {"scene": "Lagrange n = 3", "method": "rkmk4", "chart": "exp", "h": h, "steps": steps, "t_final": t1}

    def run(k):
        return ls.integrate(case.system, omega, (0.0, k * h), Gamma0=Gamma, reconstruct=True, method="rkmk4", h=h,
                            t_eval=[k * h], **extra_kw)
    try:
        probe_steps = 1000
        affordable = affordable_steps(run, steps, LONG_RUN_BUDGET_S, minimum=probe_steps)
        if affordable < steps:
            row.update(status="skipped", message=f"projected over {LONG_RUN_BUDGET_S:.0f} s on this backend "
                                                 f"({affordable} steps would fit)")
            tick()
            return [row]
        start = time.perf_counter()
        sol = ls.integrate(case.system, omega, (0.0, t1), Gamma0=Gamma, reconstruct=True, method="rkmk4", h=h,
                           t_eval=np.linspace(0.0, t1, 101), **extra_kw)
        wall = time.perf_counter() - start
        g = sol.g
        E = case.integrals["energy"](sol.omega, sol.Gamma)
        row.update(wall_time=wall, us_per_step=wall / steps * 1e6, backend=sol.stats.get("backend", "numpy"),
                   orth_defect=float(np.max(np.abs(np.swapaxes(g, -1, -2) @ g - np.eye(3)))),
                   sphere_defect=float(np.max(np.abs(np.linalg.norm(sol.Gamma, axis=-1) - 1.0))),
                   energy0=float(E[0]), energy_error=float(np.max(np.abs(E - E[0]))),
                   status="ok" if sol.success else "failed", message="" if sol.success else sol.message)
    except (MemoryError, ValueError, RuntimeError) as exc:
        row.update(status="failed", message=f"{type(exc).__name__}: {exc}")
    tick()
    return [row]
