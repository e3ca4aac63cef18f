"""Building a :class:`~liesuslov.scene.Scene` from a parsed document: the case or the body, the
constraints, the potential, the integration options and the initial data, each validated."""

from __future__ import annotations

import inspect
import math
import re
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from .._validation import check_rotations
from .core import Scene, _backends
from .schema import (
    _BODY_KEYS,
    _CALLABLE_PARAMETERS,
    _DEFAULT_N_OUT,
    _MAX_N_OUT,
    _MAX_STEPS,
    _MISSING,
    _TOP_KEYS,
    _describe,
    _did_you_mean,
    _fmt_list,
    _is_number,
    _Table,
)
from .toml import plain

__all__ = ["scene_from_dict"]


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
    from ..integrators import CHARTS, METHODS

    method = it.choice("method", tuple(METHODS), default="rkmk45")
    chart = it.choice("chart", CHARTS, default="exp")
    from ..mechanics import FORMS

    form = it.choice("form", ("auto",) + FORMS, default="auto")
    if form != "auto":
        why = system.form_obstruction(form)
        if why is not None:
            raise it.error("form", f"= {form!r} does not hold for this system: {why}")
    h = it.positive("h", default=None)
    if not METHODS[method].adaptive and h is None:
        raise it.error("h", f"(the step size) is required by the fixed-step method {method!r}; give "
                            "h = 0.01, say, or choose an adaptive method such as \"rkmk45\"")
    if h is not None:
        _check_step(it, h, t_span, adaptive=METHODS[method].adaptive)
    rtol = it.positive("rtol", default=1e-8)
    atol = it.positive("atol", default=1e-10)
    n_out, t_eval, every_step = _output_times(it, t_span)
    reconstruct = it.boolean("reconstruct", default=False)
    progress = it.boolean("progress", default=False)
    backend = it.choice("backend", _backends(), default=None) if it.has("backend") else None
    max_steps = it.integer("max_steps", default=None, minimum=1)
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
                 every_step=every_step, reconstruct=reconstruct, progress=progress, backend=backend,
                 max_steps=max_steps, out_dir=out_dir,
                 figures=figures, tol=tol, case=case, description=description, source=source,
                 data=plain(dict(d)))


# ====================================================================== the parts of a scene
def _case(top: _Table, source: str):
    from ..mechanics import CASES

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
    from ..algebra import Inertia, LieAlgebra, Subspace, se, so, suslov_distribution
    from ..mechanics import SuslovSystem

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
    from ..mechanics import LinearPotential, QuadraticPotential

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
    B = t.array("B", [(n,), (n, n)], f"a list of {n} numbers (V = 1/2 sum_i B_i Gamma_i^2) or a "
                                     f"{n}×{n} matrix (V = 1/2 Gamma^T B Gamma)")
    return _wrap(t, "B", lambda: QuadraticPotential(B))


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
    n_out = it.integer("n_out", default=_DEFAULT_N_OUT, minimum=2, maximum=_MAX_N_OUT,
                       why=" (the output times are held in memory; use t_eval = \"steps\" or a shorter t_span)")
    return n_out, None, False


def _check_step(it: _Table, h: float, t_span: tuple[float, float], adaptive: bool) -> None:
    """``h`` must let the run make progress: at most _MAX_STEPS fixed steps, above the rounding of t."""
    t0, t1 = t_span
    span = abs(t1 - t0)
    # below a few ulps of t a step does not change t at all
    floor = 8.0 * np.spacing(max(abs(t0), abs(t1)))
    if h <= floor:
        raise it.error("h", f"= {h:g} is below the resolution of t near {max(abs(t0), abs(t1)):g} ({floor:.3g}): "
                            "a step would not advance t; choose a step such as (t1 - t0) / 1000")
    if not adaptive and span / h > _MAX_STEPS:
        raise it.error("h", f"= {h:g} would take {span / h:.3g} fixed steps over t_span = [{t0:g}, {t1:g}] "
                            f"(at most {_MAX_STEPS:.0e}); choose h >= {span / _MAX_STEPS:.3g} or an adaptive method")


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
    _wrap(ini, "g", lambda: check_rotations(R, "g" if R is g else "the rotation block R of g"))


def _wrap(t: _Table, key: str, build: Callable, label: str | None = None):
    """Run a library constructor, prefixing its ValueError/TypeError with the file and field path."""
    try:
        return build()
    except (ValueError, TypeError) as exc:
        where = label or t.field(key)
        raise type(exc)(f"{t.source}: {where}: {exc}") from exc


# ====================================================================== reading tables
