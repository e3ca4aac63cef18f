"""Scene files: one experiment (body, constraints, potential, initial data, numerics, output) in TOML.

A scene file is read with :func:`load_scene` (stdlib ``tomllib``; ``tomli`` on Python 3.10) and
validated completely before anything is integrated: every mistake is a ``ValueError`` (a wrong value
or shape) or ``TypeError`` (a wrong type) whose message starts with the file and the field path,
e.g. ``scene.toml: [potential].B must be a list of 4 numbers, got a list of 3 numbers``, and says
what is expected. Unknown keys are rejected with the list of valid ones, so a typo never passes
silently. The format is documented field by field in ``docs/quickstart.md``; in short::

    description = "free text"        # optional
    gyroscopic = 0.0                 # optional, so(3) only: the force eps * Gamma x w

    [body]                           # either [body] (+ [constraints], [potential]) ...
    algebra = "so"                   # "so" (with n), "se2", "se3", or "custom" (structure_constants)
    n = 4
    mass_tensor = [1.0, 2.0, 3.0, 4.0]   # or its n×n matrix; or principal_moments (n = 3); or inertia

    [constraints]                    # default on so(n): Fedorov–Kozlov; or annihilator / span / "none"
    annihilator = [[0, 0, 1]]

    [potential]
    kind = "quadratic"               # "linear" or "quadratic"
    B = [4.0, 3.0, 2.0, 1.0]

    [case]                           # ... or a named case of ls.CASES with its parameters
    name = "klebsh_tisserand"
    [case.parameters]
    I = [1.0, 2.0, 3.0, 4.0]
    B = [4.0, 3.0, 2.0, 1.0]

    [initial]
    xi = [0.3, -0.2, 0.25]           # or omega (algebra coordinates), Omega (matrix), w (so(3))
    Gamma = [0.2, -0.4, 0.4, 0.8]    # unit vector (within 1e-8), needed when V != 0
    # g = [[...]]                    # initial attitude, with reconstruct = true

    [integrate]
    t_span = [0.0, 50.0]
    method = "rkmk853"               # a key of ls.METHODS
    chart = "exp"                    # or "cayley"
    rtol = 1e-10                     # atol, h (fixed-step methods), form
    n_out = 501                      # or t_eval = [...] or t_eval = "steps"
    reconstruct = true
    progress = false
    backend = "auto"                 # "numpy" or "numba" (the compiled kernel, liesuslov[fast])

    [output]
    name = "my scene"
    dir = "liesuslov-out"
    figures = true

    [check]
    tol = 1e-8                       # the tolerance of ``liesuslov check``

:data:`DEFAULT_SCENE` is the built-in scene of ``liesuslov run`` (``liesuslov run --print-default``).
"""

from __future__ import annotations

import difflib
import inspect
import json
import math
import re
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

__all__ = ["Scene", "load_scene", "scene_from_dict", "scene_from_text", "default_scene", "DEFAULT_SCENE",
           "to_toml"]

#: The built-in scene of ``liesuslov run`` (TOML text): the n = 4 Klebsh–Tisserand body with reconstruction.
DEFAULT_SCENE = '''\
# The built-in scene of `liesuslov run`: the n = 4 Klebsh–Tisserand body, with its attitude on SO(4).
# `liesuslov run --print-default > my_scene.toml` writes this text; edit it, then `liesuslov run my_scene.toml`.
description = "Klebsh–Tisserand case in SO(4): V = 1/2 sum B_i Gamma_i^2, motion on invariant tori"

[case]
name = "klebsh_tisserand"          # `liesuslov cases` lists the named cases
[case.parameters]
I = [1.0, 1.5, 2.0, 0.5]           # diagonal of the mass tensor
B = [4.0, 3.0, 2.5, 1.0]           # B_i > B_n: the trajectories wind on tori

[initial]
xi = [0.3, -0.2, 0.25]             # (Omega_14, Omega_24, Omega_34): the coordinates in D
Gamma = [0.2, -0.4, 0.4, 0.8]      # the vertical in the body frame, a unit vector

[integrate]
t_span = [0.0, 50.0]
method = "rkmk853"                 # adaptive Dormand–Prince 8(5,3) on the group
chart = "exp"
rtol = 1e-10
atol = 1e-12
n_out = 501                        # output times, evenly spaced
reconstruct = true                 # also integrate g in SO(4); then Gamma = g^T gamma
backend = "numpy"                  # "auto" uses the compiled kernel (liesuslov[fast]) when installed: worth
                                   # it for long single-trajectory runs; its first use compiles it (about 12 s, once)

[output]
name = "Klebsh–Tisserand, n = 4"
dir = "liesuslov-out"
figures = true

[check]
tol = 1e-8                         # `liesuslov check`: largest admissible drift and defect
'''

_MISSING = object()
_TOP_KEYS = ("description", "gyroscopic", "case", "body", "constraints", "potential", "initial", "integrate",
             "output", "check")
_BODY_KEYS = ("algebra", "n", "mass_tensor", "principal_moments", "inertia", "structure_constants",
              "representation")
_INTEGRATE_KEYS = ("t_span", "method", "chart", "h", "rtol", "atol", "n_out", "t_eval", "reconstruct",
                   "progress", "form", "backend")
_CALLABLE_PARAMETERS = ("v1", "dv1", "v2", "dv2")
_DEFAULT_N_OUT = 501


# ====================================================================== the scene
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
            ``rtol``, ``atol``, ``t_eval``, ``form``, ``progress``, ``backend`` (absent where unset):
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
        return self.system, kw

    def run(self, **overrides):
        """Integrate the scene: ``ls.integrate(system, **kwargs)``, ``overrides`` replacing kwargs.

        Returns
        -------
        Solution
            Check ``sol.success``: a failed integration (non-finite state, step-size underflow)
            returns with ``status = -1`` and a message naming the time.
        """
        from .integrators import integrate

        system, kw = self.build()
        kw.update(overrides)
        return integrate(system, **kw)

    # ------------------------------------------------------------------ variants
    def with_options(self, *, t_end: float | None = None, out_dir: str | None = None,
                     figures: bool | None = None, progress: bool | None = None,
                     backend: str | None = None) -> Scene:
        """A copy with the end time, output folder, figures, progress bar or backend changed (the CLI's overrides).

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
        return replace(self, data=data, **changes)

    def to_toml(self) -> str:
        """The scene as TOML text (validated values, overrides applied; comments are not kept)."""
        head = f"# liesuslov scene (from {self.source})\n"
        return head + to_toml(self.data)

    def __repr__(self) -> str:
        return (f"Scene({self.name!r}, {self.system!r}, t_span={self.t_span}, method={self.method!r}, "
                f"reconstruct={self.reconstruct})")


# ====================================================================== entry points
def load_scene(path) -> Scene:
    """Read and validate a scene file.

    Parameters
    ----------
    path : str or Path
        A TOML file (format: the module docstring and ``docs/quickstart.md``).

    Returns
    -------
    Scene

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError, TypeError
        For a file that is not valid TOML or not a valid scene; the message starts with the path and
        names the field.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"scene file not found: {p}")
    if p.is_dir():
        raise IsADirectoryError(f"{p} is a directory, not a scene file")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{p}: not a UTF-8 text file ({exc.reason})") from exc
    return scene_from_text(text, source=str(p), name=p.stem)


def scene_from_text(text: str, source: str = "<scene>", name: str | None = None) -> Scene:
    """Parse TOML text and validate it as a scene (see :func:`scene_from_dict`)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{source}: not valid TOML: {exc}") from exc
    return scene_from_dict(data, source=source, name=name)


def default_scene() -> Scene:
    """The built-in scene of ``liesuslov run`` (:data:`DEFAULT_SCENE`)."""
    return scene_from_text(DEFAULT_SCENE, source="<default scene>", name="default")


def scene_from_dict(d: Mapping[str, Any], source: str = "<scene>", name: str | None = None) -> Scene:
    """Validate a scene given as a dictionary (the parsed TOML document).

    Parameters
    ----------
    d : mapping
        The document: tables as dicts, arrays as lists.
    source : str
        Prefix of every error message (the file name).
    name : str, optional
        Default title when ``[output].name`` is absent.

    Returns
    -------
    Scene
    """
    top = _Table(d, source, "", _TOP_KEYS)
    description = top.string("description", default="")
    case = None
    if top.has("case"):
        for key in ("body", "constraints", "potential", "gyroscopic"):
            if top.has(key):
                what = f"[{key}]" if key != "gyroscopic" else "gyroscopic"
                raise ValueError(f"{source}: {what} cannot be combined with [case]: the named case fixes the "
                                 f"body, constraints, potential and gyroscopic term; remove {what} or the case")
        case = _case(top, source)
        system = case.system
        default_name = case.name
    else:
        if not top.has("body"):
            raise ValueError(f"{source}: a scene needs [body] (algebra, inertia) or [case] (a named case, see "
                             "`liesuslov cases`)")
        system = _system(top, source)
        default_name = name or "scene"

    # ---- integration options first: the initial data depend on reconstruct
    it = top.table("integrate", required=True)
    t_span = it.pair("t_span")
    from .integrators import CHARTS, METHODS

    method = it.choice("method", tuple(METHODS), default="rkmk45")
    chart = it.choice("chart", CHARTS, default="exp")
    from .mechanics import FORMS

    form = it.choice("form", ("auto",) + FORMS, default="auto")
    if form != "auto":
        why = system.form_obstruction(form)
        if why is not None:
            raise it.error("form", f"= {form!r} does not hold for this system: {why}")
    h = it.positive("h", default=None)
    if not METHODS[method].adaptive and h is None:
        raise it.error("h", f"(the step size) is required by the fixed-step method {method!r}; give "
                            "h = 0.01, say, or choose an adaptive method such as \"rkmk45\"")
    rtol = it.positive("rtol", default=1e-8)
    atol = it.positive("atol", default=1e-10)
    n_out, t_eval, every_step = _output_times(it, t_span)
    reconstruct = it.boolean("reconstruct", default=False)
    progress = it.boolean("progress", default=False)
    backend = it.choice("backend", _backends(), default=None) if it.has("backend") else None
    alg = system.algebra
    if reconstruct and alg.matrix_size is None:
        raise it.error("reconstruct", f"= true needs a matrix representation of {alg.name}: give "
                                      "[body].representation")

    omega0, Gamma0, g0 = _initial(top.table("initial", required=True), system, reconstruct)

    out = top.table("output")
    out_name = out.string("name", default=default_name)
    out_dir = out.string("dir", default="liesuslov-out")
    if not out_dir.strip():
        raise out.error("dir", "must be a folder name, got an empty string")
    figures = out.boolean("figures", default=True)
    chk = top.table("check", allowed=("tol",))
    tol = chk.positive("tol", default=1e-8)

    return Scene(name=out_name, system=system, omega0=omega0, t_span=t_span, Gamma0=Gamma0, g0=g0,
                 method=method, chart=chart, form=form, h=h, rtol=rtol, atol=atol, n_out=n_out, t_eval=t_eval,
                 every_step=every_step, reconstruct=reconstruct, progress=progress, backend=backend, out_dir=out_dir,
                 figures=figures, tol=tol, case=case, description=description, source=source,
                 data=_plain(dict(d)))


# ====================================================================== the parts of a scene
def _case(top: _Table, source: str):
    from .mechanics import CASES

    raw = top.get("case")
    if isinstance(raw, str):
        name, params_raw = raw, {}
        where = "case"
    else:
        t = top.table("case", allowed=("name", "parameters"))
        name = t.string("name")
        params_raw = t.get("parameters", {})
        if not isinstance(params_raw, dict):
            raise TypeError(f"{source}: [case].parameters must be a table of the case's parameters, got "
                            f"{_describe(params_raw)}")
        where = "[case].name"
    if name not in CASES:
        hint = _did_you_mean(name, CASES)
        raise ValueError(f"{source}: {where} must be one of {', '.join(CASES)}; got {name!r}{hint}")
    entry = CASES[name]
    sig = inspect.signature(entry.constructor)
    settable = [p for p in sig.parameters if p not in _CALLABLE_PARAMETERS]
    ptab = _Table(params_raw, source, "case.parameters", tuple(sig.parameters))
    params: dict[str, Any] = {}
    for key, value in params_raw.items():
        if key in _CALLABLE_PARAMETERS:
            raise ptab.error(key, f"is a Python function and cannot be set in a scene file (the example "
                                  f"function of the case is used); settable here: {', '.join(settable)}. "
                                  f"Build the case in Python for your own: ls.cases.{name}(...)")
        if key == "potential":
            params[key] = _potential_of(ptab, key, value, None)
            continue
        if isinstance(value, (bool, str)) or _is_number(value):
            if isinstance(value, str):
                raise ptab.type_error(key, "must be a number, a list of numbers or a boolean", value)
            if _is_number(value) and not math.isfinite(value):
                raise ptab.error(key, f"must be finite, got {value!r}")
            params[key] = value
        elif isinstance(value, list):
            params[key] = ptab.array(key, None, "a list (or nested lists) of numbers")
        else:
            raise ptab.type_error(key, "must be a number, a list of numbers or a boolean", value)
    try:
        case = entry.build(**params)
    except (ValueError, TypeError) as exc:
        msg = str(exc)
        m = re.match(r"(\w+)\b", msg)
        if m and m.group(1) in sig.parameters:
            key = m.group(1)
            rest = msg[len(key):]
            raise type(exc)(f"{source}: [case.parameters].{key}{rest if rest[:1] in ' :' else ' ' + rest}") \
                from exc
        raise type(exc)(f"{source}: [case.parameters] of {name!r}: {msg}") from exc
    return case


def _system(top: _Table, source: str):
    from .algebra import Inertia, LieAlgebra, Subspace, se, so, suslov_distribution
    from .mechanics import SuslovSystem

    body = top.table("body", required=True, allowed=_BODY_KEYS)
    has_C = body.has("structure_constants")
    algebra = body.choice("algebra", ("so", "se2", "se3", "custom"), default="custom" if has_C else "so")
    given = [k for k in ("mass_tensor", "principal_moments", "inertia") if body.has(k)]
    if len(given) > 1:
        raise ValueError(f"{source}: [body] takes one of mass_tensor, principal_moments, inertia; got "
                         f"{', '.join(given)}")
    if not given:
        raise ValueError(f"{source}: [body] needs the inertia: mass_tensor (so(n): n×n or its diagonal), "
                         "principal_moments (so(3)) or inertia (any algebra: a dim×dim SPD matrix)")
    how = given[0]
    if algebra != "custom":
        for key in ("structure_constants", "representation"):
            if body.has(key):
                raise body.error(key, f"is only for algebra = \"custom\" (algebra = {algebra!r} has its own)")
    if algebra != "so":
        if body.has("n"):
            raise body.error("n", f"is only for algebra = \"so\" ({algebra!r} has a fixed dimension)")
        if how != "inertia":
            raise body.error(how, f"is for a rigid body in SO(n) (algebra = \"so\"); on {algebra!r} give "
                                  "[body].inertia, a dim×dim symmetric positive definite matrix")

    # ---- the algebra and the inertia
    if algebra == "so":
        n = body.integer("n", default=None, minimum=2)
        if how == "principal_moments":
            if n is not None and n != 3:
                raise body.error("principal_moments", f"are for n = 3 (the paper's J acting on w), got n = {n}")
            n = 3
            J = body.array("principal_moments", [(3,), (3, 3)],
                           "a list of 3 numbers (J1, J2, J3) or a symmetric 3×3 matrix (the w form)")
            alg = so(3)
            inertia = _wrap(body, "principal_moments", lambda: Inertia.from_principal_moments(J))
        elif how == "mass_tensor":
            if n is None:
                raw = body.get("mass_tensor")
                n = len(raw) if isinstance(raw, list) else 0
                if n < 2:
                    raise body.type_error("mass_tensor", "must be the n diagonal entries or an n×n matrix "
                                                         "(n >= 2)", raw)
            I = body.array("mass_tensor", [(n,), (n, n)],
                           f"a list of {n} numbers (the diagonal) or a {n}×{n} symmetric matrix")
            alg = so(n)
            inertia = _wrap(body, "mass_tensor", lambda: Inertia.from_mass_tensor(I))
        else:
            if n is None:
                raise body.error("n", "is required with [body].inertia on so(n) (the matrix is dim×dim, "
                                      "dim = n(n-1)/2)")
            alg = so(n)
    elif algebra in ("se2", "se3"):
        alg = se(int(algebra[-1]))
    else:
        if not has_C:
            raise body.error("structure_constants", "are required with algebra = \"custom\": an array "
                                                    "C[i][j][k] with [e_i, e_j] = sum_k C[i][j][k] e_k")
        C = body.array("structure_constants", [(None, None, None)], "a d×d×d array (nested lists) of numbers")
        if not (C.shape[0] == C.shape[1] == C.shape[2]):
            raise body.error("structure_constants", f"must be a d×d×d array, got shape {C.shape}")
        R = None
        if body.has("representation"):
            R = body.array("representation", [(C.shape[0], None, None)],
                           f"{C.shape[0]} square matrices (the basis of a matrix representation)")
        alg = _wrap(body, "structure_constants", lambda: LieAlgebra(C, representation=R, name="custom"))
    if how == "inertia":
        d = alg.dim
        K = body.array("inertia", [(d, d)], f"a {d}×{d} symmetric positive definite matrix ({alg.name})")
        inertia = _wrap(body, "inertia", lambda: Inertia(alg, K))

    # ---- constraints
    is_so = alg.name.startswith("so(")
    raw = top.data.get("constraints", _MISSING)
    if raw is _MISSING:
        if not is_so:
            raise ValueError(f"{source}: [constraints] is required on {alg.name}: give annihilator = [[...]] "
                             "(the constraint covectors), span = [[...]] (a basis of D) or constraints = \"none\"")
        D = suslov_distribution(alg.n)
    else:
        if isinstance(raw, str):
            kind = raw
            where = "constraints"
            ctab = None
        else:
            ctab = top.table("constraints", allowed=("kind", "annihilator", "span"))
            present = [k for k in ("kind", "annihilator", "span") if ctab.has(k)]
            if len(present) != 1:
                raise ValueError(f"{source}: [constraints] takes exactly one of kind, annihilator, span; got "
                                 f"{', '.join(present) if present else 'none of them'}")
            kind = present[0] if present[0] != "kind" else ctab.string("kind")
            where = "[constraints].kind"
        d = alg.dim
        if kind == "annihilator":
            A = ctab.array("annihilator", [(None, d), (d,)], f"a list of covectors of {d} numbers ({alg.name})")
            D = _wrap(ctab, "annihilator", lambda: Subspace.annihilator(alg, A))
        elif kind == "span":
            S = ctab.array("span", [(None, d), (d,)], f"a list of vectors of {d} numbers ({alg.name})")
            D = _wrap(ctab, "span", lambda: Subspace(alg, S))
            if D.dim == 0:
                raise ctab.error("span", "spans the zero subspace: nothing can move")
        elif kind == "none":
            D = Subspace(alg, np.eye(d))
        elif kind == "fedorov_kozlov":
            if not is_so:
                raise ValueError(f"{source}: {where} = \"fedorov_kozlov\" is for so(n), this is {alg.name}")
            D = suslov_distribution(alg.n)
        else:
            raise ValueError(f"{source}: {where} must be \"fedorov_kozlov\" or \"none\" (or give "
                             f"[constraints].annihilator / .span), got {kind!r}")

    # ---- potential and gyroscopic term
    potential = None
    if top.has("potential"):
        if not is_so:
            raise ValueError(f"{source}: [potential] needs a body in SO(n) (algebra = \"so\"); on {alg.name} "
                             "only V = 0 is defined (the Euler–Poincaré–Suslov system)")
        potential = _potential_of(top, "potential", top.get("potential"), alg.n)
    eps = top.number("gyroscopic", default=0.0)
    if eps != 0.0 and not (is_so and alg.n == 3):
        raise top.error("gyroscopic", f"must be 0 here: the gyroscopic force eps * Gamma x w is defined for "
                                      f"so(3) only, this is {alg.name}")
    return _wrap(top, "body", lambda: SuslovSystem(inertia, constraints=D, potential=potential, gyroscopic=eps),
                 label="[body]")


def _potential_of(parent: _Table, key: str, value: Any, n: int | None):
    """A potential from a table ``{kind, B}`` (or ``"none"``)."""
    from .mechanics import LinearPotential, QuadraticPotential

    if isinstance(value, str):
        if value in ("none", "zero"):
            return None
        raise parent.error(key, f"must be a table {{kind = \"linear\" or \"quadratic\", B = [...]}} or "
                                f"\"none\", got {value!r}")
    if not isinstance(value, dict):
        raise parent.type_error(key, "must be a table with kind and B", value)
    path = f"{parent.path}.{key}" if parent.path else key
    t = _Table(value, parent.source, path, ("kind", "B"))
    kind = t.choice("kind", ("linear", "quadratic", "none", "zero"))
    if kind in ("none", "zero"):
        if t.has("B"):
            raise t.error("B", f"makes no sense with kind = {kind!r}")
        return None
    if not t.has("B"):
        raise t.error("B", f"is required with kind = {kind!r}")
    raw = t.get("B")
    if n is None:
        n = len(raw) if isinstance(raw, list) else 0
    if kind == "linear":
        B = t.array("B", [(n,)], f"a list of {n} numbers (B_1, ..., B_{n}): V = sum_i B_i Gamma_i")
        return _wrap(t, "B", lambda: LinearPotential(B))
    B = t.array("B", [(n,), (n, n)], f"a list of {n} numbers (V = 1/2 sum_i B_i Gamma_i^2) or an "
                                     f"{n}×{n} matrix (V = 1/2 Gamma^T B Gamma)")
    return _wrap(t, "B", lambda: QuadraticPotential(B))


def _backends() -> tuple[str, ...]:
    """The ``backend`` choices of :func:`~liesuslov.integrate` (empty if it has no such option)."""
    try:
        from .integrators.integrate import BACKENDS
    except ImportError:
        return ()
    return tuple(BACKENDS)


def _output_times(it: _Table, t_span):
    if it.has("n_out") and it.has("t_eval"):
        raise ValueError(f"{it.source}: [integrate] takes n_out or t_eval, not both")
    if it.has("t_eval"):
        raw = it.get("t_eval")
        if raw == "steps":
            return None, None, True
        if isinstance(raw, str):
            raise it.error("t_eval", f"must be a list of times or \"steps\" (every step), got {raw!r}")
        te = it.array("t_eval", [(None,)], "a list of output times, or \"steps\"")
        if te.size == 0:
            raise it.error("t_eval", "must not be empty")
        t0, t1 = t_span
        lo, hi = min(t0, t1), max(t0, t1)
        if te.min() < lo or te.max() > hi:
            raise it.error("t_eval", f"must lie within t_span = [{t0:g}, {t1:g}]")
        d = np.diff(te) * (1.0 if t1 > t0 else -1.0)
        if np.any(d <= 0):
            raise it.error("t_eval", "must be strictly increasing (decreasing when t1 < t0)")
        return None, te, False
    n_out = it.integer("n_out", default=_DEFAULT_N_OUT, minimum=2)
    return n_out, None, False


def _initial(ini: _Table, system, reconstruct: bool):
    alg = system.algebra
    D = system.constraints
    d, m = alg.dim, alg.matrix_size
    is_so = alg.name.startswith("so(")
    keys = [k for k in ("omega", "Omega", "xi", "w") if ini.has(k)]
    if len(keys) != 1:
        raise ValueError(f"{ini.source}: [initial] needs exactly one of omega (coordinates in the algebra "
                         f"basis, {d} numbers), Omega (a matrix), xi (coordinates in D, {D.dim} numbers)"
                         + (", w (the vector form, so(3))" if is_so and m == 3 else "")
                         + f"; got {', '.join(keys) if keys else 'none'}")
    key = keys[0]
    if key == "omega":
        x = ini.array("omega", [(d,)], f"a list of {d} numbers (coordinates of Omega in the {alg.name} basis)")
    elif key == "xi":
        xi = ini.array("xi", [(D.dim,)], f"a list of {D.dim} numbers (coordinates of Omega in the basis of D)")
        x = xi @ D.basis
    elif key == "w":
        if not (is_so and m == 3):
            raise ini.error("w", f"(the vector form) exists for so(3) only, this is {alg.name}")
        w = ini.array("w", [(3,)], "a list of 3 numbers (w1, w2, w3) = (-Omega_23, Omega_13, -Omega_12)")
        x = alg.from_vector3(w)
    else:
        if m is None:
            raise ini.error("Omega", f"needs a matrix representation of {alg.name}; give omega (coordinates)")
        Om = ini.array("Omega", [(m, m)], f"a {m}×{m} matrix" + (" (skew-symmetric)" if is_so else ""))
        x = _wrap(ini, "Omega", lambda: system.coordinates(Om, "Omega"), label="[initial].Omega")
    if key != "xi" and not bool(D.contains(x, 1e-9)):
        viol = float(np.max(np.abs(x @ D.covectors.T))) if D.dim < d else 0.0
        near = D.project(x)
        raise ini.error(key, f"is not in D: the constraints <a^i, Omega> = 0 fail (largest violation "
                             f"{viol:.3g}); the nearest admissible omega is {_fmt_list(near)}"
                             + (f", i.e. xi = {_fmt_list(D.coordinates(near))}" if D.dim < d else ""))
    Gamma = None
    if ini.has("Gamma"):
        if not is_so:
            raise ini.error("Gamma", f"is for a body in SO(n); {alg.name} has no vertical Gamma")
        n = alg.n
        Gamma = ini.array("Gamma", [(n,)], f"a list of {n} numbers (a unit vector)")
        nrm = float(np.linalg.norm(Gamma))
        if abs(nrm - 1.0) > 1e-8:
            hint = f"; normalised it is {_fmt_list(Gamma / nrm, 17)}" if nrm > 0 else ""
            raise ini.error("Gamma", f"must be a unit vector (|Gamma| = 1 within 1e-8), got |Gamma| = "
                                     f"{nrm:.12g}{hint}")
    elif system.needs_gamma:
        why = "the potential depends on it" if system.has_potential else "the gyroscopic term depends on it"
        raise ini.error("Gamma", f"is required ({why}): a unit vector of {system.n} numbers")
    g = None
    if ini.has("g"):
        if not reconstruct:
            raise ini.error("g", "(the initial attitude) needs [integrate].reconstruct = true")
        if m is None:
            raise ini.error("g", f"needs a matrix representation of {alg.name}")
        g = ini.array("g", [(m, m)], f"a {m}×{m} matrix (the initial attitude)")
        _check_group_element(ini, g, alg)
    return x, Gamma, g


def _check_group_element(ini: _Table, g: np.ndarray, alg) -> None:
    m = g.shape[0]
    if alg.name.startswith("so("):
        R = g
    elif alg.name in ("se(2)", "se(3)"):
        R = g[:-1, :-1]
        last = np.zeros(m)
        last[-1] = 1.0
        if np.max(np.abs(g[-1] - last)) > 1e-8:
            raise ini.error("g", f"must be in {alg.name.upper()}: its last row must be {_fmt_list(last)}")
    else:
        if abs(np.linalg.det(g)) < 1e-12:
            raise ini.error("g", "must be invertible")
        return
    k = R.shape[0]
    err = float(np.max(np.abs(R.T @ R - np.eye(k))))
    if err > 1e-8 or np.linalg.det(R) < 0:
        raise ini.error("g", f"must be a rotation (R^T R = I within 1e-8, det R = +1): max |R^T R - I| = "
                             f"{err:.3g}, det R = {np.linalg.det(R):.6g}")


def _wrap(t: _Table, key: str, build: Callable, label: str | None = None):
    """Run a library constructor, prefixing its ValueError/TypeError with the file and field path."""
    try:
        return build()
    except (ValueError, TypeError) as exc:
        where = label or t.field(key)
        raise type(exc)(f"{t.source}: {where}: {exc}") from exc


# ====================================================================== reading tables
def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _shape_of(v: Any) -> tuple[int, ...] | None:
    """Shape of a rectangular nested list of numbers, or None."""
    if _is_number(v):
        return ()
    if isinstance(v, list):
        if not v:
            return (0,)
        shapes = {_shape_of(e) for e in v}
        if len(shapes) != 1 or None in shapes:
            return None
        return (len(v),) + shapes.pop()
    return None


def _fits(want: tuple[int | None, ...], shape: tuple[int, ...]) -> bool:
    return len(want) == len(shape) and all(a is None or a == b for a, b in zip(want, shape, strict=True))


def _describe(v: Any) -> str:
    if isinstance(v, bool):
        return f"the boolean {str(v).lower()}"
    if _is_number(v):
        return f"the number {v!r}"
    if isinstance(v, str):
        return f"the string {v!r}"
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, list):
        s = _shape_of(v)
        if s is None:
            if any(isinstance(e, (str, bool, dict)) for e in v):
                return "a list that contains something other than numbers"
            return "nested lists of unequal lengths"
        if len(s) == 1:
            return f"a list of {s[0]} number{'s' if s[0] != 1 else ''}"
        if len(s) == 2:
            return f"a {s[0]}×{s[1]} matrix"
        return f"an array of shape {s}"
    return f"a {type(v).__name__}"


def _did_you_mean(word: str, options) -> str:
    close = difflib.get_close_matches(str(word), list(options), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


class _Table:
    """One TOML table, read field by field; unknown keys are rejected when it is opened."""

    def __init__(self, data: Any, source: str, path: str, allowed: tuple[str, ...] | None = None) -> None:
        self.source, self.path = source, path
        where = f"[{path}]" if path else "the top level"
        if not isinstance(data, Mapping):
            raise TypeError(f"{source}: {where} must be a table, got {_describe(data)}")
        self.data = data
        if allowed is not None:
            unknown = [k for k in data if k not in allowed]
            if unknown:
                k = unknown[0]
                label = f"[{path}].{k}" if path else k
                raise ValueError(f"{source}: unknown key {label}{_did_you_mean(k, allowed)}; the valid keys "
                                 f"of {where} are: {', '.join(allowed)}")

    # ------------------------------------------------------------------ messages
    def field(self, key: str) -> str:
        return f"[{self.path}].{key}" if self.path else key

    def error(self, key: str, msg: str) -> ValueError:
        return ValueError(f"{self.source}: {self.field(key)} {msg}")

    def type_error(self, key: str, expected: str, value: Any) -> TypeError:
        return TypeError(f"{self.source}: {self.field(key)} {expected}, got {_describe(value)}")

    # ------------------------------------------------------------------ access
    def has(self, key: str) -> bool:
        return key in self.data

    def get(self, key: str, default: Any = _MISSING) -> Any:
        if key in self.data:
            return self.data[key]
        if default is _MISSING:
            raise self.error(key, "is required")
        return default

    def table(self, key: str, required: bool = False, allowed: tuple[str, ...] | None = None) -> _Table:
        if key not in self.data:
            if required:
                raise ValueError(f"{self.source}: the table [{key}] is required")
            return _Table({}, self.source, key, allowed)
        if allowed is None:
            allowed = {"integrate": _INTEGRATE_KEYS, "initial": ("omega", "Omega", "xi", "w", "Gamma", "g"),
                       "output": ("name", "dir", "figures")}.get(key)
        path = f"{self.path}.{key}" if self.path else key
        return _Table(self.data[key], self.source, path, allowed)

    def string(self, key: str, default: Any = _MISSING) -> Any:
        v = self.get(key, default)
        if v is default and key not in self.data:
            return v
        if not isinstance(v, str):
            raise self.type_error(key, "must be a string", v)
        return v

    def choice(self, key: str, options: tuple[str, ...], default: Any = _MISSING) -> Any:
        v = self.string(key, default)
        if key in self.data and v not in options:
            raise self.error(key, f"must be one of {', '.join(repr(o) for o in options)}; got {v!r}"
                                  f"{_did_you_mean(v, options)}")
        return v

    def boolean(self, key: str, default: Any = _MISSING) -> Any:
        v = self.get(key, default)
        if key in self.data and not isinstance(v, bool):
            raise self.type_error(key, "must be true or false", v)
        return v

    def number(self, key: str, default: Any = _MISSING) -> Any:
        v = self.get(key, default)
        if key not in self.data:
            return v
        if not _is_number(v):
            raise self.type_error(key, "must be a number", v)
        if not math.isfinite(v):
            raise self.error(key, f"must be finite, got {v!r}")
        return float(v)

    def positive(self, key: str, default: Any = _MISSING) -> Any:
        v = self.number(key, default)
        if key in self.data and v <= 0:
            raise self.error(key, f"must be a positive number, got {self.data[key]!r}")
        return v

    def integer(self, key: str, default: Any = _MISSING, minimum: int | None = None) -> Any:
        v = self.get(key, default)
        if key not in self.data:
            return v
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.type_error(key, "must be an integer", v)
        if minimum is not None and v < minimum:
            raise self.error(key, f"must be an integer >= {minimum}, got {v}")
        return v

    def pair(self, key: str) -> tuple[float, float]:
        a = self.array(key, [(2,)], "a list of 2 numbers [t0, t1]")
        if a[0] == a[1]:
            raise self.error(key, f"must have t0 != t1, got {_fmt_list(a)}")
        return float(a[0]), float(a[1])

    def array(self, key: str, shapes: list[tuple[int | None, ...]] | None, expected: str) -> np.ndarray:
        """A numeric array whose shape is one of ``shapes`` (None entries: any length; None: any shape)."""
        v = self.get(key)
        s = _shape_of(v)
        if s is None or s == () or not isinstance(v, list):
            raise self.type_error(key, f"must be {expected}", v)
        if shapes is not None and not any(_fits(w, s) for w in shapes):
            raise ValueError(f"{self.source}: {self.field(key)} must be {expected}, got {_describe(v)}")
        a = np.array(v, dtype=float)
        if not np.all(np.isfinite(a)):
            raise self.error(key, "must contain finite numbers only (no inf or nan)")
        return a


# ====================================================================== output helpers
def _fmt_list(a, digits: int = 6) -> str:
    a = np.asarray(a, dtype=float)
    if a.ndim == 0:
        return f"{float(a):.{digits}g}"
    return "[" + ", ".join(_fmt_list(e, digits) for e in a) + "]"


def _plain(v: Any) -> Any:
    """Plain-data copy of a TOML document (dates become strings)."""
    if isinstance(v, Mapping):
        return {str(k): _plain(e) for k, e in v.items()}
    if isinstance(v, list):
        return [_plain(e) for e in v]
    if isinstance(v, (bool, int, float, str)):
        return v
    return str(v)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(e) for e in v) + "]"
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(e)}" for k, e in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _toml_key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k, ensure_ascii=False)


def to_toml(data: Mapping[str, Any], _prefix: str = "") -> str:
    """Write plain data (tables, arrays, strings, numbers, booleans) as TOML text; inverse of ``tomllib.loads``."""
    lines = []
    tables = []
    for k, v in data.items():
        if isinstance(v, Mapping):
            tables.append((k, v))
        else:
            lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
    out = "\n".join(lines) + ("\n" if lines else "")
    for k, v in tables:
        name = f"{_prefix}.{_toml_key(k)}" if _prefix else _toml_key(k)
        body = to_toml(v, name)
        has_scalars = any(not isinstance(e, Mapping) for e in v.values())
        if has_scalars or not v:
            out += ("\n" if out else "") + f"[{name}]\n" + body
        else:
            out += body
    return out
