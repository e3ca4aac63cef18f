"""The numpy solver: each trajectory's own time loop (step, controller, output, events) in Python.

The reference the compiled kernel (:mod:`.kernel`) is tested against, and the path for what the kernel
cannot run (a user potential, a user event function, a group part it does not know). The parts:

* the stepper (:class:`.rkmk.RKMKStepper`): trial steps, the extension's extra stages, dense states;
* the controller and the norm (:mod:`.control`), shared with the kernel;
* output (:class:`_Output`): t_eval served by the continuous extension, or every step;
* events (:class:`_Events`): sign changes between accepted steps, roots by Brent's method on the
  continuous extension.

Each trajectory runs alone (one after the other), so its numbers cannot depend on its batch mates.
"""

from __future__ import annotations

import math

import numpy as np

from . import control
from .problem import RENORM_EVERY, STATUS_FAILED, STATUS_TERMINAL, Problem, RawResult
from .rkmk import RKMKStepper

__all__ = ["solve"]


def solve(problem: Problem, done=None) -> RawResult:
    """Integrate every trajectory of ``problem`` on numpy (see :class:`~.problem.RawResult`).

    ``done(1)``, if given, is called as each trajectory ends (a progress bar's ``update``).
    """
    P = problem
    B, k, q = P.B, P.k, P.q
    t_out = P.t_eval
    rec_all = t_out is None
    M = 0 if rec_all else t_out.size
    xi_out = np.full((M, B, k), np.nan)
    G_out = np.full((M, B, q), np.nan)
    status = np.zeros(B, np.int64)
    failure = np.zeros(B, np.int64)
    t_stop = np.full(B, P.t1)
    counts = np.zeros((3, B), np.int64)
    ev = [[[] for _ in range(B)] for _ in range(P.n_events)]
    # the kernel's kind when the problem was built for it (tests compare the two on one Problem), else the default
    stepper = RKMKStepper(P.model, P.plan, P.chart, P.mode, 1, kind=P.kind, rtol=P.rtol, atol=P.atol)
    steps_t, steps_xi, steps_G = [], [], []
    with np.errstate(all="ignore"):  # a diverging step is detected (status -1), not warned about
        for b in range(B):
            stepper.reset()
            out = _Output(P, b, xi_out, G_out, steps_t, steps_xi, steps_G, rec_all)
            events = _Events(P, b, ev)
            run = _Trajectory(P, b, stepper, out, events)
            status[b], failure[b], t_stop[b] = run.run()
            counts[:, b] = (run.nfev, run.steps, run.rejected)
            if done is not None:
                done(1)
    if rec_all:
        t_out = np.asarray(steps_t, dtype=float)
        xi_out = np.asarray(steps_xi, dtype=float).reshape(t_out.size, 1, k)
        G_out = np.asarray(steps_G, dtype=float).reshape(t_out.size, 1, q)
    raw = RawResult(t=t_out, xi=xi_out, G=G_out, status=status, t_stop=t_stop, failure=failure, nfev=counts[0],
                    steps=counts[1], rejected=counts[2], backend="numpy")
    for e in range(P.n_events):
        rows = [(b, t, x, g) for b in range(B) for (t, x, g) in ev[e][b]]
        raw.event_index.append(np.array([r[0] for r in rows], dtype=np.int64))
        raw.event_t.append(np.array([r[1] for r in rows], dtype=float))
        raw.event_xi.append(np.array([r[2] for r in rows], dtype=float).reshape(len(rows), k))
        raw.event_G.append(np.array([r[3] for r in rows], dtype=float).reshape(len(rows), q))
    return raw


# ---------------------------------------------------------------------------------------------------------
class _Output:
    """Where a trajectory's states go: the t_eval rows (by the continuous extension) or every step."""

    def __init__(self, P: Problem, b: int, xi_out, G_out, steps_t, steps_xi, steps_G, rec_all: bool) -> None:
        self.P, self.b, self.xi_out, self.G_out = P, b, xi_out, G_out
        self.rec_all = rec_all
        self.steps_t, self.steps_xi, self.steps_G = steps_t, steps_xi, steps_G
        self.next = 0  # first t_eval index not yet written

    def start(self, t0: float, xi, G) -> None:
        if self.rec_all:
            self.record(t0, xi, G)
        elif self.P.t_eval[0] == t0:
            self.write(0, xi, G)
            self.next = 1

    def record(self, t: float, xi, G) -> None:
        self.steps_t.append(t)
        self.steps_xi.append(np.array(xi, dtype=float).reshape(-1))
        self.steps_G.append(np.zeros(0) if G is None else np.array(G, dtype=float).reshape(-1))

    def write(self, i: int, xi, G) -> None:
        self.xi_out[i, self.b] = np.reshape(xi, -1)
        if G is not None:
            self.G_out[i, self.b] = np.reshape(G, -1)

    def pending(self, t: float, t_new: float, direction: float) -> list[int]:
        """The t_eval indices in (t, t_new] (in the direction of integration)."""
        if self.rec_all:
            return []
        te, out = self.P.t_eval, []
        i = self.next
        while i < te.size and direction * (te[i] - t_new) <= 0:
            out.append(i)
            i += 1
        return out


class _Events:
    """A trajectory's event functions: values at accepted points, crossings located on the extension."""

    def __init__(self, P: Problem, b: int, store) -> None:
        self.P, self.b, self.store = P, b, store
        self.E = P.n_events
        self.old = None

    def values(self, t: float, xi, G) -> np.ndarray:
        P = self.P
        vals = np.empty(self.E)
        for e, fn in enumerate(P.events):
            lin = P.event_linear[e]
            if lin is not None:
                coef, off = lin
                z = np.concatenate([np.reshape(xi, -1), np.reshape(G, -1) if G is not None else np.zeros(0)])
                vals[e] = float(coef[self.b] @ z - off[self.b])
            else:
                vals[e] = float(np.reshape(fn(t, *P.user_state(self.b, xi, G)), -1)[0])
        return vals

    def crossings(self, old: np.ndarray, new: np.ndarray, at_start: bool) -> list[int]:
        """Events whose value changed sign (in their direction) over the step (scipy's rule)."""
        out = []
        for e in range(self.E):
            g0, g1 = old[e], new[e]
            if at_start and g0 == 0.0:  # starting on the surface is not a crossing
                continue
            up = g0 <= 0.0 <= g1 and g0 != g1
            down = g0 >= 0.0 >= g1 and g0 != g1
            d = self.P.event_direction[e]
            if (up and d >= 0) or (down and d <= 0):
                out.append(e)
        return out


class _Trajectory:
    """One trajectory's time loop: controller, failure rules, output, events, re-projection."""

    def __init__(self, P: Problem, b: int, stepper: RKMKStepper, out: _Output, events: _Events) -> None:
        self.P, self.b, self.st, self.out, self.ev = P, b, stepper, out, events
        self.nfev = self.steps = self.rejected = 0
        self.xi, self.G, self.gamma = P.initial_state(b)
        self.renorm = max(RENORM_EVERY, P.m)

    def _flatG(self, G):
        return None if G is None else np.reshape(G, -1)

    def run(self) -> tuple[int, int, float]:
        st = self.st
        nfev0 = st.nfev
        try:
            return self._run()
        finally:
            self.nfev = st.nfev - nfev0

    def _fail(self, code: int, t: float) -> tuple[int, int, float]:
        return STATUS_FAILED, code, t

    def _run(self) -> tuple[int, int, float]:
        P, st = self.P, self.st
        t, t1, direction = P.t0, P.t1, P.direction
        f0 = st.field(self.xi, self.G, self.gamma)
        if not np.all(np.isfinite(f0)) or not np.all(np.isfinite(self.xi)):
            return self._fail(1, t)
        self.out.start(t, self.xi, self._flatG(self.G))
        ev_old = self.ev.values(t, self.xi, self._flatG(self.G)) if self.ev.E else None
        at_start = True
        if P.adaptive:
            h_abs = P.h if P.h > 0 else self._initial_step()
        else:
            h_abs = P.h
        after_reject = False
        # fixed step: the grid t0 + i h (no accumulated sums), the last step shortened to land on t1
        n_fixed = 0 if P.adaptive else max(1, math.ceil(abs(t1 - t) / h_abs - 1e-9))
        while direction * (t1 - t) > 0:
            if self.steps + self.rejected >= P.max_steps:
                return self._fail(3, t)
            if P.adaptive:
                if h_abs < 10 * abs(math.nextafter(t, direction * math.inf) - t):
                    return self._fail(2, t)
                hit = h_abs >= abs(t1 - t)
                h = (t1 - t) if hit else direction * h_abs
            else:
                hit = self.steps + 1 >= n_fixed
                h = (t1 if hit else P.t0 + direction * h_abs * (self.steps + 1)) - t
            xi1, G1, err, ok = st.trial(h, self.xi, self.G, self.gamma)
            if P.adaptive:
                norm = float(control.combine(err[0], err[1], P.k + P.q, P.plan.two_estimators)[0]) if ok else math.inf
                if not norm <= 1.0:
                    self.rejected += 1
                    h_abs = abs(h) * float(control.reject_factor(norm, P.plan.error_exponent))
                    after_reject = True
                    continue
            finite = bool(np.all(np.isfinite(xi1)) and (G1 is None or np.all(np.isfinite(G1))))
            if not finite:  # also a NaN chart argument: the field, not the chart, broke down
                return self._fail(1, t + h)
            if not ok:
                return self._fail(4, t)
            t_new = t1 if hit else t + h
            # the step is accepted: its interior, if asked for, comes from the continuous extension
            idx = self.out.pending(t, t_new, direction)
            ev_new = self.ev.values(t_new, xi1, self._flatG(G1)) if self.ev.E else None
            crossed = self.ev.crossings(ev_old, ev_new, at_start) if self.ev.E else []
            if idx or crossed:
                st.complete()
            stop_t = None
            if crossed:
                self._x1, self._G1 = xi1, G1
                stop_t = self._locate(crossed, t, h, t_new, ev_old, ev_new)
            for i in idx:
                te = P.t_eval[i]
                if stop_t is not None and direction * (te - stop_t) > 0:
                    break
                if te == t_new:
                    self.out.write(i, xi1, self._flatG(G1))
                else:
                    x, g = st.dense((te - t) / h, self.xi, self.G, h)
                    self.out.write(i, x, self._flatG(g))
                self.out.next = i + 1
            st.accept()
            self.steps += 1
            if stop_t is not None:
                return STATUS_TERMINAL, 0, stop_t
            if P.reproject and G1 is not None and self.steps % self.renorm == 0:
                G1 = P.reprojected(G1)
                st.reset()
            self.xi, self.G, t = xi1, G1, t_new
            if self.out.rec_all:
                self.out.record(t, self.xi, self._flatG(self.G))
            ev_old, at_start = ev_new, False
            if P.adaptive:
                h_new = abs(h) * float(control.accept_factor(norm, P.plan.error_exponent, after_reject))
                h_abs = max(h_abs, h_new) if hit else h_new
                after_reject = False
        return 0, 0, t1

    def _initial_step(self) -> float:
        """Hairer's starting step on the embedded state y = (xi, G), as scipy's (one more evaluation)."""
        P, st = self.P, self.st
        G = self.G
        y0 = np.concatenate([self.xi.reshape(-1), np.zeros(0) if G is None else G.reshape(-1)])
        f0 = np.concatenate([st.field(self.xi, G, self.gamma).reshape(-1), P.group_velocity(self.xi, G)])
        sc = control.scale(y0, y0, P.rtol, P.atol)
        d0 = math.sqrt(np.mean((y0 / sc) ** 2))
        d1 = math.sqrt(np.mean((f0 / sc) ** 2))
        h0 = float(control.probe_step(d0, d1))
        y1 = y0 + P.direction * h0 * f0
        xi1 = y1[: P.k].reshape(1, -1)
        G1 = None if G is None else y1[P.k:].reshape(G.shape)
        L1 = P.model.xi_dot(xi1, st.vertical(G1, self.gamma))
        st.nfev += 1
        f1 = np.concatenate([np.reshape(L1, -1), P.group_velocity(xi1, G1)])
        d2 = math.sqrt(np.mean(((f1 - f0) / sc) ** 2)) / h0
        return float(control.initial_step(d0, d1, d2, h0, P.plan.order))

    def _locate(self, crossed, t, h, t_new, ev_old, ev_new) -> float | None:
        """Locate each crossing on the extension, record them in time order; the first terminal time or None."""
        from scipy.optimize import brentq  # loaded when an event is first located

        P, st = self.P, self.st
        found = []
        for e in crossed:
            def value(theta, e=e):
                if theta == 1.0:
                    return ev_new[e]
                x, g = st.dense(theta, self.xi, self.G, h)
                return self.ev.values(t + theta * h, x, self._flatG(g))[e]

            lo_val = ev_old[e]
            if lo_val == 0.0:
                theta = 0.0
            elif ev_new[e] == 0.0:
                theta = 1.0
            else:
                xtol = 4.0 * abs(math.nextafter(t_new, math.inf) - t_new) / abs(h)
                theta = brentq(value, 0.0, 1.0, xtol=max(xtol, 1e-300), rtol=4 * np.finfo(float).eps, maxiter=200)
            found.append((theta, e))
        found.sort()
        stop = None
        for theta, e in found:
            if stop is not None and theta > stop:
                break
            if theta == 1.0:
                tc, x, g = t_new, self._x1, self._G1
            else:
                tc = t + theta * h
                x, g = st.dense(theta, self.xi, self.G, h)
            self.ev.store[e][self.b].append((tc, np.reshape(x, -1).copy(),
                                             np.zeros(0) if g is None else np.reshape(g, -1).copy()))
            if P.event_terminal[e]:
                stop = theta
        return None if stop is None else (t_new if stop == 1.0 else t + stop * h)
