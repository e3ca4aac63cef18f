"""What the benchmark measures: the error levels, the sweeps, the presets (:class:`BenchConfig`) and the
container of what was measured (:class:`BenchReport`)."""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field, replace

import numpy as np

from .scenes import SCENES, scene_key

#: Error levels of the ratio table.
LEVELS: tuple[float, ...] = (1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)

#: The goal for the ratio liesuslov / scipy at every level (issue 10, compiled; reported, not asserted).
GOAL_RATIO = 0.1

#: Tolerances of the two independent high-accuracy reference runs (10x tighter than any swept run).
REF_RTOL, REF_ATOL = 1e-13, 1e-15

#: atol = ATOL_FACTOR * rtol in every adaptive run (both libraries).
ATOL_FACTOR = 1e-2

#: Timed repeats of one setting stop once their total exceeds this many seconds (at least one).
REPEAT_BUDGET_S = 0.6

#: The adaptive methods (the others are swept over step sizes).
ADAPTIVE = ("rkmk23", "rkmk45", "rkmk853")

SCIPY_METHODS = ("RK45", "DOP853", "Radau")

# Fixed-step sweeps: step counts as multiples of a scene's n_base (rkmk4 with n_base steps errs by ~1e-7).
FIXED_FACTORS: dict[str, tuple[float, ...]] = {
    "lie-euler": (1, 4, 16),
    "rkmk2": (0.5, 1, 2, 4, 8),
    "rkmk-heun": (0.5, 1, 2, 4, 8),
    "rkmk3": (0.5, 1, 2, 4, 8),
    "rkmk4": (0.25, 0.5, 1, 2, 4, 8),
    "rkmk5": (0.125, 0.25, 0.5, 1, 2, 4),
    "rkmk8": (0.0625, 0.125, 0.25, 0.5, 1),
}

TOLERANCES: dict[str, tuple[float, ...]] = {
    "rkmk23": tuple(10.0 ** -k for k in range(3, 9)),
    "rkmk45": tuple(10.0 ** -k for k in range(3, 12)),
    "rkmk853": tuple(10.0 ** -k for k in range(2, 13)),
    "RK45": tuple(10.0 ** -k for k in range(3, 12)),
    "DOP853": tuple(10.0 ** -k for k in range(2, 13)),
    "Radau": tuple(10.0 ** -k for k in range(3, 10)),
}

#: The sweeps of the quick preset.
QUICK_FIXED = {"rkmk4": (0.5, 2, 8)}

QUICK_TOL = {"rkmk45": (1e-5, 1e-7, 1e-9), "rkmk853": (1e-6, 1e-9, 1e-12), "RK45": (1e-5, 1e-7, 1e-9),
              "DOP853": (1e-6, 1e-9, 1e-12), "Radau": (1e-4, 1e-6, 1e-8)}

RESULT_COLUMNS = ("scene", "library", "route", "method", "chart", "backend", "setting_kind", "setting",
                  "t_final", "wall_time", "repeats", "nfev", "steps", "rejected", "status", "message",
                  "err_Omega", "err_Gamma", "err_g", "err_pendulum", "error", "orth_defect", "sphere_defect",
                  "constraint_defect", "drift_energy", "drift_integrals", "drifts", "ref_uncertainty")


@dataclass(frozen=True)
class BenchConfig:
    """What :func:`run_bench` measures. :meth:`full` and :meth:`quick` are the two presets.

    Attributes
    ----------
    scenes : tuple of str
        Keys of :data:`SCENES`.
    methods : tuple of str or None
        liesuslov methods (None: every key of ``liesuslov.METHODS``).
    charts : tuple of str
    scipy_methods : tuple of str
    fixed_factors : dict or None
        Step counts per fixed method as multiples of the scene's ``n_base`` (None: the full sweeps).
    tolerances : dict or None
        rtol values per adaptive / scipy method (None: the full sweeps); ``atol = 1e-2 rtol``.
    max_settings : int or None
        Keep at most this many settings per route (evenly spread over the sweep).
    repeats : int
        Timed repeats after the warm-up (fewer once their total passes ``REPEAT_BUDGET_S``).
    batch_sizes : tuple of int
        Batch throughput (empty: skipped).
    throughput_work : int
        Trajectory-steps per throughput measurement (steps = work / batch, 5 to 1000).
    batch_dims : tuple of int
        n of the throughput scenes (3: Lagrange, 4: Klebsh–Tisserand).
    scaling_sizes : tuple of int
        n of the per-step cost sweep (empty: skipped).
    long_run_steps : int
        Steps of the long run (0: skipped).
    plots : bool
    levels : tuple of float
        Error levels of the ratio table.
    backend : str or None
        Passed to ``integrate(..., backend=...)`` when given (needs a liesuslov that has it).
    isolated_timeout : float
        Time limit (s) of a measurement run in a child process (n > 64, batch > 1e4); past it the
        size is recorded as failed and the larger ones are skipped.
    targets : bool
        Measure the targets of issue 10 (:mod:`.targets`): the floor comparisons, the dense-output
        evaluations and the cold start.
    target_steps : int
        Steps of the one-trajectory floor comparison (h = 0.005).
    target_batch, target_batch_steps : int
        Size and steps of the batch floor comparison.
    import_runs : int
        Fresh processes timing ``import liesuslov`` (the fastest counts).
    cold_compile : bool
        Also time the first compiled call in fresh processes with an empty numba cache (as installed, and
        compiling the kernel itself) and the build's precompile step.
    preset : str
        ``"full"``, ``"quick"`` or a name of your own (reported).
    """

    scenes: tuple[str, ...] = tuple(SCENES)
    methods: tuple[str, ...] | None = None
    charts: tuple[str, ...] = ("exp", "cayley")
    scipy_methods: tuple[str, ...] = SCIPY_METHODS
    fixed_factors: dict | None = None
    tolerances: dict | None = None
    max_settings: int | None = None
    repeats: int = 5
    batch_sizes: tuple[int, ...] = (1, 10, 100, 1000, 10_000, 100_000)
    throughput_work: int = 1_000_000
    batch_dims: tuple[int, ...] = (3, 4)
    scaling_sizes: tuple[int, ...] = (3, 4, 8, 16, 32, 64, 128, 256)
    long_run_steps: int = 1_000_000
    plots: bool = True
    levels: tuple[float, ...] = LEVELS
    backend: str | None = None
    isolated_timeout: float = 150.0
    targets: bool = True
    target_steps: int = 20_000
    target_batch: int = 10_000
    target_batch_steps: int = 100
    import_runs: int = 3
    cold_compile: bool = True
    preset: str = "full"

    @classmethod
    def full(cls, **overrides) -> BenchConfig:
        """Every method × chart over the full sweeps, batches up to 1e5, n up to 256, the long run."""
        return cls(**overrides)

    @classmethod
    def quick(cls, **overrides) -> BenchConfig:
        """rkmk4, rkmk45, rkmk853 × exp/cayley and the three scipy methods at 3 settings; no long run, short
        floor comparisons, batches of at most 100 (the minute's budget on the numpy path), no cold
        compilation.

        Runs the numpy path (``backend="numpy"`` where ``integrate`` has the option): the one-off
        compilation of an optional kernel (20–60 s on a cold cache) would not fit in the minute.
        """
        base = dict(methods=("rkmk4", "rkmk45", "rkmk853"), fixed_factors=dict(QUICK_FIXED),
                    tolerances=dict(QUICK_TOL), repeats=1, batch_sizes=(1, 10, 100), throughput_work=5000,
                    scaling_sizes=(3, 4, 8, 16, 32, 64), long_run_steps=0, preset="quick", target_steps=2000,
                    target_batch=100, target_batch_steps=10, cold_compile=False,
                    backend="numpy" if has_backend_option() else None)
        return cls(**{**base, **overrides})

    def validated(self) -> BenchConfig:
        """The configuration with names normalised; ValueError naming what is wrong."""
        import liesuslov as ls

        scenes = tuple(scene_key(s) for s in self.scenes)
        if not scenes:
            raise ValueError(f"scenes must name at least one scene; valid scenes: {', '.join(SCENES)}")
        methods = tuple(ls.METHODS) if self.methods is None else tuple(self.methods)
        bad = [m for m in methods if m not in ls.METHODS]
        if bad:
            raise ValueError(f"unknown method(s) {bad}; valid methods: {', '.join(ls.METHODS)}")
        bad = [c for c in self.charts if c not in ("exp", "cayley")]
        if bad or not self.charts:
            raise ValueError(f"charts must be a non-empty subset of ('exp', 'cayley'), got {self.charts}")
        bad = [m for m in self.scipy_methods if m not in TOLERANCES]
        if bad:
            raise ValueError(f"unknown scipy method(s) {bad}; valid: {', '.join(SCIPY_METHODS)}")
        if isinstance(self.repeats, bool) or not isinstance(self.repeats, (int, np.integer)) or self.repeats < 1:
            raise ValueError(f"repeats must be an integer >= 1, got {self.repeats!r}")
        if self.max_settings is not None and self.max_settings < 1:
            raise ValueError(f"max_settings must be >= 1 or None, got {self.max_settings!r}")
        if any(int(b) < 1 for b in self.batch_sizes) or any(int(n) < 3 for n in self.scaling_sizes):
            raise ValueError("batch_sizes must be >= 1 and scaling_sizes >= 3")
        bad = [n for n in self.batch_dims if n not in (3, 4)]
        if bad:
            raise ValueError(f"batch_dims must be 3 (Lagrange) or 4 (Klebsh–Tisserand), got {bad}")
        return replace(self, scenes=scenes, methods=methods, repeats=int(self.repeats))


@dataclass
class BenchReport:
    """What :func:`run_bench` measured and wrote.

    Attributes
    ----------
    rows : list of dict
        One per work-precision run (columns :data:`RESULT_COLUMNS`).
    ratios : list of dict
        The ratio table: scene, level, fastest liesuslov and scipy routes and times, ratio.
    throughput, scaling, longrun : list of dict
    targets : list of dict
        The measurements of issue 10's targets (:func:`.targets.run_targets`).
    target_summary : list of dict
        One row per target: what, value, goal, met, detail (:func:`.targets.summary`).
    scaling_exponent : dict
        ``"backend/chart"`` (or chart) -> fitted exponent p of ``time per step ~ n^p`` over the three
        largest sizes that ran, with the sizes used.
    references : dict
        Scene key -> ``{"uncertainty": float, "how": str, "title": str, "t1": float}``.
    machine : dict
    paths : dict
        Name -> path of every file written.
    elapsed : float
        Seconds for the whole benchmark.
    """

    rows: list = field(default_factory=list)
    ratios: list = field(default_factory=list)
    throughput: list = field(default_factory=list)
    scaling: list = field(default_factory=list)
    longrun: list = field(default_factory=list)
    targets: list = field(default_factory=list)
    target_summary: list = field(default_factory=list)
    scaling_exponent: dict = field(default_factory=dict)
    references: dict = field(default_factory=dict)
    machine: dict = field(default_factory=dict)
    paths: dict = field(default_factory=dict)
    elapsed: float = 0.0


def has_backend_option() -> bool:
    """Whether ``liesuslov.integrate`` takes ``backend=`` (the optional compiled kernel)."""
    import liesuslov as ls

    return "backend" in inspect.signature(ls.integrate).parameters


def integrate_kwargs(backend: str | None) -> dict:
    """``{"backend": backend}`` if asked for and supported by ``integrate``."""
    if backend is None:
        return {}
    if not has_backend_option():
        raise ValueError(f"backend={backend!r}: this liesuslov's integrate() has no backend option")
    return {"backend": backend}
