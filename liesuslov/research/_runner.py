"""Shared plumbing of the research tools: inputs, default options, crossings of a section.

The crossings come from ``integrate(..., events=...)`` (roots located per trajectory on the method's
continuous extension). While the integrator of this tree has no ``events`` argument, a fallback samples
the solution on a fine grid (``t_eval``) and locates each root on the local degree-7 interpolant of the
samples (error ~ ``(h/T)^8``, about ``1e-12`` relative at the grid used); its results carry the same
fields as an :class:`EventRecord`. The fallback is selected automatically and never by the user.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import as_float_array, check_positive
from ..integrators import integrate

#: Options of every research tool called without integrator options (the contract's defaults).
DEFAULT_OPTIONS = {"method": "rkmk853", "rtol": 1e-10, "atol": 1e-12}

try:  # the integrator's own event machinery, when this tree has it
    from ..integrators.events import LinearEvent  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the integrator's version
    LinearEvent = None  # type: ignore[assignment]

try:
    from ..integrators.events import EventRecord  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the integrator's version
    EventRecord = None  # type: ignore[assignment]


def integrator_has_events() -> bool:
    """True iff :func:`liesuslov.integrate` accepts ``events`` and ``dense_output``."""
    params = inspect.signature(integrate).parameters
    return "events" in params and "dense_output" in params


def options_with_defaults(options: dict) -> dict:
    """The integrator options of a research tool: the contract's defaults unless any option is given.

    A fixed-step method without ``h`` is rejected here with the fix, before any work.
    """
    opts = dict(options)
    if not any(k in opts for k in ("method", "rtol", "atol", "h")):
        opts.update(DEFAULT_OPTIONS)
    else:
        opts.setdefault("method", DEFAULT_OPTIONS["method"])
    from ..integrators import METHODS

    meth = METHODS.get(opts["method"]) if isinstance(opts["method"], str) else None
    if meth is not None and not meth.adaptive and opts.get("h") is None:
        raise ValueError(f"h (the step size) is required by the fixed-step method {opts['method']!r}; pass h=..., "
                         "or leave method out to use the adaptive default rkmk853")
    for bad in ("t_eval", "events", "dense_output", "reconstruct"):
        if bad in opts:
            raise ValueError(f"{bad} is chosen by the research tool itself; remove it from the options")
    return opts


# ------------------------------------------------------------------------------------------ inputs
@dataclass
class Batch:
    """Validated, flattened initial data of a research tool (``B`` trajectories)."""

    system: Any
    shape: tuple[int, ...]
    omega: np.ndarray            # (B, d) coordinates in the algebra basis, in D
    Gamma: np.ndarray | None     # (B, n) unit vectors, or None
    g0: np.ndarray | None        # (B, m, m) or None

    @property
    def size(self) -> int:
        return int(self.omega.shape[0])

    @property
    def n(self) -> int | None:
        return self.system.n

    def reduced(self, omega: np.ndarray, Gamma: np.ndarray | None) -> np.ndarray:
        """The reduced state ``(xi, Gamma)`` (xi = coordinates in D's orthonormal basis), (..., k [+ n])."""
        xi = omega @ self.system.constraints.basis.T
        return xi if Gamma is None else np.concatenate([xi, Gamma], axis=-1)


def prepare(system, Omega0, Gamma0=None, g0=None) -> Batch:
    """Check ``system``, ``Omega0`` (in D), ``Gamma0`` (unit) and ``g0`` (SO(n)); broadcast and flatten."""
    from ..mechanics import SuslovSystem

    if not isinstance(system, SuslovSystem):
        raise TypeError(f"system must be a SuslovSystem (e.g. ls.SuslovSystem(J, ...)), got {type(system).__name__}")
    x = system.coordinates(Omega0, "Omega0")
    D = system.constraints
    inside = D.contains(x, 1e-9)
    if not np.all(inside):
        dist = float(np.max(np.linalg.norm(x - D.project(x), axis=-1)))
        raise ValueError(f"Omega0 is not in the constraint subspace D (distance {dist:.3g}); project it first, "
                         "e.g. system.constraints.project(omega)")
    shapes = [x.shape[:-1]]
    G = None
    if Gamma0 is None and system.needs_gamma:
        raise ValueError(f"Gamma0 is required: the potential (or gyroscopic term) depends on Gamma; pass a unit "
                         f"vector of shape (..., {system.n})")
    if Gamma0 is not None:
        if not system.is_so:
            raise ValueError(f"Gamma0 must be None on {system.algebra.name}: Gamma exists only for a body in SO(n)")
        G = as_float_array(Gamma0, "Gamma0", ndim_min=1, tail=(system.n,))
        norms = np.linalg.norm(G, axis=-1)
        dev = float(np.max(np.abs(norms - 1.0))) if norms.size else 0.0
        if dev > 1e-8:
            raise ValueError(f"Gamma0 must be a unit vector (|Gamma0| = 1 to 1e-8); the largest deviation is "
                             f"{dev:.3g}: pass Gamma0 / |Gamma0|")
        G = G / norms[..., None]
        shapes.append(G.shape[:-1])
    g = None
    if g0 is not None:
        m = system.n
        if m is None:
            raise ValueError(f"g0 needs a matrix representation of {system.algebra.name}")
        g = as_float_array(g0, "g0", ndim_min=2, tail=(m, m))
        if system.is_so:
            err = float(np.max(np.abs(np.swapaxes(g, -1, -2) @ g - np.eye(m)), initial=0.0))
            if err > 1e-8 or np.any(np.linalg.det(g) < 0):
                raise ValueError(f"g0 must be in SO(n): g^T g = I (max defect {err:.3g}) and det g = +1")
        shapes.append(g.shape[:-2])
    try:
        shape = tuple(np.broadcast_shapes(*shapes))
    except ValueError as exc:
        raise ValueError(f"the batch axes of Omega0, Gamma0 and g0 do not broadcast: {shapes}") from exc
    B = int(np.prod(shape, dtype=int))
    if B == 0:
        raise ValueError(f"the batch of initial data is empty (batch shape {shape}); pass at least one Omega0")
    x = np.broadcast_to(x, shape + x.shape[-1:]).reshape(B, -1).copy()
    if G is not None:
        G = np.broadcast_to(G, shape + G.shape[-1:]).reshape(B, -1).copy()
    if g is not None:
        g = np.broadcast_to(g, shape + g.shape[-2:]).reshape((B,) + g.shape[-2:]).copy()
    return Batch(system, shape, x, G, g)


def check_span(t_span, name: str = "t_span") -> tuple[float, float]:
    """A pair ``(t0, t1)`` of finite numbers with ``t1 > t0``."""
    try:
        t0, t1 = (float(v) for v in t_span)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a pair of numbers (t0, t1), got {t_span!r}") from exc
    if not (np.isfinite(t0) and np.isfinite(t1)) or t1 <= t0:
        raise ValueError(f"{name} must be finite with t1 > t0, got {t_span!r}")
    return t0, t1


# ------------------------------------------------------------------------------------------ events
class PlaneEvent:
    """A linear functional of the state, ``a . omega + b . Gamma + sum(c * g) - offset`` (fallback form).

    The same constructor as the integrator's ``LinearEvent``; coefficient arrays may carry batch axes
    (one plane per trajectory). Callable as an event function ``event(t, Omega, Gamma, g)``.
    """

    def __init__(self, omega=None, Gamma=None, g=None, offset=0.0, terminal: bool = False, direction: int = 0):
        self.omega = None if omega is None else np.asarray(omega, dtype=float)
        self.Gamma = None if Gamma is None else np.asarray(Gamma, dtype=float)
        self.g = None if g is None else np.asarray(g, dtype=float)
        self.offset = np.asarray(offset, dtype=float)
        self.terminal = bool(terminal)
        self.direction = int(direction)

    def value(self, omega, Gamma, g) -> np.ndarray:
        """The functional on coordinates: ``omega (..., d)``, ``Gamma (..., n)``, ``g (..., m, m)``."""
        out = -self.offset
        if self.omega is not None:
            out = out + np.sum(self.omega * omega, axis=-1)
        if self.Gamma is not None:
            out = out + np.sum(self.Gamma * Gamma, axis=-1)
        if self.g is not None:
            out = out + np.sum(self.g * g, axis=(-2, -1))
        return out

    def __call__(self, t, Omega, Gamma, g):
        m = Omega.shape[-1]
        r, c = np.triu_indices(m, 1)
        return self.value(Omega[..., r, c], Gamma, g)


def make_plane(omega=None, Gamma=None, g=None, offset=0.0, direction: int = 0):
    """A linear event: the integrator's ``LinearEvent`` when available, else :class:`PlaneEvent`."""
    kw: dict[str, Any] = {"offset": offset, "terminal": False, "direction": direction}
    for name, val in (("omega", omega), ("Gamma", Gamma), ("g", g)):
        if val is not None:
            kw[name] = val
    if LinearEvent is not None and integrator_has_events():
        return LinearEvent(**kw)
    return PlaneEvent(**kw)


def flat_event(event, shape: tuple[int, ...]):
    """The event with its coefficient arrays broadcast to the flat batch ``(B, ...)`` of ``shape``."""
    if not _is_linear(event):
        return event
    B = int(np.prod(shape, dtype=int))
    kw: dict[str, Any] = {}
    for name, nd in (("omega", 1), ("Gamma", 1), ("g", 2), ("offset", 0)):
        val = getattr(event, name, None)
        if val is None:
            continue
        val = np.asarray(val, dtype=float)
        if val.ndim > nd:
            tail = val.shape[val.ndim - nd:] if nd else ()
            try:
                val = np.broadcast_to(val, tuple(shape) + tail).reshape((B,) + tail)
            except ValueError as exc:
                raise ValueError(f"section: the batch axes {val.shape[:val.ndim - nd]} of its {name} coefficients "
                                 f"do not broadcast to the batch {tuple(shape)}") from exc
        kw[name] = val
    return make_plane(kw.get("omega"), kw.get("Gamma"), kw.get("g"), kw.get("offset", 0.0),
                      direction=int(getattr(event, "direction", 0)))


def slice_event(event, rows: np.ndarray, B: int):
    """The event restricted to the trajectories ``rows`` of a flat batch of ``B`` (after :func:`flat_event`)."""
    if not _is_linear(event):
        return event
    kw: dict[str, Any] = {}
    for name, nd in (("omega", 1), ("Gamma", 1), ("g", 2), ("offset", 0)):
        val = getattr(event, name, None)
        if val is None:
            continue
        val = np.asarray(val, dtype=float)
        if val.ndim > nd and val.shape[0] == B:
            val = val[rows]
        kw[name] = val
    return make_plane(kw.get("omega"), kw.get("Gamma"), kw.get("g"), kw.get("offset", 0.0),
                      direction=int(getattr(event, "direction", 0)))


def _is_linear(event) -> bool:
    return isinstance(event, PlaneEvent) or (LinearEvent is not None and isinstance(event, LinearEvent))


@dataclass
class Crossings:
    """Crossings of one event by a flat batch: the fields of an EventRecord (``index`` into the batch)."""

    t: np.ndarray          # (K,)
    index: np.ndarray      # (K,) int
    omega: np.ndarray      # (K, d)
    Gamma: np.ndarray | None
    g: np.ndarray | None

    @classmethod
    def empty(cls, d: int, n: int | None, with_gamma: bool, with_g: bool) -> Crossings:
        return cls(np.zeros(0), np.zeros(0, dtype=int), np.zeros((0, d)),
                   np.zeros((0, n)) if with_gamma else None, np.zeros((0, n, n)) if with_g else None)


@dataclass
class Window:
    """The result of one window of integration: crossings, end states, per-trajectory status."""

    crossings: Crossings
    omega: np.ndarray        # (B, d) at the end
    Gamma: np.ndarray | None
    g: np.ndarray | None
    status: np.ndarray       # (B,) 0 reached the end, -1 failed


def run_window(batch_system, omega, Gamma, g, t_span, event, direction: int, opts: dict,
               reconstruct: bool) -> Window:
    """Integrate a flat batch over ``t_span`` and return the crossings of ``event`` in ``direction``.

    ``event``: a linear event (planes possibly per trajectory) or a callable ``event(t, Omega, Gamma, g)``.
    """
    system = batch_system
    B = omega.shape[0]
    kwargs = dict(opts)
    if Gamma is not None:
        kwargs["Gamma0"] = Gamma
    if reconstruct:
        kwargs["reconstruct"] = True
        kwargs["g0"] = g
    if integrator_has_events():
        return _window_events(system, omega, t_span, event, direction, kwargs, B)
    return _window_fallback(system, omega, t_span, event, direction, kwargs, B)


def _window_events(system, omega, t_span, event, direction, kwargs, B) -> Window:
    if _is_linear(event):
        ev = event
        if int(getattr(ev, "direction", 0)) != direction:
            ev = slice_event(event, np.arange(B), B)
            ev = make_plane(getattr(ev, "omega", None), getattr(ev, "Gamma", None), getattr(ev, "g", None),
                            getattr(ev, "offset", 0.0), direction=direction)
    else:
        def ev(t, Omega, Gamma, g, _f=event):
            return _f(t, Omega, Gamma, g)

        ev.terminal = False
        ev.direction = direction
    sol = integrate(system, omega, t_span, events=[ev], **kwargs)
    rec = sol.events[0]
    cr = Crossings(np.asarray(rec.t, dtype=float), np.asarray(rec.index, dtype=int), np.asarray(rec.omega),
                   None if rec.Gamma is None else np.asarray(rec.Gamma), None if rec.g is None else np.asarray(rec.g))
    status = np.broadcast_to(np.asarray(sol.status), (B,)).astype(int)
    G_end = None if sol.Gamma is None else sol.Gamma[-1]
    g_end = None if sol.g is None else sol.g[-1]
    return Window(cr, sol.omega[-1], G_end, g_end, status)


# Fallback: a grid of _SAMPLES_PER_UNIT / rate points per unit time and a degree-7 local interpolant.
_SAMPLES_PER_UNIT = 40.0
_STENCIL = 8


def _rate(system, omega, Gamma) -> float:
    """A frequency scale of the motion (1/time) for the fallback's grid."""
    xdot, _ = system.rhs(omega, Gamma)
    w = float(np.max(np.linalg.norm(omega, axis=-1)))
    acc = float(np.max(np.linalg.norm(xdot, axis=-1)))
    return max(1.0, w, np.sqrt(acc))


def _window_fallback(system, omega, t_span, event, direction, kwargs, B) -> Window:
    from scipy.interpolate import BarycentricInterpolator
    from scipy.optimize import brentq

    t0, t1 = t_span
    rate = _rate(system, omega, kwargs.get("Gamma0"))
    N = max(_STENCIL + 1, int(np.ceil((t1 - t0) * rate * _SAMPLES_PER_UNIT)) + 1)
    grid = np.linspace(t0, t1, N)
    sol = integrate(system, omega, (t0, t1), t_eval=grid, **kwargs)
    om = sol.omega                     # (N, B, d)
    Ga = sol.Gamma
    gg = sol.g
    if _is_linear(event):
        f = event.value(om, Ga, gg) if isinstance(event, PlaneEvent) else PlaneEvent(
            getattr(event, "omega", None), getattr(event, "Gamma", None), getattr(event, "g", None),
            getattr(event, "offset", 0.0)).value(om, Ga, gg)
    else:
        tt = np.broadcast_to(grid[:, None], om.shape[:2])
        f = np.asarray(event(tt, sol.Omega, Ga, gg), dtype=float)
    f = np.broadcast_to(f, om.shape[:2])
    lo, hi = f[:-1], f[1:]
    up = (lo < 0.0) & (hi >= 0.0)
    down = (lo > 0.0) & (hi <= 0.0)
    hit = up if direction > 0 else down if direction < 0 else (up | down)
    ks, bs = np.nonzero(hit)
    ts, idx, oms, Gs, gs = [], [], [], [], []
    D = system.constraints
    for k, b in zip(ks.tolist(), bs.tolist(), strict=True):
        j0 = min(max(k - _STENCIL // 2 + 1, 0), N - _STENCIL)
        sl = slice(j0, j0 + _STENCIL)
        tk = grid[sl]
        scale = tk[-1] - tk[0]
        xs = (tk - tk[0]) / scale
        fi = BarycentricInterpolator(xs, f[sl, b])
        lo_x, hi_x = (grid[k] - tk[0]) / scale, (grid[k + 1] - tk[0]) / scale
        if f[k + 1, b] == 0.0:
            xr = hi_x
        else:
            xr = brentq(lambda s, fi=fi: float(fi(s)), lo_x, hi_x, xtol=1e-15, rtol=1e-15)
        ts.append(tk[0] + xr * scale)
        idx.append(b)
        oms.append(D.project(BarycentricInterpolator(xs, om[sl, b])(xr)))
        if Ga is not None:
            G = BarycentricInterpolator(xs, Ga[sl, b])(xr)
            Gs.append(G / np.linalg.norm(G))
        if gg is not None:
            m = gg.shape[-1]
            gi = BarycentricInterpolator(xs, gg[sl, b].reshape(_STENCIL, -1))(xr).reshape(m, m)
            U, _, Vt = np.linalg.svd(gi)
            gs.append(U @ Vt)
    d = om.shape[-1]
    n = system.n
    if ts:
        order = np.lexsort((np.asarray(ts), np.asarray(idx)))
        cr = Crossings(np.asarray(ts)[order], np.asarray(idx, dtype=int)[order], np.asarray(oms)[order],
                       np.asarray(Gs)[order] if Ga is not None else None,
                       np.asarray(gs)[order] if gg is not None else None)
    else:
        cr = Crossings.empty(d, n, Ga is not None, gg is not None)
    status = np.full(B, int(sol.status))
    return Window(cr, om[-1], None if Ga is None else Ga[-1], None if gg is None else gg[-1], status)


def make_record(cr: Crossings, n: int | None, algebra_name: str):
    """An :class:`EventRecord` (the integrator's class when available) from flat crossings."""
    Omega = None
    if algebra_name.startswith("so(") and n is not None:
        from ..algebra import so

        Omega = so(n).hat(cr.omega)
    if EventRecord is not None:
        try:
            return EventRecord(t=cr.t, index=cr.index, omega=cr.omega, Gamma=cr.Gamma, g=cr.g, n=n,
                               algebra_name=algebra_name)
        except TypeError:  # pragma: no cover - a different constructor: fall back to ours
            pass
    return SectionRecord(t=cr.t, index=cr.index, omega=cr.omega, Omega=Omega, Gamma=cr.Gamma, g=cr.g)


@dataclass
class SectionRecord:
    """Crossings of a section (the fields of the integrator's ``EventRecord``).

    Attributes
    ----------
    t : ndarray, shape (K,)
        Crossing times, sorted by (index, t).
    index : ndarray of int, shape (K,)
        Flat (C-order) batch index of the trajectory that crossed.
    omega : ndarray, shape (K, d)
    Omega : ndarray, shape (K, n, n), or None
    Gamma : ndarray, shape (K, n), or None
    g : ndarray, shape (K, m, m), or None
    """

    t: np.ndarray
    index: np.ndarray
    omega: np.ndarray
    Omega: np.ndarray | None
    Gamma: np.ndarray | None
    g: np.ndarray | None


def run_plain(system, omega, Gamma, g, t_span, opts: dict) -> tuple[np.ndarray, np.ndarray]:
    """Integrate a flat batch with the attitude from ``g`` over ``t_span``: ``(g at t1 (B, m, m), status (B,))``."""
    kwargs = dict(opts)
    if Gamma is not None:
        kwargs["Gamma0"] = Gamma
    sol = integrate(system, omega, t_span, reconstruct=True, g0=g, **kwargs)
    status = np.broadcast_to(np.asarray(sol.status), (omega.shape[0],)).astype(int)
    return sol.g[-1], status


def positive(value, name: str) -> float:
    return check_positive(value, name)
