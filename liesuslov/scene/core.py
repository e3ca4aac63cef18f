"""The validated scene: :class:`Scene` (what is integrated, how, and where the output goes)."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .schema import _DEFAULT_N_OUT
from .toml import to_toml

__all__ = ["Scene"]


@dataclass(frozen=True, eq=False)
class Scene:
    """A validated scene: the system, the initial data, the integration options and the output.

    Build one with :func:`load_scene`, :func:`scene_from_dict` or :func:`default_scene`; the fields
    hold validated values (numpy arrays, a :class:`~liesuslov.SuslovSystem`).

    Attributes
    ----------
    name : str
        Title used in reports and figures (``[output].name``, default: the file's stem or the case).
    system : SuslovSystem
    omega0 : ndarray, shape (d,)
        Initial Omega as coordinates in the algebra basis (in D).
    Gamma0 : ndarray of shape (n,), or None
    g0 : ndarray of shape (m, m), or None
    t_span : (float, float)
    method, chart, form : str
    h : float or None
    rtol, atol : float
    n_out : int or None
        Number of evenly spaced output times (None when ``t_eval`` is given or every step is kept).
    t_eval : ndarray or None
        Explicit output times.
    every_step : bool
        ``t_eval = "steps"``: the solution at every step.
    reconstruct, progress, figures : bool
    backend : str or None
        ``backend`` of :func:`~liesuslov.integrate` ("auto", "numpy", "numba"); None: its default.
    max_steps : int or None
        ``max_steps`` of :func:`~liesuslov.integrate` (per trajectory); None: its default, 10⁷.
    out_dir : str
    tol : float
        Tolerance of ``liesuslov check`` (``[check].tol``).
    case : Case or None
        The named case, when the scene is one (its first integrals are then known).
    description : str
    source : str
        Where the scene came from (a path or ``"<default scene>"``), used in error messages.
    data : dict
        The scene as a TOML document (plain data), with any overrides applied: :meth:`to_toml`.
    """

    name: str
    system: Any
    omega0: np.ndarray
    t_span: tuple[float, float]
    Gamma0: np.ndarray | None = None
    g0: np.ndarray | None = None
    method: str = "rkmk45"
    chart: str = "exp"
    form: str = "auto"
    h: float | None = None
    rtol: float = 1e-8
    atol: float = 1e-10
    n_out: int | None = _DEFAULT_N_OUT
    t_eval: np.ndarray | None = None
    every_step: bool = False
    reconstruct: bool = False
    progress: bool = False
    backend: str | None = None
    max_steps: int | None = None
    out_dir: str = "liesuslov-out"
    figures: bool = True
    tol: float = 1e-8
    case: Any = None
    description: str = ""
    source: str = "<scene>"
    data: dict = field(default_factory=dict, repr=False)

    # ------------------------------------------------------------------ what is integrated
    @property
    def integrals(self) -> dict[str, Callable]:
        """First integrals ``F(omega, Gamma) -> (...)``: the case's, or just the energy."""
        if self.case is not None:
            return dict(self.case.integrals)
        system = self.system

        def energy(x, G):
            return system.energy(x, G)
        return {"energy": energy}

    def output_times(self) -> np.ndarray | None:
        """The ``t_eval`` passed to :func:`~liesuslov.integrate` (None: every step)."""
        if self.every_step:
            return None
        if self.t_eval is not None:
            return self.t_eval
        return np.linspace(self.t_span[0], self.t_span[1], self.n_out or _DEFAULT_N_OUT)

    def model(self):
        """The model that :func:`~liesuslov.integrate` will run (``system.model(...)``)."""
        return self.system.model(gamma=True if self.Gamma0 is not None else None, form=self.form)

    def build(self) -> tuple[Any, dict[str, Any]]:
        """The system and the keyword arguments of :func:`liesuslov.integrate`.

        Returns
        -------
        system : SuslovSystem
        kwargs : dict
            ``Omega0``, ``t_span``, ``Gamma0``, ``g0``, ``reconstruct``, ``method``, ``chart``, ``h``,
            ``rtol``, ``atol``, ``t_eval``, ``form``, ``progress``, ``backend``, ``max_steps`` (absent where unset):
            ``ls.integrate(system, **kwargs)`` runs the scene.
        """
        kw: dict[str, Any] = {"Omega0": self.omega0.copy(), "t_span": tuple(self.t_span),
                              "reconstruct": self.reconstruct, "method": self.method, "chart": self.chart,
                              "rtol": self.rtol, "atol": self.atol, "t_eval": self.output_times(),
                              "form": self.form, "progress": self.progress}
        if self.h is not None:
            kw["h"] = self.h
        if self.Gamma0 is not None:
            kw["Gamma0"] = self.Gamma0.copy()
        if self.g0 is not None:
            kw["g0"] = self.g0.copy()
        if self.backend is not None:
            kw["backend"] = self.backend
        if self.max_steps is not None:
            kw["max_steps"] = self.max_steps
        return self.system, kw

    def run(self, **overrides):
        """Integrate the scene: ``ls.integrate(system, **kwargs)``, ``overrides`` replacing kwargs.

        Returns
        -------
        Solution
            Check ``sol.success``: a failed integration (non-finite state, step-size underflow)
            returns with ``status = -1`` and a message naming the time.
        """
        from ..integrators import integrate

        system, kw = self.build()
        kw.update(overrides)
        return integrate(system, **kw)

    # ------------------------------------------------------------------ variants
    def with_options(self, *, t_end: float | None = None, out_dir: str | None = None,
                     figures: bool | None = None, progress: bool | None = None,
                     backend: str | None = None, max_steps: int | None = None) -> Scene:
        """A copy with the end time, output folder, figures, progress bar, backend or max_steps changed (the CLI's
        overrides).

        Explicit ``t_eval`` times beyond a shorter ``t_end`` are dropped (``t_end`` itself is kept).
        """
        changes: dict[str, Any] = {}
        data = json.loads(json.dumps(self.data))  # a deep copy of plain data
        if t_end is not None:
            t0 = self.t_span[0]
            try:
                t1 = float(t_end)
            except (TypeError, ValueError) as exc:
                raise TypeError(f"t_end must be a number, got {t_end!r}") from exc
            if not math.isfinite(t1) or t1 == t0:
                raise ValueError(f"t_end must be finite and differ from t0 = {t0:g}, got {t_end!r}")
            changes["t_span"] = (t0, t1)
            data.setdefault("integrate", {})["t_span"] = [t0, t1]
            if self.t_eval is not None:
                lo, hi = min(t0, t1), max(t0, t1)
                te = self.t_eval[(self.t_eval >= lo) & (self.t_eval <= hi)]
                if te.size == 0 or te[-1] != t1:
                    te = np.append(te, t1)
                changes["t_eval"] = te
                data["integrate"]["t_eval"] = te.tolist()
        if out_dir is not None:
            changes["out_dir"] = str(out_dir)
            data.setdefault("output", {})["dir"] = str(out_dir)
        if figures is not None:
            changes["figures"] = bool(figures)
            data.setdefault("output", {})["figures"] = bool(figures)
        if progress is not None:
            changes["progress"] = bool(progress)
            data.setdefault("integrate", {})["progress"] = bool(progress)
        if backend is not None:
            choices = _backends()
            if choices and backend not in choices:
                raise ValueError(f"backend must be one of {', '.join(choices)}, got {backend!r}")
            changes["backend"] = str(backend)
            data.setdefault("integrate", {})["backend"] = str(backend)
        if max_steps is not None:
            if isinstance(max_steps, bool) or not isinstance(max_steps, int):
                raise TypeError(f"max_steps must be an integer, got {max_steps!r}")
            if max_steps < 1:
                raise ValueError(f"max_steps must be a positive integer, got {max_steps!r}")
            changes["max_steps"] = max_steps
            data.setdefault("integrate", {})["max_steps"] = max_steps
        return replace(self, data=data, **changes)

    def to_toml(self) -> str:
        """The scene as TOML text (validated values, overrides applied; comments are not kept)."""
        head = f"# liesuslov scene (from {self.source})\n"
        return head + to_toml(self.data)

    def __repr__(self) -> str:
        return (f"Scene({self.name!r}, {self.system!r}, t_span={self.t_span}, method={self.method!r}, "
                f"reconstruct={self.reconstruct})")


def _backends() -> tuple[str, ...]:
    """The ``backend`` choices of :func:`~liesuslov.integrate` (empty if it has no such option)."""
    try:
        from ..integrators.integrate import BACKENDS
    except ImportError:
        return ()
    return tuple(BACKENDS)
