"""Work-precision benchmark: liesuslov's RKMK integrators against scipy's ``solve_ivp``, speed against error.

Run it as ``python -m liesuslov.bench`` (or ``liesuslov bench``); ``--quick`` takes under a minute.
Regenerate the documentation page with::

    python -m liesuslov.bench --docs docs/performance.md

What is measured
----------------
* **Work-precision sweeps** on five reference scenes with exact or analytic solutions
  (:data:`SCENES`): every liesuslov method × chart over a sweep of step sizes (fixed-step methods) or
  tolerances (adaptive ones), and scipy's ``solve_ivp`` (RK45, DOP853, Radau) on the equivalent
  embedded ODE — state ``(xi, vec g)`` with ``Gamma = g^T gamma`` when the attitude is reconstructed,
  ``(xi, Gamma)`` otherwise — with a hand-written numpy right-hand side, as a user would write it.
  Each run records the wall time (minimum over repeats after one warm-up run), ``nfev``, steps, the
  errors in Omega, Gamma and g at the final time against the reference, the orthogonality defect
  ``max |g^T g - I|``, the sphere defect ``max ||Gamma| - 1|``, the constraint defect ``max |<a^i, Omega>|``
  and the drift of every first integral (maxima over all steps).
* **The ratio table**: for each scene and error level 1e-5 … 1e-10 the fastest liesuslov route and
  the fastest scipy route that reach it (log time interpolated linearly in log error along each
  route's sweep) and the ratio liesuslov / scipy (goal: at most 0.5).
* **Batch throughput** (trajectory-steps per second, RKMK4 with reconstruction, n = 3 and 4),
  **per-step cost against n** (Fedorov–Kozlov D, reconstruction, n = 3 … 256, with a fitted
  exponent) and a **long run** (10⁶ RKMK4 steps, n = 3: orthogonality and energy error).

Outputs (in the folder given): ``results.csv`` (one row per work-precision run), ``throughput.csv``,
``nscaling.csv``, ``longrun.csv``, ``ratios.csv``, ``summary.md`` and PNG plots. Every file is
written to a temporary name and renamed, after all measurements succeeded.

The numbers are reported, never asserted: the tests (``tests/test_bench.py``) check the machinery.
"""

from __future__ import annotations

import argparse
import csv
import datetime as _dt
import gc
import inspect
import io
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["SCENES", "LEVELS", "BenchConfig", "BenchReport", "Scene", "add_arguments", "build_scene",
           "main", "run_bench", "run_from_args", "time_to_reach"]

#: Error levels of the ratio table.
LEVELS: tuple[float, ...] = (1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
#: The goal for the ratio liesuslov / scipy at every level (reported, not asserted).
GOAL_RATIO = 0.5
#: Tolerances of the two independent high-accuracy reference runs (10x tighter than any swept run).
REF_RTOL, REF_ATOL = 1e-13, 1e-15
#: atol = ATOL_FACTOR * rtol in every adaptive run (both libraries).
ATOL_FACTOR = 1e-2
#: Timed repeats of one setting stop once their total exceeds this many seconds (at least one).
REPEAT_BUDGET_S = 0.6

_ADAPTIVE = ("rkmk23", "rkmk45", "rkmk853")
_SCIPY_METHODS = ("RK45", "DOP853", "Radau")
# Fixed-step sweeps: step counts as multiples of a scene's n_base (rkmk4 with n_base steps errs by ~1e-7).
_FIXED_FACTORS: dict[str, tuple[float, ...]] = {
    "lie-euler": (1, 4, 16),
    "rkmk2": (0.5, 1, 2, 4, 8),
    "rkmk-heun": (0.5, 1, 2, 4, 8),
    "rkmk3": (0.5, 1, 2, 4, 8),
    "rkmk4": (0.25, 0.5, 1, 2, 4, 8),
    "rkmk5": (0.125, 0.25, 0.5, 1, 2, 4),
    "rkmk8": (0.0625, 0.125, 0.25, 0.5, 1),
}
_TOLERANCES: dict[str, tuple[float, ...]] = {
    "rkmk23": tuple(10.0 ** -k for k in range(3, 9)),
    "rkmk45": tuple(10.0 ** -k for k in range(3, 12)),
    "rkmk853": tuple(10.0 ** -k for k in range(4, 13)),
    "RK45": tuple(10.0 ** -k for k in range(3, 12)),
    "DOP853": tuple(10.0 ** -k for k in range(4, 13)),
    "Radau": tuple(10.0 ** -k for k in range(3, 10)),
}
_QUICK_FIXED = {"rkmk4": (0.5, 2, 8)}
_QUICK_TOL = {"rkmk45": (1e-5, 1e-7, 1e-9), "rkmk853": (1e-6, 1e-9, 1e-12), "RK45": (1e-5, 1e-7, 1e-9),
              "DOP853": (1e-6, 1e-9, 1e-12), "Radau": (1e-4, 1e-6, 1e-8)}

RESULT_COLUMNS = ("scene", "library", "route", "method", "chart", "backend", "setting_kind", "setting",
                  "t_final", "wall_time", "repeats", "nfev", "steps", "rejected", "status", "message",
                  "err_Omega", "err_Gamma", "err_g", "err_pendulum", "error", "orth_defect", "sphere_defect",
                  "constraint_defect", "drift_energy", "drift_integrals", "drifts", "ref_uncertainty")


# ====================================================================== scenes
@dataclass
class Scene:
    """A reference scene: the system, its initial data, the scipy formulation and the reference.

    Attributes
    ----------
    key, title : str
    n : int
        SO(n).
    system : SuslovSystem
    omega0 : ndarray, shape (d,)
        Initial Omega in so(n) coordinates (in D).
    Gamma0 : ndarray, shape (n,), or None
    reconstruct : bool
        Integrate the attitude g (g0 = identity); then Gamma = g^T gamma with gamma = Gamma0.
    t1 : float
        Final time (the errors are taken there).
    integrals : dict of str to callable
        First integrals ``F(omega (..., d), Gamma (..., n) or None)``; "energy" among them.
    rhs : callable
        ``f(t, y)`` of the embedded ODE for ``scipy.integrate.solve_ivp``.
    y0 : ndarray
        Its initial state.
    unpack : callable
        ``y (N, dim) -> (omega (N, d), Gamma (N, n) or None, g (N, n, n) or None)``.
    n_base : int
        The step-count scale of the fixed-step sweeps: rkmk4 with ``n_base`` steps over ``[0, t1]`` errs
        by about 1e-7 … 1e-6 (a quarter of it by ~1e-4).
    analytic : callable or None
        ``() -> dict`` with some of ``"omega"``, ``"Gamma"`` at ``t1`` from the closed form.
    extra : callable or None
        ``(omega, Gamma, g) -> dict`` of derived quantities at ``t1`` compared with ``extra_ref``
        (the Lagrange scene: the spherical pendulum ``q, v``).
    extra_ref : callable or None
        ``() -> dict`` of the same quantities from the closed form.
    reference : str
        How the reference was obtained (for the report).
    """

    key: str
    title: str
    n: int
    system: Any
    omega0: np.ndarray
    Gamma0: np.ndarray | None
    reconstruct: bool
    t1: float
    integrals: dict
    rhs: Callable
    y0: np.ndarray
    unpack: Callable
    n_base: int
    analytic: Callable | None = None
    extra: Callable | None = None
    extra_ref: Callable | None = None
    reference: str = ""

    @property
    def has_group(self) -> bool:
        """Whether a group part (g or Gamma) is integrated, i.e. whether the chart matters."""
        return self.reconstruct or self.Gamma0 is not None


def _fk_coords(n: int) -> tuple[int, np.ndarray]:
    """(d, positions of Omega_in, i < n, among the so(n) coordinates)."""
    import liesuslov as ls

    alg = ls.so(n)
    return alg.dim, np.array([alg.index(i, n - 1) for i in range(n - 1)])


def _fk_unpacker(n: int, with_g: bool, gamma: np.ndarray | None) -> Callable:
    """Unpack ``y = (xi, vec g)`` or ``(xi, Gamma)`` of a Fedorov–Kozlov scene."""
    d, idx = _fk_coords(n)
    m = n - 1

    def unpack(y):
        omega = np.zeros((y.shape[0], d))
        omega[:, idx] = y[:, :m]
        if with_g:
            g = y[:, m:].reshape(-1, n, n)
            Gamma = None if gamma is None else np.einsum("tji,j->ti", g, gamma)
            return omega, Gamma, g
        return omega, y[:, m:], None
    return unpack


def _fk_g_rhs(n: int, xi_dot: Callable) -> Callable:
    """Embedded ODE ``xi' = f(xi, Gamma)``, ``g' = g Omega`` with ``Gamma = g^T gamma``, Omega in the FK D.

    Omega has only its last row and column: ``(g Omega)[:, j] = -g[:, n-1] xi_j`` (j < n-1) and
    ``(g Omega)[:, n-1] = g[:, :n-1] @ xi``.
    """
    m = n - 1

    def rhs(t, y, gamma):
        xi = y[:m]
        g = y[m:].reshape(n, n)
        Gam = gamma @ g  # g^T gamma
        out = np.empty_like(y)
        out[:m] = xi_dot(xi, Gam)
        dg = out[m:].reshape(n, n)
        dg[:, :m] = np.multiply.outer(-g[:, m], xi)
        dg[:, m] = g[:, :m] @ xi
        return out
    return rhs


def _klebsh_tisserand() -> Scene:
    import liesuslov as ls

    n = 4
    I = np.array([1.0, 2.0, 3.0, 4.0])
    B = np.array([4.0, 3.0, 2.0, 1.0])
    case = ls.cases.klebsh_tisserand(I, B)
    u0 = np.array([0.3, -0.2, 0.15])
    G0 = np.array([0.3, 0.25, -0.2, 0.0])
    G0[-1] = math.sqrt(1.0 - float(G0 @ G0))
    d, idx = _fk_coords(n)
    omega0 = np.zeros(d)
    omega0[idx] = u0
    t1 = 20.0
    c = (B[:-1] - B[-1]) / (I[:-1] + I[-1])
    base = _fk_g_rhs(n, lambda xi, G: c * G[:-1] * G[-1])

    def analytic():
        u, G = ls.analytic.KlebshTisserandMotion(u0, G0, I, B).state(t1)
        om = np.zeros(d)
        om[idx] = u
        return {"omega": om, "Gamma": G}

    return Scene("klebsh-tisserand", "Klebsh–Tisserand, n = 4, with reconstruction", n, case.system, omega0, G0,
                 True, t1, dict(case.integrals), lambda t, y: base(t, y, G0),
                 np.concatenate([u0, np.eye(n).ravel()]), _fk_unpacker(n, True, G0), 250, analytic,
                 reference="Omega, Gamma: KlebshTisserandMotion (closed form on the torus, t(tau) by quadrature); "
                           "g: mean of liesuslov rkmk853 and scipy DOP853 at rtol 1e-13")


def _kharlamova() -> Scene:
    import liesuslov as ls

    n = 5
    I = np.array([1.0, 1.5, 2.0, 2.5, 3.0])
    B = np.array([1.0, -0.6, 0.8, 0.5])
    case = ls.cases.kharlamova(I, B)
    u0 = np.array([0.2, -0.1, 0.15, 0.05])
    G0 = np.array([0.3, -0.2, 0.4, 0.1, 0.8])
    G0 = G0 / np.linalg.norm(G0)
    motion = ls.analytic.KharlamovaMotion(u0, G0, I, B)
    if str(motion.kind) != "periodic":  # pragma: no cover - fixed data
        raise RuntimeError("the Kharlamova scene's data must give a periodic motion")
    T = float(motion.period)
    d, idx = _fk_coords(n)
    omega0 = np.zeros(d)
    omega0[idx] = u0
    m = n - 1
    c = B / (I[:-1] + I[-1])

    def rhs(t, y):  # (I_i + I_n) u_i' = B_i Gamma_n, Gamma' = -Omega Gamma
        xi, G = y[:m], y[m:]
        out = np.empty_like(y)
        out[:m] = c * G[m]
        out[m:-1] = -G[m] * xi
        out[-1] = G[:m] @ xi
        return out

    def analytic():  # one period: the state returns to itself
        return {"omega": omega0.copy(), "Gamma": G0.copy()}

    return Scene("kharlamova", f"Kharlamova, n = 5, over one period (T = {T:.6f})", n, case.system, omega0, G0,
                 False, T, dict(case.integrals), rhs, np.concatenate([u0, G0]), _fk_unpacker(n, False, None), 100,
                 analytic, reference="the initial state (period T from KharlamovaMotion, Carlson's R_F)")


def _lagrange() -> Scene:
    import liesuslov as ls

    n = 3
    I1, In, Bn = 1.0, 0.5, 1.0
    case = ls.cases.lagrange(n, I1, In, Bn)
    u0 = np.array([0.6, 0.3])
    G0 = np.array([0.4, 0.2, 0.9])
    G0 = G0 / np.linalg.norm(G0)
    d, idx = _fk_coords(n)
    omega0 = np.zeros(d)
    omega0[idx] = u0
    t1 = 10.0
    k = -Bn / (I1 + In)
    base = _fk_g_rhs(n, lambda xi, G: k * G[:-1])
    q0, v0 = ls.to_spherical_pendulum(np.eye(n), omega0)
    pendulum = ls.analytic.SphericalPendulum(q0, v0, G0, I1 + In, Bn)

    def extra(omega, Gamma, g):
        try:
            q, v = ls.to_spherical_pendulum(g, omega)
        except ValueError:  # g off SO(n) by more than 1e-8 (scipy at loose tolerances): the same map, unchecked
            q, v = g[:, -1], g @ ls.so(n).hat(omega)[:, -1]
        return {"q": q, "v": v}

    def extra_ref():
        q, v = pendulum.state(t1)
        return {"q": q, "v": v}

    return Scene("lagrange", "Lagrange, n = 3, mapped to the spherical pendulum", n, case.system, omega0, G0, True,
                 t1, dict(case.integrals), lambda t, y: base(t, y, G0), np.concatenate([u0, np.eye(n).ravel()]),
                 _fk_unpacker(n, True, G0), 150, None, extra, extra_ref,
                 reference="(q, v) = (g e_n, g Omega e_n): SphericalPendulum (Jacobi elliptic functions); "
                           "Omega, Gamma, g: mean of liesuslov rkmk853 and scipy DOP853 at rtol 1e-13")


def _euler_top() -> Scene:
    import liesuslov as ls

    n = 3
    Id = np.array([1.0, 2.0, 3.5])  # mass tensor; J = tr(I) - I acts on w
    alg = ls.so(3)
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag(Id)), constraints=ls.Subspace(alg, np.eye(3)))
    K = system.inertia.matrix
    J = Id.sum() - Id
    w0 = np.array([0.8, 0.6, 0.5])
    omega0 = np.array([-w0[2], w0[1], -w0[0]])  # (Omega_12, Omega_13, Omega_23) = (-w3, w2, -w1)
    t1 = 20.0
    a1, a2, a3 = (J[1] - J[2]) / J[0], (J[2] - J[0]) / J[1], (J[0] - J[1]) / J[2]

    def rhs(t, y):  # J w' = J w x w, g' = g hat(w)
        w1, w2, w3 = y[0], y[1], y[2]
        g = y[3:].reshape(3, 3)
        out = np.empty_like(y)
        out[0], out[1], out[2] = a1 * w2 * w3, a2 * w3 * w1, a3 * w1 * w2
        W = np.array([[0.0, -w3, w2], [w3, 0.0, -w1], [-w2, w1, 0.0]])
        out[3:] = (g @ W).ravel()
        return out

    def unpack(y):
        w = y[:, :3]
        return np.stack([-w[:, 2], w[:, 1], -w[:, 0]], axis=-1), None, y[:, 3:].reshape(-1, 3, 3)

    def energy(x, G):
        return 0.5 * np.sum((x @ K) * x, axis=-1)

    def casimir(x, G):
        M = x @ K
        return np.sum(M * M, axis=-1)

    return Scene("euler-top", "free rigid body (Euler top), n = 3, with attitude", n, system, omega0, None, True, t1,
                 {"energy": energy, "|M|^2": casimir}, rhs, np.concatenate([w0, np.eye(3).ravel()]), unpack, 120,
                 reference="mean of liesuslov rkmk853 and scipy DOP853 at rtol 1e-13 (independent formulations)")


def _suslov3() -> Scene:
    import liesuslov as ls

    Jw = np.array([[2.0, 0.0, 0.3], [0.0, 3.0, 0.4], [0.3, 0.4, 4.0]])
    case = ls.cases.suslov3(Jw)
    w0 = np.array([1.0, 0.5, 0.0])
    omega0 = np.array([-w0[2], w0[1], -w0[0]])
    t1 = 25.0
    JD, b = Jw[:2, :2], Jw[:2, 2]
    RJ = np.array([[0.0, -1.0], [1.0, 0.0]]) @ JD / np.linalg.det(JD)

    def rhs(t, y):  # J_D w' = <b, w> R w  (w3 = 0)
        return (b @ y) * (RJ @ y)

    def unpack(y):
        z = np.zeros(y.shape[0])
        return np.stack([z, y[:, 1], -y[:, 0]], axis=-1), None, None

    def analytic():
        w = ls.analytic.Suslov3Free(w0, Jw).omega(t1)
        return {"omega": np.array([-w[2], w[1], -w[0]])}

    return Scene("suslov3", "Suslov, n = 3, V = 0: asymptotic motion", 3, case.system, omega0, None, False, t1,
                 dict(case.integrals), rhs, w0[:2].copy(), unpack, 40, analytic,
                 reference="Suslov3Free (explicit tanh law on the energy ellipse)")


#: Scene name -> constructor.
SCENES: dict[str, Callable[[], Scene]] = {
    "klebsh-tisserand": _klebsh_tisserand,
    "kharlamova": _kharlamova,
    "lagrange": _lagrange,
    "euler-top": _euler_top,
    "suslov3": _suslov3,
}


def build_scene(name: str) -> Scene:
    """The :class:`Scene` called ``name`` (a key of :data:`SCENES`; underscores accepted).

    Raises
    ------
    ValueError
        Unknown name (the message lists the valid ones).
    """
    return SCENES[_scene_key(name)]()


def _scene_key(name: str) -> str:
    key = str(name).strip().lower().replace("_", "-")
    if key not in SCENES:
        raise ValueError(f"unknown scene {name!r}; valid scenes: {', '.join(SCENES)}")
    return key


# ====================================================================== configuration
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
    preset : str
        ``"full"``, ``"quick"`` or a name of your own (reported).
    """

    scenes: tuple[str, ...] = tuple(SCENES)
    methods: tuple[str, ...] | None = None
    charts: tuple[str, ...] = ("exp", "cayley")
    scipy_methods: tuple[str, ...] = _SCIPY_METHODS
    fixed_factors: dict | None = None
    tolerances: dict | None = None
    max_settings: int | None = None
    repeats: int = 5
    batch_sizes: tuple[int, ...] = (1, 10, 100, 1000, 10_000, 100_000)
    batch_dims: tuple[int, ...] = (3, 4)
    scaling_sizes: tuple[int, ...] = (3, 4, 8, 16, 32, 64, 128, 256)
    long_run_steps: int = 1_000_000
    plots: bool = True
    levels: tuple[float, ...] = LEVELS
    backend: str | None = None
    isolated_timeout: float = 150.0
    preset: str = "full"

    @classmethod
    def full(cls, **overrides) -> BenchConfig:
        """Every method × chart over the full sweeps, batches up to 1e5, n up to 256, the long run."""
        return cls(**overrides)

    @classmethod
    def quick(cls, **overrides) -> BenchConfig:
        """rkmk4, rkmk45, rkmk853 × exp/cayley and the three scipy methods at 3 settings; no long run.

        Runs the numpy path (``backend="numpy"`` where ``integrate`` has the option): the one-off
        compilation of an optional kernel (20–60 s on a cold cache) would not fit in the minute.
        """
        base = dict(methods=("rkmk4", "rkmk45", "rkmk853"), fixed_factors=dict(_QUICK_FIXED),
                    tolerances=dict(_QUICK_TOL), repeats=1, batch_sizes=(1, 10, 100, 1000, 10_000),
                    scaling_sizes=(3, 4, 8, 16, 32, 64), long_run_steps=0, preset="quick",
                    backend="numpy" if _has_backend_option() else None)
        return cls(**{**base, **overrides})

    def validated(self) -> BenchConfig:
        """The configuration with names normalised; ValueError naming what is wrong."""
        import liesuslov as ls

        scenes = tuple(_scene_key(s) for s in self.scenes)
        if not scenes:
            raise ValueError(f"scenes must name at least one scene; valid scenes: {', '.join(SCENES)}")
        methods = tuple(ls.METHODS) if self.methods is None else tuple(self.methods)
        bad = [m for m in methods if m not in ls.METHODS]
        if bad:
            raise ValueError(f"unknown method(s) {bad}; valid methods: {', '.join(ls.METHODS)}")
        bad = [c for c in self.charts if c not in ("exp", "cayley")]
        if bad or not self.charts:
            raise ValueError(f"charts must be a non-empty subset of ('exp', 'cayley'), got {self.charts}")
        bad = [m for m in self.scipy_methods if m not in _TOLERANCES]
        if bad:
            raise ValueError(f"unknown scipy method(s) {bad}; valid: {', '.join(_SCIPY_METHODS)}")
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


# ====================================================================== results
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
    scaling_exponent : dict
        ``"backend/chart"`` (or chart) -> fitted exponent p of ``time per step ~ n^p`` over the three
        largest sizes that ran, with the sizes used.
    references : dict
        Scene -> ``{"uncertainty": float, "how": str, "title": str, "t1": float}``.
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
    scaling_exponent: dict = field(default_factory=dict)
    references: dict = field(default_factory=dict)
    machine: dict = field(default_factory=dict)
    paths: dict = field(default_factory=dict)
    elapsed: float = 0.0


# ====================================================================== running
def _has_backend_option() -> bool:
    """Whether ``liesuslov.integrate`` takes ``backend=`` (the optional compiled kernel)."""
    import liesuslov as ls

    return "backend" in inspect.signature(ls.integrate).parameters


def _integrate_kwargs(backend: str | None) -> dict:
    """``{"backend": backend}`` if asked for and supported by ``integrate``."""
    if backend is None:
        return {}
    if not _has_backend_option():
        raise ValueError(f"backend={backend!r}: this liesuslov's integrate() has no backend option")
    return {"backend": backend}


def _timed(fn: Callable[[], Any], repeats: int) -> tuple[Any, float, int]:
    """Warm up once, then time up to ``repeats`` calls; returns (warm-up result, min time, timed calls)."""
    result = fn()
    best, count, total = math.inf, 0, 0.0
    enabled = gc.isenabled()
    # As timeit: one collection before, none during the repeats. (A gc.collect() before every call
    # walks every live object and leaves the CPU caches cold: ~0.4 ms added to each call of either
    # library, which swamps short runs.)
    gc.collect()
    gc.disable()
    try:
        while count < repeats and (count == 0 or total < REPEAT_BUDGET_S):
            start = time.perf_counter()
            fn()
            dt = time.perf_counter() - start
            best, total, count = min(best, dt), total + dt, count + 1
    finally:
        if enabled:
            gc.enable()
    return result, best, count


def _max_abs(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))))


@dataclass
class _Reference:
    omega: np.ndarray
    Gamma: np.ndarray | None
    g: np.ndarray | None
    extra: dict
    uncertainty: float
    details: dict


def _run_liesuslov(scene: Scene, method: str, chart: str, kind: str, value: float, extra_kw: dict):
    import liesuslov as ls

    kw: dict = {"h": value} if kind == "h" else {"rtol": value, "atol": ATOL_FACTOR * value}
    return ls.integrate(scene.system, scene.omega0, (0.0, scene.t1), Gamma0=scene.Gamma0,
                        reconstruct=scene.reconstruct, method=method, chart=chart, **kw, **extra_kw)


def _run_scipy(scene: Scene, method: str, rtol: float):
    from scipy.integrate import solve_ivp

    return solve_ivp(scene.rhs, (0.0, scene.t1), scene.y0, method=method, rtol=rtol, atol=ATOL_FACTOR * rtol)


def _trajectory_liesuslov(sol) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    om = sol.omega.reshape(sol.omega.shape[0], -1)
    return om, sol.Gamma, sol.g


def _trajectory_scipy(scene: Scene, sol) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    return scene.unpack(np.ascontiguousarray(sol.y.T))


def _reference(scene: Scene, extra_kw: dict) -> _Reference:
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
    lo, lG, lg = (a[-1] if a is not None else None for a in _trajectory_liesuslov(lie))
    so_, sG, sg = (a[-1] if a is not None else None for a in _trajectory_scipy(scene, sp))
    details = {"liesuslov vs scipy (Omega)": _max_abs(lo, so_)}
    if lG is not None:
        details["liesuslov vs scipy (Gamma)"] = _max_abs(lG, sG)
    if lg is not None:
        details["liesuslov vs scipy (g)"] = _max_abs(lg, sg)
    # Without a closed form: the mean of the two independent runs (no swept run coincides with it).
    omega = 0.5 * (lo + so_)
    Gamma = None if lG is None else 0.5 * (lG + sG)
    g = None if lg is None else 0.5 * (lg + sg)
    if scene.analytic is not None:
        an = scene.analytic()
        if "omega" in an:
            details["closed form vs numeric (Omega)"] = max(_max_abs(an["omega"], lo), _max_abs(an["omega"], so_))
            omega = np.asarray(an["omega"], dtype=float)
        if "Gamma" in an and lG is not None:
            details["closed form vs numeric (Gamma)"] = max(_max_abs(an["Gamma"], lG), _max_abs(an["Gamma"], sG))
            Gamma = np.asarray(an["Gamma"], dtype=float)
    extra: dict = {}
    if scene.extra is not None and scene.extra_ref is not None:
        extra = {k: np.asarray(v, dtype=float) for k, v in scene.extra_ref().items()}
        for name, (a, b) in {"liesuslov": (lo, lg), "scipy": (so_, sg)}.items():
            got = scene.extra(a, None, b)
            details[f"closed form vs {name} ({', '.join(extra)})"] = max(_max_abs(got[k], extra[k]) for k in extra)
    unc = max(details.values())
    return _Reference(omega, Gamma, g, extra, unc, details)


def _metrics(scene: Scene, ref: _Reference, omega, Gamma, g) -> dict:
    """Errors at t1 against the reference, structure defects and integral drifts over the trajectory."""
    nan = float("nan")
    row: dict = {"err_Omega": _max_abs(omega[-1], ref.omega), "err_Gamma": nan, "err_g": nan, "err_pendulum": nan}
    if Gamma is not None and ref.Gamma is not None:
        row["err_Gamma"] = _max_abs(Gamma[-1], ref.Gamma)
    if g is not None and ref.g is not None:
        row["err_g"] = _max_abs(g[-1], ref.g)
    if ref.extra and scene.extra is not None and g is not None:
        got = scene.extra(omega[-1], None if Gamma is None else Gamma[-1], g[-1])
        row["err_pendulum"] = max(_max_abs(got[k], ref.extra[k]) for k in ref.extra)
    errs = [row[k] for k in ("err_Omega", "err_Gamma", "err_g", "err_pendulum") if np.isfinite(row[k])]
    row["error"] = max(errs) if errs else nan
    if g is not None:
        m = g.shape[-1]
        row["orth_defect"] = float(np.max(np.abs(np.swapaxes(g, -1, -2) @ g - np.eye(m))))
    else:
        row["orth_defect"] = nan
    row["sphere_defect"] = (float(np.max(np.abs(np.linalg.norm(Gamma, axis=-1) - 1.0)))
                            if Gamma is not None else nan)
    A = np.asarray(scene.system.covectors, dtype=float)
    row["constraint_defect"] = float(np.max(np.abs(omega @ A.T), initial=0.0)) if A.size else 0.0
    drifts = {}
    for name, F in scene.integrals.items():
        vals = np.asarray(F(omega, Gamma), dtype=float)
        drifts[name] = float(np.max(np.abs(vals - vals[0])))
    row["drift_energy"] = drifts.get("energy", nan)
    others = [v for k, v in drifts.items() if k != "energy"]
    row["drift_integrals"] = max(others) if others else nan
    row["drifts"] = ";".join(f"{k}={v:.3e}" for k, v in drifts.items())
    return row


def _nan_row() -> dict:
    nan = float("nan")
    return {k: nan for k in ("err_Omega", "err_Gamma", "err_g", "err_pendulum", "error", "orth_defect",
                             "sphere_defect", "constraint_defect", "drift_energy", "drift_integrals")} | {"drifts": ""}


@dataclass(frozen=True)
class _Task:
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


def _plan(config: BenchConfig, scene: Scene) -> list[_Task]:
    import liesuslov as ls

    tasks = []
    fixed_f = config.fixed_factors if config.fixed_factors is not None else _FIXED_FACTORS
    tols = config.tolerances if config.tolerances is not None else _TOLERANCES
    charts = config.charts if scene.has_group else ("-",)
    for method in config.methods or ():
        adaptive = bool(getattr(ls.METHODS[method], "adaptive", method in _ADAPTIVE))
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


def _execute(task: _Task, scene: Scene, ref: _Reference, repeats: int, extra_kw: dict) -> dict:
    row: dict = {"scene": task.scene, "library": task.library, "route": task.route, "method": task.method,
                 "chart": task.chart, "setting_kind": task.kind, "setting": task.value, "t_final": scene.t1,
                 "ref_uncertainty": ref.uncertainty}
    chart = "exp" if task.chart == "-" else task.chart
    try:
        if task.library == "liesuslov":
            sol, wall, count = _timed(lambda: _run_liesuslov(scene, task.method, chart, task.kind, task.value,
                                                             extra_kw), repeats)
            ok, msg = sol.success, sol.message
            row.update(backend=sol.stats.get("backend", "numpy"), nfev=sol.stats.get("nfev"),
                       steps=sol.stats.get("steps"), rejected=sol.stats.get("rejected"))
            traj = _trajectory_liesuslov(sol)
        else:
            sol, wall, count = _timed(lambda: _run_scipy(scene, task.method, task.value), repeats)
            ok, msg = sol.success, sol.message
            row.update(backend="scipy", nfev=sol.nfev, steps=len(sol.t) - 1, rejected="")
            traj = _trajectory_scipy(scene, sol)
        row.update(wall_time=wall, repeats=count, status="ok" if ok else "failed", message=str(msg))
        with np.errstate(all="ignore"):
            row.update(_metrics(scene, ref, *traj) if ok else _nan_row())
    except (ValueError, RuntimeError, FloatingPointError, MemoryError, np.linalg.LinAlgError) as exc:
        row.update(_nan_row(), wall_time=float("nan"), repeats=0, status="failed",
                   message=f"{type(exc).__name__}: {exc}", backend=row.get("backend", ""))
    return row


# ---------------------------------------------------------------------- ratio table
def time_to_reach(points: Iterable[tuple[float, float]], level: float) -> float:
    """Time a route needs to reach ``error <= level``, from its sweep ``[(error, time), ...]``.

    Along consecutive sweep points whose errors straddle ``level``, ``log time`` is interpolated
    linearly in ``log error``; a point already at or below ``level`` counts with its own time.
    The smallest candidate is returned; ``inf`` when no point reaches ``level``.

    Parameters
    ----------
    points : iterable of (error, time)
        In sweep order (coarse to fine); non-finite entries are skipped.
    level : float
    """
    pts = [(float(e), float(t)) for e, t in points if np.isfinite(e) and np.isfinite(t) and t > 0]
    best = math.inf
    for e, t in pts:
        if e <= level:
            best = min(best, t)
    for (e1, t1), (e2, t2) in zip(pts[:-1], pts[1:], strict=True):
        if e1 > 0 and e2 > 0 and (e1 - level) * (e2 - level) < 0:
            f = (math.log(level) - math.log(e1)) / (math.log(e2) - math.log(e1))
            best = min(best, math.exp(math.log(t1) + f * (math.log(t2) - math.log(t1))))
    return best


def _fastest(rows: list[dict], level: float) -> tuple[float, str]:
    routes: dict[str, list] = {}
    for r in rows:
        if r["status"] == "ok":
            routes.setdefault(r["route"], []).append(r)
    best, name = math.inf, ""
    for route, rs in routes.items():
        key = (lambda r: -r["setting"]) if rs[0]["setting_kind"] == "h" else (lambda r: -r["setting"])
        rs = sorted(rs, key=key)  # coarse to fine: decreasing h or rtol
        t = time_to_reach([(r["error"], r["wall_time"]) for r in rs], level)
        if t < best:
            best, name = t, route
    return best, name


def _ratio_table(rows: list[dict], scenes: Sequence[str], levels: Sequence[float], refs: dict) -> list[dict]:
    out = []
    for s in scenes:
        srows = [r for r in rows if r["scene"] == s]
        unc = refs[s]["uncertainty"]
        for level in levels:
            lt, lr = _fastest([r for r in srows if r["library"] == "liesuslov"], level)
            st, sr = _fastest([r for r in srows if r["library"] == "scipy"], level)
            ratio = lt / st if np.isfinite(lt) and np.isfinite(st) else float("nan")
            out.append({"scene": s, "level": level, "liesuslov_time": lt, "liesuslov_route": lr,
                        "scipy_time": st, "scipy_route": sr, "ratio": ratio,
                        "goal_met": bool(np.isfinite(ratio) and ratio <= GOAL_RATIO),
                        "reliable": bool(level >= 10 * unc)})
    return out


# ---------------------------------------------------------------------- throughput, scaling, long run
def _kt_system(n: int):
    """The Klebsh–Tisserand case in SO(n) used by the throughput sweep (n = 4)."""
    import liesuslov as ls

    I = np.linspace(1.0, 2.0, n)
    B = np.linspace(3.0, 2.0, n)
    B[-1] = 1.0
    return ls.cases.klebsh_tisserand(I, B)


def _scaling_scene(n: int):
    """(system, Omega0, Gamma0) of the n-scaling sweep: Klebsh–Tisserand in SO(n), Fedorov–Kozlov D.

    Built as a SuslovSystem, not a Case: the Case's energy integral holds the dense d x d inertia
    (d = n(n-1)/2; 8 GiB at n = 256), which the integration itself does not need.
    """
    import liesuslov as ls

    I = np.linspace(1.0, 2.0, n)
    B = np.linspace(3.0, 2.0, n)
    B[-1] = 1.0
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), potential=ls.QuadraticPotential(B))
    rng = np.random.default_rng(n)
    u = 0.3 * rng.standard_normal(n - 1)
    Omega0 = np.zeros((n, n))
    Omega0[:-1, -1], Omega0[-1, :-1] = u, -u
    Gamma0 = rng.standard_normal(n)
    return system, Omega0, Gamma0 / np.linalg.norm(Gamma0)


def _throughput_case(n: int):
    import liesuslov as ls

    return ls.cases.lagrange(3, 1.0, 0.5, 1.0) if n == 3 else _kt_system(4)


def _measure_throughput(n: int, batch: int, steps: int, repeats: int, extra_kw: dict) -> dict:
    """RKMK4 with reconstruction on a batch of random initial data in D: the timing row."""
    import liesuslov as ls

    h = 0.01
    case = _throughput_case(n)
    omega, Gamma = case.random_state(np.random.default_rng(batch), batch=(batch,), scale=0.5)

    def run():
        return ls.integrate(case.system, omega, (0.0, steps * h), Gamma0=Gamma, reconstruct=True, method="rkmk4",
                            h=h, t_eval=[steps * h], **extra_kw)
    sol, wall, count = _timed(run, repeats)
    ts = batch * steps
    return {"wall_time": wall, "repeats": count, "backend": sol.stats.get("backend", "numpy"),
            "traj_steps_per_s": ts / wall, "ns_per_traj_step": wall / ts * 1e9, "us_per_step": wall / steps * 1e6,
            "status": "ok" if sol.success else "failed", "message": "" if sol.success else sol.message}


def _measure_scaling(n: int, chart: str, repeats: int, extra_kw: dict) -> dict:
    """RKMK4 with reconstruction on SO(n), Klebsh–Tisserand with the Fedorov–Kozlov D: the timing row."""
    import liesuslov as ls

    h = 0.01
    system, Omega0, Gamma0 = _scaling_scene(n)

    def run(steps):
        return ls.integrate(system, Omega0, (0.0, steps * h), Gamma0=Gamma0, reconstruct=True, method="rkmk4",
                            chart=chart, h=h, t_eval=[steps * h], **extra_kw)
    run(1)  # compiles / warms caches
    start = time.perf_counter()
    run(2)
    probe = (time.perf_counter() - start) / 2
    steps = int(min(200, max(3, 0.3 / max(probe, 1e-9))))
    sol, wall, count = _timed(lambda: run(steps), repeats)
    if not sol.success:
        raise RuntimeError(sol.message)
    g = sol.g[-1]
    return {"steps": steps, "wall_time": wall, "repeats": count, "us_per_step": wall / steps * 1e6,
            "backend": sol.stats.get("backend", "numpy"), "form": sol.stats.get("form", ""),
            "orth_defect": float(np.max(np.abs(g.T @ g - np.eye(n)))), "status": "ok", "message": ""}


_MEASURES: dict[str, Callable[..., dict]] = {"throughput": _measure_throughput, "scaling": _measure_scaling}
#: Sizes measured in a child process with memory and time limits (a failure there is recorded, not fatal).
_ISOLATE_N, _ISOLATE_BATCH = 64, 10_000


def _memory_budget() -> int:
    """Bytes of address space a child measurement may add: half the available memory, at most 8 GiB."""
    avail = 4 << 30
    try:
        with open("/proc/meminfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError):
        pass
    return int(min(avail // 2, 8 << 30))


def _guarded(kind: str, kwargs: dict, *, isolate: bool, timeout: float) -> dict:
    """Run a measurement; in a child process with memory and time limits when ``isolate``.

    Any failure (out of memory, time limit, an exception) comes back as ``status = "failed"`` with the reason.
    """
    if not isolate:
        try:
            return _MEASURES[kind](**kwargs)
        except (MemoryError, ValueError, RuntimeError, np.linalg.LinAlgError) as exc:
            return {"status": "failed", "message": f"{type(exc).__name__}: {exc}"}
    import json

    env = dict(os.environ)
    root = str(Path(__file__).resolve().parent.parent)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    payload = json.dumps({"kind": kind, "kwargs": kwargs, "budget": _memory_budget()})
    try:
        res = subprocess.run([sys.executable, "-c", "from liesuslov.bench import _child_main; _child_main()"],
                             input=payload, capture_output=True, text=True, timeout=timeout, env=env, check=False)
    except subprocess.TimeoutExpired:
        return {"status": "failed", "message": f"time limit: not done in {timeout:.0f} s"}
    lines = [ln for ln in res.stdout.splitlines() if ln.startswith("{")]
    if res.returncode == 0 and lines:
        return json.loads(lines[-1])
    err = (res.stderr.strip().splitlines() or [f"exit status {res.returncode}"])[-1]
    return {"status": "failed", "message": f"child process: {err}"[:300]}


def _child_main() -> None:
    """Entry point of an isolated measurement: JSON in on stdin, one JSON row out on stdout."""
    import json

    job = json.loads(sys.stdin.read())
    try:
        import resource

        with open("/proc/self/status", encoding="utf-8") as fh:
            vm = next(int(ln.split()[1]) * 1024 for ln in fh if ln.startswith("VmSize:"))
        hard = resource.getrlimit(resource.RLIMIT_AS)[1]
        limit = vm + int(job["budget"])
        if hard != resource.RLIM_INFINITY:
            limit = min(limit, hard)
        resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    except (ImportError, OSError, ValueError, StopIteration):  # pragma: no cover - not Linux
        pass
    try:
        row = _MEASURES[job["kind"]](**job["kwargs"])
    except MemoryError:
        row = {"status": "failed", "message": f"out of memory (limit {job['budget'] / 2**30:.1f} GiB)"}
    except (ValueError, RuntimeError, np.linalg.LinAlgError) as exc:
        row = {"status": "failed", "message": f"{type(exc).__name__}: {exc}"}
    print(json.dumps(row, default=float))


def _throughput(config: BenchConfig, extra_kw: dict, tick: Callable[[], None]) -> list[dict]:
    rows = []
    work = 2e5 if config.preset == "quick" else 1e6  # trajectory-steps per measurement
    for n in config.batch_dims:
        for batch in config.batch_sizes:
            steps = int(min(1000, max(5, round(work / batch))))
            row: dict = {"n": n, "scene": "Lagrange" if n == 3 else "Klebsh–Tisserand", "batch": int(batch),
                         "steps": steps, "method": "rkmk4", "chart": "exp"}
            row.update(_guarded("throughput", {"n": n, "batch": int(batch), "steps": steps, "repeats": config.repeats,
                                               "extra_kw": extra_kw},
                                isolate=batch > _ISOLATE_BATCH, timeout=config.isolated_timeout))
            rows.append(row)
            tick()
    return rows


def _scaling_backends(config: BenchConfig) -> tuple[str | None, ...]:
    """Backends of the n-scaling sweep: the configured one, else numpy and the default ("auto") if both exist."""
    if config.backend is not None or not _has_backend_option():
        return (config.backend,)
    return ("numpy", "auto")


def _scaling(config: BenchConfig, extra_kw: dict, tick: Callable[[], None]) -> list[dict]:
    rows = []
    for backend in _scaling_backends(config):
        kw = dict(extra_kw) if backend is None else {**extra_kw, "backend": backend}
        for chart in config.charts:
            stop = ""
            for n in config.scaling_sizes:
                row: dict = {"n": int(n), "chart": chart, "requested": backend or "default", "method": "rkmk4",
                             "h": 0.01}
                if stop:
                    row.update(status="skipped", message=stop)
                else:
                    row.update(_guarded("scaling", {"n": int(n), "chart": chart, "repeats": config.repeats,
                                                    "extra_kw": kw},
                                        isolate=n > _ISOLATE_N, timeout=config.isolated_timeout))
                    if row.get("status") != "ok":
                        stop = f"after n = {n} failed"
                rows.append(row)
                tick()
    return rows


def _scaling_key(row: dict) -> str:
    return f"{row['requested']}/{row['chart']}" if row.get("requested", "default") != "default" else row["chart"]


def _fit_exponent(rows: list[dict]) -> dict:
    """Least-squares slope of log(us per step) against log n, per backend and chart.

    Over the three largest sizes that ran (the small ones measure the fixed cost per call, not the growth).
    """
    out = {}
    for key in dict.fromkeys(_scaling_key(r) for r in rows):
        ok = sorted((r for r in rows if _scaling_key(r) == key and r.get("status") == "ok"), key=lambda r: r["n"])
        use = ok[-3:]
        if len(use) >= 2:
            x = np.log([r["n"] for r in use])
            y = np.log([r["us_per_step"] for r in use])
            out[key] = {"exponent": float(np.polyfit(x, y, 1)[0]),
                        "sizes": f"{min(r['n'] for r in use)}..{max(r['n'] for r in use)}"}
    return out


def _long_run(config: BenchConfig, extra_kw: dict, tick: Callable[[], None]) -> list[dict]:
    import liesuslov as ls

    if not config.long_run_steps:
        return []
    steps = int(config.long_run_steps)
    h = 0.01
    t1 = steps * h
    case = _throughput_case(3)
    omega, Gamma = case.random_state(np.random.default_rng(7), scale=0.5)
    row: dict = {"scene": "Lagrange n = 3", "method": "rkmk4", "chart": "exp", "h": h, "steps": steps, "t_final": t1}
    try:
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


# ---------------------------------------------------------------------- machine
def _version(dist: str) -> str:
    from importlib import metadata

    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "not installed"


def machine_info() -> dict:
    """CPU model, cores, Python / numpy / scipy / numba / liesuslov versions, date, git commit."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        usable = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        usable = os.cpu_count() or 0
    import liesuslov as ls

    commit = ""
    here = Path(__file__).resolve().parent
    try:
        res = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=here, capture_output=True, text=True,
                             timeout=5, check=False)
        if res.returncode == 0:
            commit = res.stdout.strip()
            dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", "."], cwd=here,
                                   capture_output=True, text=True, timeout=5, check=False)
            if dirty.returncode == 0 and dirty.stdout.strip():
                commit += " + uncommitted changes"
    except (OSError, subprocess.SubprocessError):
        pass
    return {"cpu": cpu, "cores": f"{usable} usable of {os.cpu_count()}", "platform": platform.platform(),
            "python": platform.python_version(), "numpy": np.__version__, "scipy": _version("scipy"),
            "numba": _version("numba"), "liesuslov": getattr(ls, "__version__", "?"), "commit": commit or "unknown",
            "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")}


# ====================================================================== output
def _fmt(x, spec: str = ".3g") -> str:
    if x is None or x == "":
        return ""
    if isinstance(x, (bool, np.bool_)):
        return str(bool(x))
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        if math.isnan(x):
            return "nan"
        if math.isinf(x):
            return "inf"
        return format(float(x), spec)
    return str(x)


def _csv_text(rows: list[dict], columns: Sequence[str] | None = None) -> str:
    if columns is None:
        columns = []
        for r in rows:
            columns.extend(k for k in r if k not in columns)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([_fmt(r.get(c, ""), ".17g") if isinstance(r.get(c), (float, np.floating)) else _fmt(r.get(c, ""))
                    for c in columns])
    return buf.getvalue()


def _md_table(header: Sequence[str], body: Iterable[Sequence[Any]]) -> str:
    """A markdown table; ``|`` inside cells is escaped."""
    def cell(c: Any) -> str:
        return str(c).replace("|", "\\|")
    lines = ["| " + " | ".join(cell(c) for c in header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(cell(c) for c in row) + " |" for row in body]
    return "\n".join(lines)


def _ms(t: float) -> str:
    if not np.isfinite(t):
        return "—"
    return f"{t * 1e3:.3g} ms"


def _summary_sections(report: BenchReport, config: BenchConfig, image_dir: str | None) -> list[str]:
    """The generated markdown (shared by summary.md and the docs page)."""
    sec = []
    m = report.machine
    sec.append("## Machine\n\n" + _md_table(["", ""], [
        ["CPU", m["cpu"]], ["cores", m["cores"]], ["platform", m["platform"]], ["Python", m["python"]],
        ["numpy", m["numpy"]], ["scipy", m["scipy"]], ["numba", m["numba"]], ["liesuslov", m["liesuslov"]],
        ["commit", m["commit"]], ["date", m["date"]],
        ["mode", f"{config.preset}, {report.elapsed:.0f} s in all"],
        ["backends seen", ", ".join(sorted({str(r.get('backend')) for r in report.rows
                                           if r["library"] == "liesuslov" and r.get("backend")})) or "—"]]))
    # ratio table, compact
    levels = list(config.levels)
    body = []
    for s in config.scenes:
        cells = [s]
        for lv in levels:
            r = next(x for x in report.ratios if x["scene"] == s and x["level"] == lv)
            if np.isfinite(r["ratio"]):
                mark = "✓" if r["goal_met"] else "✗"
                cells.append(f"{r['ratio']:.2f} {mark}" + ("" if r["reliable"] else " (†)"))
            else:
                cells.append("—")
        body.append(cells)
    sec.append("## Ratio table\n\nTime of the fastest liesuslov route divided by the time of the fastest scipy "
               f"route reaching the same error at t1 (goal: ≤ {GOAL_RATIO}; ✓ met, ✗ not met; — a side never "
               "reached the level in its sweep; † level within 10× the reference's own uncertainty).\n\n"
               + _md_table(["scene"] + [f"{lv:.0e}" for lv in levels], body))
    body = []
    for r in report.ratios:
        body.append([r["scene"], f"{r['level']:.0e}", r["liesuslov_route"] or "—", _ms(r["liesuslov_time"]),
                     r["scipy_route"] or "—", _ms(r["scipy_time"]),
                     f"{r['ratio']:.3f}" if np.isfinite(r["ratio"]) else "—"])
    sec.append("### Fastest routes per level\n\n" + _md_table(
        ["scene", "error", "fastest liesuslov", "time", "fastest scipy", "time", "ratio"], body))
    # references
    body = [[s, report.references[s]["title"], f"{report.references[s]['t1']:.6g}",
             f"{report.references[s]['uncertainty']:.1e}", report.references[s]["how"]] for s in config.scenes]
    sec.append("## Scenes and references\n\nThe reference's uncertainty is the largest disagreement among its "
               "independent determinations (closed form, liesuslov rkmk853 and scipy DOP853 at rtol 1e-13).\n\n"
               + _md_table(["scene", "description", "t1", "uncertainty", "reference"], body))
    # structure
    body = []
    for s in config.scenes:
        for lib in ("liesuslov", "scipy"):
            rs = [r for r in report.rows if r["scene"] == s and r["library"] == lib and r["status"] == "ok"]
            if not rs:
                continue

            def mx(key, rs=rs):
                v = [r[key] for r in rs if np.isfinite(r[key])]
                return f"{max(v):.1e}" if v else "—"
            tight = min(rs, key=lambda r: r["error"] if np.isfinite(r["error"]) else math.inf)
            body.append([s, lib, mx("orth_defect"), mx("sphere_defect"), mx("constraint_defect"),
                         f"{tight['error']:.1e} ({tight['route']})", f"{tight['drift_energy']:.1e}"])
    sec.append("## Structure\n\nLargest defects over every run of the sweep (maxima over all steps): the "
               "orthogonality defect max|gᵀg − I|, the sphere defect max||Γ| − 1|, the constraint defect "
               "max|⟨aⁱ, Ω⟩|; and the most accurate run with its energy drift.\n\n"
               + _md_table(["scene", "library", "orthogonality", "sphere", "constraints", "best error (route)",
                            "its energy drift"], body))
    if image_dir is not None and config.plots:
        imgs = [f"![{s}]({image_dir}/bench-{s}.png)" for s in config.scenes]
        sec.append("## Work-precision plots\n\nError at t1 against wall time (log-log); solid: exponential "
                   "chart, dotted: Cayley; black dashed: scipy.\n\n" + "\n\n".join(imgs))
    if report.throughput:
        body = [[r["n"], r["scene"], r["batch"], r.get("steps", ""), _fmt(r.get("traj_steps_per_s"), ".3g"),
                 _fmt(r.get("ns_per_traj_step"), ".4g"), _fmt(r.get("us_per_step"), ".4g"), r.get("backend", ""),
                 r["status"] if r["status"] == "ok" else f"{r['status']}: {r.get('message', '')}"]
                for r in report.throughput]
        txt = ("## Batch throughput\n\nRKMK4 (exponential chart, h = 0.01) with reconstruction on SO(n), random "
               "initial data in D, one vectorised run per batch; output at the final time only.\n\n"
               + _md_table(["n", "scene", "batch", "steps", "trajectory-steps/s", "ns per trajectory-step",
                            "µs per step", "backend", "status"], body))
        if image_dir is not None and config.plots:
            txt += f"\n\n![throughput]({image_dir}/bench-throughput.png)"
        sec.append(txt)
    if report.scaling:
        body = [[r["n"], r["chart"], r.get("requested", ""), r.get("steps", ""), _fmt(r.get("us_per_step"), ".4g"),
                 _fmt(r.get("orth_defect"), ".1e"), r.get("form", ""), r.get("backend", ""),
                 r["status"] if r["status"] == "ok" else f"{r['status']}: {r.get('message', '')}"]
                for r in report.scaling]
        fits = "; ".join(f"{c}: time per step ∝ n^{v['exponent']:.2f} (fit over n = {v['sizes']})"
                         for c, v in report.scaling_exponent.items()) or "no fit (fewer than two sizes)"
        txt = ("## Cost per step against n\n\nKlebsh–Tisserand with the Fedorov–Kozlov D (I = linspace(1, 2, n)), "
               "RKMK4, h = 0.01, reconstruction of g ∈ SO(n), one trajectory. Fitted growth: " + fits
               + " (the goal is n², not n³).\n\n"
               + _md_table(["n", "chart", "backend asked", "steps", "µs per step", "max|gᵀg − I|", "form",
                            "backend ran", "status"], body))
        if image_dir is not None and config.plots:
            txt += f"\n\n![n-scaling]({image_dir}/bench-nscaling.png)"
        sec.append(txt)
    if report.longrun:
        body = [[r["scene"], r["method"], r["h"], r["steps"], _fmt(r.get("wall_time"), ".3g"),
                 _fmt(r.get("us_per_step"), ".3g"), _fmt(r.get("orth_defect"), ".1e"),
                 _fmt(r.get("sphere_defect"), ".1e"), _fmt(r.get("energy_error"), ".1e"), _fmt(r.get("energy0"), ".4g"),
                 r["status"]] for r in report.longrun]
        sec.append("## Long run\n\nOne trajectory, fixed step, output every 1% of the interval.\n\n"
                   + _md_table(["scene", "method", "h", "steps", "wall time (s)", "µs per step", "max|gᵀg − I|",
                                "max||Γ| − 1|", "max|E − E0|", "E0", "status"], body))
    return sec


_DOCS_INTRO = """# Performance

!!! note "Regenerate this page"
    Every number below is produced by one command, run from the repository root:

        python -m liesuslov.bench --docs docs/performance.md

    (`liesuslov bench --docs docs/performance.md` is the same; add `--out DIR` for the CSV files,
    `--quick` for a one-minute subset.) Everything after the section *How it is measured* is generated.

Speed only matters at a given accuracy, so liesuslov is measured the way integrators are compared:
**work-precision sweeps** — wall time against the error actually reached — on scenes whose
motion is known exactly, against scipy's `solve_ivp` integrating the same motion.

## How it is measured

**Scenes.** Five motions with independent references: the Klebsh–Tisserand body in SO(4) with its
attitude (closed form on the invariant torus for Ω and Γ); the Kharlamova body in SO(5) over one
period (the state returns to itself); the Lagrange body in SO(3) mapped to the spherical pendulum
(`q = g e_n`, `v = g Ω e_n` against the Jacobi elliptic solution); the free rigid body (Euler top) with
its attitude; and Suslov's problem in SO(3) with V = 0 (the explicit tanh law). Where the closed form
does not give a quantity (the attitude g), the reference is the mean of a liesuslov rkmk853 run and a
scipy DOP853 run at rtol 1e-13 (ten times tighter than any swept run), written independently; their
disagreement (and that with the closed form) is the reference's *uncertainty*, listed with the scenes.

**Routes.** Every liesuslov method (fixed step: lie-euler, rkmk2, rkmk-heun, rkmk3, rkmk4, rkmk5,
rkmk8 over a sweep of step sizes; adaptive: rkmk23, rkmk45, rkmk853 over a sweep of tolerances) in both
charts (exponential and Cayley), and scipy's `solve_ivp` with RK45, DOP853 and Radau over tolerance
sweeps (atol = 10⁻² rtol for both libraries). scipy integrates the *embedded* ODE — the state
(ξ, vec g) with Γ = gᵀγ when the attitude is reconstructed, (ξ, Γ) otherwise — with a numpy right-hand
side written by hand for each scene, as a user would.

**Timing.** Wall time of the whole call (`ls.integrate` or `solve_ivp`), the minimum over repeats
after one warm-up run (repeats stop once they add up to 0.6 s, at least one); as in `timeit`, one
garbage collection before the repeats and none during them. BLAS threads as the environment sets them
(the numbers below were taken with `OPENBLAS_NUM_THREADS=1`: on a loaded 2-core machine a threaded BLAS
makes small products erratic for both libraries).

**Errors.** At the final time t1, where both libraries land exactly: the largest absolute component
error of Ω (so(n) coordinates), of Γ, of g, and of the pendulum's (q, v); a run's *error* is the largest
of those its scene has. Structure: max|gᵀg − I|, max||Γ| − 1| and the constraint components max|⟨aⁱ, Ω⟩|,
and the drift max|F(t) − F(0)| of every first integral, all over every step of the run.

**Throughput, cost against n, long run.** RKMK4 with reconstruction, h = 0.01, output at the final time
only: a batch of random initial data in D advanced in one vectorised run (n = 3: Lagrange, n = 4:
Klebsh–Tisserand); one trajectory of the Klebsh–Tisserand body in SO(n), n = 3 … 256, with the growth
exponent fitted over the three largest sizes (sizes above 64 run in a child process with memory and
time limits: a failure there is recorded, not fatal); one trajectory of 10⁶ steps. Where `integrate` has
a `backend` option, the n-sweep is measured with `numpy` and with the default; every table names the
backend that ran. `--quick` runs the numpy path (no one-off kernel compilation).

**The ratio table and the goal.** For each scene and error level 10⁻⁵ … 10⁻¹⁰, the time of the fastest
route of each library to reach it (log time interpolated linearly in log error between consecutive points
of a route's sweep), and their ratio. The goal is liesuslov ≤ 0.5 × scipy at every level, with the
structure exact — reported here, never asserted in the tests.
"""


def _plot_scene(path: Path, scene_key: str, title: str, rows: list[dict], levels: Sequence[float]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9.5, 5.5))
    routes: dict[str, list] = {}
    for r in rows:
        if r["scene"] == scene_key and r["status"] == "ok" and np.isfinite(r["error"]) and r["error"] > 0:
            routes.setdefault(r["route"], []).append(r)
    colors = plt.get_cmap("tab10")
    lie_methods = sorted({r["method"] for rs in routes.values() for r in rs if r["library"] == "liesuslov"})
    scipy_marks = {"RK45": "s", "DOP853": "D", "Radau": "^"}
    for route, rs in sorted(routes.items()):
        rs = sorted(rs, key=lambda r: -r["setting"])
        t = [r["wall_time"] for r in rs]
        e = [r["error"] for r in rs]
        if rs[0]["library"] == "scipy":
            ax.loglog(t, e, "--", color="black", marker=scipy_marks.get(rs[0]["method"], "x"), ms=5, lw=1.2,
                      label=route)
        else:
            c = colors(lie_methods.index(rs[0]["method"]) % 10)
            ls_ = ":" if rs[0]["chart"] == "cayley" else "-"
            ax.loglog(t, e, ls_, color=c, marker="o", ms=3, lw=1.2, label=route)
    for lv in levels:
        ax.axhline(lv, color="0.85", lw=0.6, zorder=0)
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel("error at t1 (max abs)")
    ax.set_title(title)
    ax.legend(fontsize=6.5, ncol=2, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    _save_fig(fig, path)
    plt.close(fig)


def _plot_throughput(path: Path, rows: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for n in sorted({r["n"] for r in rows}):
        rs = [r for r in rows if r["n"] == n and r["status"] == "ok"]
        ax.loglog([r["batch"] for r in rs], [r["ns_per_traj_step"] for r in rs], "o-", label=f"n = {n}")
    ax.axhline(1000.0, color="0.6", ls="--", lw=0.8, label="1 µs")
    ax.set_xlabel("batch size")
    ax.set_ylabel("ns per trajectory-step")
    ax.set_title("RKMK4 with reconstruction: batch throughput")
    ax.legend()
    fig.tight_layout()
    _save_fig(fig, path)
    plt.close(fig)


def _plot_scaling(path: Path, rows: list[dict], fits: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for key in dict.fromkeys(_scaling_key(r) for r in rows):
        rs = [r for r in rows if _scaling_key(r) == key and r.get("status") == "ok"]
        if not rs:
            continue
        label = key + (f" (∝ n^{fits[key]['exponent']:.2f})" if key in fits else "")
        ax.loglog([r["n"] for r in rs], [r["us_per_step"] for r in rs], "o-", label=label)
    ok = [r for r in rows if r.get("status") == "ok"]
    if ok:
        n0, t0 = ok[0]["n"], ok[0]["us_per_step"]
        ns = np.array(sorted({r["n"] for r in ok}), dtype=float)
        ax.loglog(ns, t0 * (ns / n0) ** 2, color="0.6", ls="--", lw=0.8, label="∝ n²")
    ax.set_xlabel("n")
    ax.set_ylabel("µs per step")
    ax.set_title("RKMK4 + reconstruction, Fedorov–Kozlov D")
    ax.legend()
    fig.tight_layout()
    _save_fig(fig, path)
    plt.close(fig)


def _umask_mode() -> int:
    """0o666 less the process umask: the mode an ordinary ``open(path, "w")`` would give."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def _save_fig(fig, path: Path) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}-", suffix=".png", dir=path.parent)
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=90)
        os.chmod(tmp, _umask_mode())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _write_text(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (temporary file in the same folder, then rename)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}-", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
        os.chmod(tmp, _umask_mode())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _copy_atomic(src: Path, dst: Path) -> Path:
    dst.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{dst.name}-", dir=dst.parent)
    os.close(fd)
    try:
        shutil.copyfile(src, tmp)
        os.chmod(tmp, _umask_mode())
        os.replace(tmp, dst)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return dst


def _have_matplotlib() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


# ====================================================================== front door
def run_bench(out_dir, *, quick: bool = False, scenes: Sequence[str] | None = None, progress: bool = True,
              repeats: int | None = None, docs=None, config: BenchConfig | None = None) -> BenchReport:
    """Run the benchmark and write its report into ``out_dir``.

    Parameters
    ----------
    out_dir : str or Path
        Output folder (created). Receives ``results.csv``, ``ratios.csv``, ``throughput.csv``,
        ``nscaling.csv``, ``longrun.csv`` (those measured), ``summary.md`` and PNG plots.
    quick : bool
        The reduced preset (:meth:`BenchConfig.quick`, under a minute); else :meth:`BenchConfig.full`.
    scenes : sequence of str, optional
        Keys of :data:`SCENES` (default: all).
    progress : bool
        A tqdm progress bar over the runs (on stderr).
    repeats : int, optional
        Timed repeats after the warm-up (default 5, quick 1).
    docs : str or Path, optional
        Also write the documentation page there (plots copied to ``img/`` next to it).
    config : BenchConfig, optional
        A full configuration (overrides ``quick``; ``scenes`` and ``repeats`` still apply when given).

    Returns
    -------
    BenchReport

    Raises
    ------
    ValueError
        An unknown scene (the message lists the valid ones), ``repeats < 1``, or an invalid configuration.
    """
    if config is None:
        config = BenchConfig.quick() if quick else BenchConfig.full()
    if scenes is not None:
        if isinstance(scenes, str):
            scenes = [s for s in scenes.split(",") if s.strip()]
        config = replace(config, scenes=tuple(scenes))
    if repeats is not None:
        config = replace(config, repeats=repeats)
    config = config.validated()
    extra_kw = _integrate_kwargs(config.backend)
    out = Path(out_dir)
    start = time.perf_counter()
    built = {k: build_scene(k) for k in config.scenes}
    plans = {k: _plan(config, built[k]) for k in config.scenes}
    total = (sum(len(p) + 1 for p in plans.values()) + len(config.batch_sizes) * len(config.batch_dims)
             + len(config.scaling_sizes) * len(config.charts) * len(_scaling_backends(config))
             + (1 if config.long_run_steps else 0))
    bar = _bar(total, progress)

    def tick(desc: str | None = None) -> None:
        if bar is not None:
            if desc:
                bar.set_postfix_str(desc, refresh=False)
            bar.update(1)

    report = BenchReport(machine=machine_info())
    try:
        for key in config.scenes:
            scene = built[key]
            ref = _reference(scene, extra_kw)
            report.references[key] = {"uncertainty": ref.uncertainty, "how": scene.reference, "title": scene.title,
                                      "t1": scene.t1, "details": ref.details}
            tick(f"{key}: reference")
            for task in plans[key]:
                report.rows.append(_execute(task, scene, ref, config.repeats, extra_kw))
                tick(f"{key}: {task.route} {task.kind}={task.value:.2g}")
        report.throughput = _throughput(config, extra_kw, lambda: tick("throughput"))
        report.scaling = _scaling(config, extra_kw, lambda: tick("n-scaling"))
        report.scaling_exponent = _fit_exponent(report.scaling)
        report.longrun = _long_run(config, extra_kw, lambda: tick("long run"))
    finally:
        if bar is not None:
            bar.close()
    report.ratios = _ratio_table(report.rows, config.scenes, config.levels, report.references)
    report.elapsed = time.perf_counter() - start
    _write_outputs(report, config, out, docs)
    return report


def _bar(total: int, on: bool):
    if not on:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None
    return tqdm(total=total, unit="run", desc="liesuslov bench", file=sys.stderr, dynamic_ncols=True)


def _write_outputs(report: BenchReport, config: BenchConfig, out: Path, docs) -> None:
    """Write every output into a staging folder inside ``out``, then move the files into place.

    A failure while writing (a plot, the disk) leaves ``out`` and the docs page as they were.
    """
    out.mkdir(parents=True, exist_ok=True)
    plots = config.plots and _have_matplotlib()
    config = replace(config, plots=plots)
    stage = Path(tempfile.mkdtemp(prefix=".bench-staging-", dir=out))
    names: dict[str, str] = {}
    try:
        if plots:
            for s in config.scenes:
                names[f"plot {s}"] = f"bench-{s}.png"
                _plot_scene(stage / names[f"plot {s}"], s, report.references[s]["title"], report.rows,
                            config.levels)
            if report.throughput and any(r["status"] == "ok" for r in report.throughput):
                names["plot throughput"] = "bench-throughput.png"
                _plot_throughput(stage / names["plot throughput"], report.throughput)
            if report.scaling and any(r.get("status") == "ok" for r in report.scaling):
                names["plot nscaling"] = "bench-nscaling.png"
                _plot_scaling(stage / names["plot nscaling"], report.scaling, report.scaling_exponent)
        tables = {"results": (report.rows, RESULT_COLUMNS), "ratios": (report.ratios, None),
                  "throughput": (report.throughput, None), "nscaling": (report.scaling, None),
                  "longrun": (report.longrun, None)}
        for name, (rows, columns) in tables.items():
            if rows or name in ("results", "ratios"):
                names[name] = f"{name}.csv"
                _write_text(stage / names[name], _csv_text(rows, columns))
        title = ("# liesuslov benchmark: speed against error\n\nGenerated by `python -m liesuslov.bench"
                 + (" --quick" if config.preset == "quick" else "")
                 + "`. Full data: `results.csv` and the other CSV files here.\n")
        names["summary"] = "summary.md"
        _write_text(stage / "summary.md",
                    "\n\n".join([title] + _summary_sections(report, config, "." if plots else None)) + "\n")
        page = None
        if docs is not None:
            page = "\n\n".join([_DOCS_INTRO.rstrip()] + _summary_sections(report, config, "img" if plots else None))
        paths: dict[str, str] = {}
        for key, name in names.items():
            os.replace(stage / name, out / name)
            paths[key] = str(out / name)
        if docs is not None:
            docs = Path(docs)
            for key, name in names.items():
                if key.startswith("plot "):
                    _copy_atomic(out / name, docs.parent / "img" / name)
            paths["docs"] = str(_write_text(docs, page + "\n"))
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    report.paths = paths


# ====================================================================== command line
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the benchmark's options to ``parser`` (used by ``liesuslov bench`` and ``python -m liesuslov.bench``)."""
    parser.add_argument("--out", default="liesuslov-bench", metavar="DIR",
                        help="output folder for the CSV files, summary.md and the plots (default: liesuslov-bench)")
    parser.add_argument("--quick", action="store_true",
                        help="reduced set (rkmk4, rkmk45, rkmk853 x exp/cayley, 3 settings each; under a minute)")
    parser.add_argument("--scenes", default=None, metavar="LIST",
                        help=f"comma-separated scenes (default: all of {', '.join(SCENES)})")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--repeats", type=int, default=None, metavar="N",
                        help="timed repeats after the warm-up run (default 5; --quick 1)")
    parser.add_argument("--docs", default=None, metavar="PATH",
                        help="also write the documentation page (e.g. docs/performance.md; plots go to img/ beside it)")
    parser.add_argument("--backend", default=None,
                        help="passed to integrate(backend=...) when liesuslov has the option (default: the "
                             "library's default; --quick: numpy, which needs no compilation)")


def run_from_args(args: argparse.Namespace) -> int:
    """Run the benchmark from parsed arguments (see :func:`add_arguments`); returns the exit status."""
    scenes = None if args.scenes is None else [s for s in args.scenes.split(",") if s.strip()]
    config = BenchConfig.quick() if args.quick else BenchConfig.full()
    if getattr(args, "backend", None) is not None:
        config = replace(config, backend=args.backend)
    try:
        report = run_bench(args.out, quick=args.quick, scenes=scenes, progress=not args.no_progress,
                           repeats=args.repeats, docs=args.docs, config=config)
    except ValueError as exc:
        print(f"liesuslov bench: error: {exc}", file=sys.stderr)
        return 2
    print(f"liesuslov bench: {len(report.rows)} runs in {report.elapsed:.1f} s")
    for r in report.ratios:
        ratio = f"{r['ratio']:.3f}" if np.isfinite(r["ratio"]) else "—"
        print(f"  {r['scene']:<17} {r['level']:.0e}: liesuslov {_ms(r['liesuslov_time']):>10} "
              f"({r['liesuslov_route'] or '—'}), scipy {_ms(r['scipy_time']):>10} ({r['scipy_route'] or '—'}), "
              f"ratio {ratio}")
    for name, p in report.paths.items():
        if not name.startswith("plot"):
            print(f"wrote {p}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m liesuslov.bench``."""
    parser = argparse.ArgumentParser(prog="python -m liesuslov.bench",
                                     description="liesuslov work-precision benchmark against scipy's solve_ivp")
    add_arguments(parser)
    return run_from_args(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
