"""Shared plumbing of the research tools: inputs, default options, crossings of a section.

The crossings come from ``integrate(..., events=[event])``: roots located per trajectory on the method's
continuous extension, returned as an :class:`~liesuslov.integrators.events.EventRecord`. Linear sections
(:class:`~liesuslov.integrators.events.LinearEvent`, possibly one plane per trajectory) are evaluated
natively by the integrator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._rows import rows_at
from .._validation import check_positive, check_t_span
from ..integrators import integrate
from ..integrators.events import EventRecord, LinearEvent
from ..integrators.problem import run_message

#: Options of every research tool called without integrator options (the contract's defaults).
DEFAULT_OPTIONS = {"method": "rkmk853", "rtol": 1e-10, "atol": 1e-12}


def adaptive(method) -> bool | None:
    """Whether ``method`` (a name of :data:`~liesuslov.integrators.METHODS`) is adaptive; None if it is not one
    (integrate then names it in its error)."""
    from ..integrators import METHODS

    meth = METHODS.get(method) if isinstance(method, str) else None
    return None if meth is None else meth.adaptive


def options_with_defaults(options: dict) -> dict:
    """The integrator options of a research tool: each of ``method``, ``rtol``, ``atol`` the contract's default
    (:data:`DEFAULT_OPTIONS`) unless given — ``atol=1e-14`` alone keeps ``rtol=1e-10``, not integrate's 1e-8.

    A fixed-step method without ``h`` is rejected here with the fix, before any work.
    """
    opts = {**DEFAULT_OPTIONS, **options}
    if adaptive(opts["method"]) is False and opts.get("h") is None:
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
        xi = rows_at(omega, self.system.constraints.basis.T)
        return xi if Gamma is None else np.concatenate([xi, Gamma], axis=-1)


def prepare(system, Omega0, Gamma0=None, g0=None) -> Batch:
    """Check ``system``, ``Omega0`` (in D), ``Gamma0`` (unit) and ``g0`` (SO(n)); broadcast and flatten."""
    from ..mechanics import SuslovSystem

    if not isinstance(system, SuslovSystem):
        raise TypeError(f"system must be a SuslovSystem (e.g. ls.SuslovSystem(J, ...)), got {type(system).__name__}")
    # integrate's own reading and checks (one source): coordinates in D, Gamma0 unit (normalised), g0 on the group
    from ..integrators.integrate import _initial_data

    _, x, G, g, shape = _initial_data(system, False, Omega0, Gamma0, g0, g0 is not None, "auto")
    shape = tuple(shape)
    B = math.prod(shape)
    x = np.broadcast_to(x, shape + x.shape[-1:]).reshape(B, -1).copy()
    if G is not None:
        G = np.broadcast_to(G, shape + G.shape[-1:]).reshape(B, -1).copy()
    if g is not None:
        g = np.broadcast_to(g, shape + g.shape[-2:]).reshape((B,) + g.shape[-2:]).copy()
    return Batch(system, shape, x, G, g)


def check_span(t_span) -> tuple[float, float]:
    """A pair ``(t0, t1)`` of finite numbers with ``t1 > t0`` (integrate's check, plus the forward direction)."""
    if isinstance(t_span, (list, tuple)) and any(isinstance(v, (bool, np.bool_)) for v in t_span):
        raise TypeError(f"t_span must be a pair of numbers (t0, t1), got booleans {t_span!r}")
    t0, t1 = check_t_span(t_span)
    if t1 <= t0:
        raise ValueError(f"t_span must have t1 > t0 (the research tools integrate forward), got {t_span!r}")
    return t0, t1


# ------------------------------------------------------------------------------------------ events
def make_plane(omega=None, Gamma=None, g=None, offset=0.0, direction: int = 0) -> LinearEvent:
    """A non-terminal :class:`LinearEvent` with the given coefficients (None: not read)."""
    kw: dict[str, Any] = {"offset": offset, "terminal": False, "direction": direction}
    for name, val in (("omega", omega), ("Gamma", Gamma), ("g", g)):
        if val is not None:
            kw[name] = val
    return LinearEvent(**kw)


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
    return isinstance(event, LinearEvent)


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
    why: np.ndarray          # (B,) object: integrate's reason for a failed trajectory ("" otherwise)
    samples: tuple | None = None   # (omega (N, B, d), Gamma (N, B, n) or None) at the asked times, if any
    message: str = ""        # integrate's


def failure_reasons(sol, B: int) -> np.ndarray:
    """Per trajectory (B,), why ``integrate`` failed it — its reason and time, as ``sol.message`` says the
    first — or ""."""
    status = np.broadcast_to(np.asarray(sol.status), (B,))
    t_stop = np.broadcast_to(np.asarray(sol.stats["t_stop"], dtype=float), (B,))
    code = np.broadcast_to(np.asarray(sol.stats["failure"]), (B,))
    why = np.full(B, "", dtype=object)
    for k in np.flatnonzero(status < 0):
        why[k] = run_message(np.array([-1]), t_stop[k:k + 1], code[k:k + 1])
    return why


def run_window(batch_system, omega, Gamma, g, t_span, event, direction: int, opts: dict,
               reconstruct: bool, samples: int = 0) -> Window:
    """Integrate a flat batch over ``t_span`` and return the crossings of ``event`` in ``direction``.

    ``event``: a linear event (planes possibly per trajectory) or a callable ``event(t, Omega, Gamma, g)``;
    ``samples`` > 1: also the states at that many evenly spaced times of ``t_span`` (``Window.samples``).
    """
    system = batch_system
    B = omega.shape[0]
    kwargs = dict(opts)
    if Gamma is not None:
        kwargs["Gamma0"] = Gamma
    if reconstruct:
        kwargs["reconstruct"] = True
        kwargs["g0"] = g
    if samples > 1:
        kwargs["t_eval"] = np.linspace(t_span[0], t_span[1], samples)
    return _window_events(system, omega, t_span, event, direction, kwargs, B)


def _window_events(system, omega, t_span, event, direction, kwargs, B) -> Window:
    if _is_linear(event):
        ev = event
        if int(event.direction) != direction:
            ev = make_plane(event.omega, event.Gamma, event.g, event.offset, direction=direction)
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
    samples = (sol.omega, sol.Gamma) if "t_eval" in kwargs else None
    return Window(cr, sol.omega[-1], G_end, g_end, status, failure_reasons(sol, B), samples, sol.message)


def rates(omega: np.ndarray, xdot: np.ndarray) -> np.ndarray:
    """A frequency scale of each trajectory (1/time), ``max(1, |omega|, sqrt|omega'|)``, shape (B,).

    The period search sizes each trajectory's first window from its own rate (~32 / rate long).
    """
    w = np.linalg.norm(omega, axis=-1)
    acc = np.linalg.norm(xdot, axis=-1)
    return np.maximum(1.0, np.maximum(w, np.sqrt(acc)))


def make_record(cr: Crossings, n: int | None, algebra_name: str, status=None, message: str = "") -> EventRecord:
    """An :class:`EventRecord` from flat crossings."""
    return EventRecord(t=cr.t, index=cr.index, omega=cr.omega, Gamma=cr.Gamma, g=cr.g, n=n,
                       algebra_name=algebra_name, status=status, message=message)


#: A reduced speed at most this times |s0| is an equilibrium to the integrator's resolution; otherwise a crossing
#: before ``start_time`` is the start itself (a root at t0, located ~eps |s0| / speed after it: 1e-17..1e-16).
STILL = 1e-12


def start_time(speed: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Per trajectory, the time after t0 within which a crossing is the start itself: ``STILL (1 + |s0| / speed)``."""
    return STILL * (1.0 + scale / np.maximum(speed, np.finfo(float).tiny))


def run_plain(system, omega, Gamma, g, t_span, opts: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integrate a flat batch with the attitude from ``g`` over ``t_span``: ``(g at t1 (B, m, m), status (B,),
    why (B,))`` (:func:`failure_reasons`)."""
    kwargs = dict(opts)
    if Gamma is not None:
        kwargs["Gamma0"] = Gamma
    sol = integrate(system, omega, t_span, reconstruct=True, g0=g, **kwargs)
    B = omega.shape[0]
    status = np.broadcast_to(np.asarray(sol.status), (B,)).astype(int)
    return sol.g[-1], status, failure_reasons(sol, B)


def positive(value, name: str) -> float:
    return check_positive(value, name)


#: The tolerances of the re-integrations that check a research tool's own (possibly loose) integration:
#: a candidate return of the period search, the error of the monodromy.
TIGHT = {"method": "rkmk853", "rtol": 1e-12, "atol": 1e-14}


def tight_options(opts: dict) -> dict | None:
    """Options of a checking re-integration (:data:`TIGHT`, or tighter if ``opts`` are), None if ``opts`` are that.

    The user's other options (``chart``, ``form``, ``max_steps``, ...) are kept; ``h`` and ``first_step`` are
    dropped (the adaptive method chooses its steps).
    """
    own = adaptive(opts.get("method")) is True
    rtol = min(TIGHT["rtol"], float(opts.get("rtol", 1.0))) if own else TIGHT["rtol"]
    atol = min(TIGHT["atol"], float(opts.get("atol", 1.0))) if own else TIGHT["atol"]
    if opts.get("method") == TIGHT["method"] and float(opts.get("rtol", 1e-8)) <= rtol \
            and float(opts.get("atol", 1e-10)) <= atol and "h" not in opts and "first_step" not in opts:
        return None
    out = {k: v for k, v in opts.items() if k not in ("h", "first_step")}
    out.update(method=TIGHT["method"], rtol=rtol, atol=atol)
    return out
