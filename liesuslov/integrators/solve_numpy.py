"""The numpy solver: every trajectory of a batch with its own steps, advanced together in vectorised numpy.

The reference the compiled kernel (:mod:`.kernel`) is tested against, and the path for what the kernel
cannot run (a user potential, a user event function, a group part it does not know). Each trajectory
has its own time, step size, accept/reject, status and failure; the time loop advances all running
trajectories at once, with their step sizes as a (B,) array and masks for who is running, accepted,
rejected. The parts:

* the stepper (:class:`.rkmk.RKMKStepper`): trial steps, the extension's extra stages, dense states;
* the controller and the norm (:mod:`.control`), shared with the kernel — elementwise, so one call
  serves the batch;
* output (:class:`_Output`): t_eval served by the continuous extension (vectorised over every
  (trajectory, output time) pair of a step), or every step for a single trajectory;
* events (:class:`_Events`): values at accepted points (one call on the whole batch), crossings found for
  the whole batch at once, roots located by Illinois on the continuous extension — every crossing of a
  loop's accepted steps at once, each by its own iteration (the rules of :mod:`.control`, as the kernel's).

A trajectory's numbers do not depend on its batch mates or on B: no computation mixes trajectories
(see :mod:`.rkmk`), and one trajectory is a batch of one on the same code. When trajectories end, the
working arrays keep them (their rows take zero steps nobody reads) until a quarter of the rows have
ended; then the arrays are compressed to the running ones.
"""

from __future__ import annotations

import numpy as np

from . import control
from .problem import RENORM_EVERY, STATUS_FAILED, STATUS_REACHED, STATUS_TERMINAL, Problem, RawResult
from .rkmk import RKMKStepper, Step

__all__ = ["solve"]


def solve(problem: Problem, done=None) -> RawResult:
    """Integrate every trajectory of ``problem`` on numpy (see :class:`~.problem.RawResult`).

    ``done(n)``, if given, is called with the number of trajectories that ended at each step of the
    loop (a progress bar's ``update``).
    """
    with np.errstate(all="ignore"):  # a diverging step is detected (status -1), not warned about
        return _Solve(problem, done).run()


def _where(mask: np.ndarray):
    """``(rows, count)`` where ``mask`` holds: ``slice(None)`` when it holds for every row (selections are then
    views, not copies), else the indices."""
    n = int(np.count_nonzero(mask))
    return (slice(None) if n == mask.size else np.flatnonzero(mask)), n


# ---------------------------------------------------------------------------------------------------------
class _Output:
    """Where the states go: the t_eval rows (written by trajectory and output index), or every step (B = 1)."""

    def __init__(self, P: Problem) -> None:
        self.P = P
        self.rec_all = P.t_eval is None
        M = 0 if self.rec_all else P.t_eval.size
        self.xi = np.full((M, P.B, P.k), np.nan)
        self.G = np.full((M, P.B, P.q), np.nan)
        # t_eval in increasing order of direction * t, for searchsorted
        self.key = None if self.rec_all else P.direction * P.t_eval
        self.steps_t, self.steps_xi, self.steps_G = [], [], []

    def write(self, i: np.ndarray, traj: np.ndarray, xi: np.ndarray, G: np.ndarray | None) -> None:
        """Rows ``(i[r], traj[r])`` of the output get ``xi[r]``, ``G[r]`` (flattened)."""
        self.xi[i, traj] = xi
        if G is not None:
            self.G[i, traj] = G.reshape(G.shape[0], self.P.q)

    def record(self, t: float, xi: np.ndarray, G: np.ndarray | None) -> None:
        """Every step (one trajectory): the state (1, k) and group part after an accepted step."""
        self.steps_t.append(t)
        self.steps_xi.append(np.array(xi, dtype=float).reshape(-1))
        self.steps_G.append(np.zeros(0) if G is None else np.array(G, dtype=float).reshape(-1))

    def end(self, t_new: np.ndarray, closed: bool = True) -> np.ndarray:
        """For each step end, one past the last t_eval index in the step's interval (t, t_new] (``closed``)
        or (t, t_new) (the output times the continuous extension serves: the end is the step's own)."""
        return np.searchsorted(self.key, self.P.direction * t_new, side="right" if closed else "left")

    def arrays(self):
        """``(t, xi (M, B, k), G (M, B, q))`` for the :class:`~.problem.RawResult`."""
        P = self.P
        if not self.rec_all:
            return P.t_eval, self.xi, self.G
        t = np.asarray(self.steps_t, dtype=float)
        return (t, np.asarray(self.steps_xi, dtype=float).reshape(t.size, 1, P.k),
                np.asarray(self.steps_G, dtype=float).reshape(t.size, 1, P.q))


class _Events:
    """The event functions: values at accepted points, crossings, and what was found (in the order found)."""

    def __init__(self, P: Problem) -> None:
        self.P = P
        self.E = P.n_events
        self.found = [[] for _ in range(self.E)]  # per event: (trajectory, t, xi (k,), G (q,))
        self.count = np.zeros((P.B, self.E), dtype=np.int64)  # crossings so far, per trajectory and event
        if any(lin is None for lin in P.event_linear):
            # a user callable sees the whole batch: each trajectory at its last accepted point, but those asked about
            self.last_t, self.last_xi, self.last_G = np.full(P.B, P.t0), P.xi0.copy(), P.G0.copy()

    def values(self, t: np.ndarray, xi: np.ndarray, G: np.ndarray | None, traj: np.ndarray, which=None,
               accepted: bool = False, start: bool = False) -> np.ndarray:
        """Event values (R, E) — or (R, len(which)) — at times ``t`` (R,) and states of the R distinct
        trajectories ``traj``; ``accepted``: they are accepted points (the trajectories' last points from now on).

        A :class:`~.events.LinearEvent` is one stacked dot product per trajectory; a user callable is called
        once, on the whole batch (:meth:`~.problem.Problem.call_event`), with the other trajectories at their
        last accepted points — so it may use per-trajectory parameters of the batch's shape. ``start``: the
        values at t0, where a linear event within its rounding of 0 is 0 (:func:`.control.on_surface_at_start`).
        """
        P = self.P
        R = traj.size
        which = range(self.E) if which is None else which
        Gf = None if G is None else G.reshape(R, -1)
        z = np.ascontiguousarray(xi if G is None else np.concatenate([xi, Gf], axis=1))
        out = np.empty((R, len(which)))
        batch = None
        for c, e in enumerate(which):
            lin = P.event_linear[e]
            if lin is not None:
                coef, off = lin
                out[:, c] = np.matmul(coef[traj][:, None, :], z[:, :, None])[:, 0, 0] - off[traj]
                if start:
                    magnitude = np.abs(off[traj]) + np.sum(np.abs(coef[traj] * z), axis=1)
                    out[:, c] = control.on_surface_at_start(out[:, c], magnitude, z.shape[1])
                continue
            if batch is None:
                T, X, GG = ((self.last_t, self.last_xi, self.last_G) if accepted
                            else (self.last_t.copy(), self.last_xi.copy(), self.last_G.copy()))
                T[traj], X[traj] = t, xi
                if Gf is not None:
                    GG[traj] = Gf
                batch = (T, X, None if Gf is None else GG)
            out[:, c] = P.call_event(e, *batch)[traj]
            if np.isnan(out[:, c]).any():  # the crossing rule cannot see through NaN: no crossing would be found
                r = int(np.flatnonzero(np.isnan(out[:, c]))[0])
                raise ValueError(f"events[{e}] returned NaN for trajectory {int(traj[r])} (flat index) at t = "
                                 f"{float(t[r]):.17g}, a finite state; an event must return real numbers")
        return out

    def crossings(self, old: np.ndarray, new: np.ndarray) -> np.ndarray:
        """(R, E) bool: the events the step crossed (:func:`.control.crossed`)."""
        return control.crossed(old, new, self.P.event_direction[None, :])

    def record(self, e: int, traj: int, t: float, xi: np.ndarray, G: np.ndarray | None) -> bool:
        """Keep a crossing; True when it is the one at which the event stops the trajectory."""
        g = np.zeros(0) if G is None else np.reshape(G, -1).copy()
        self.found[e].append((traj, t, np.reshape(xi, -1).copy(), g))
        self.count[traj, e] += 1
        return bool(self.count[traj, e] == self.P.event_terminal[e])

    def arrays(self, k: int, q: int):
        """Per event: ``(index, t, xi, G)`` sorted by trajectory, then time (the order found within one)."""
        out = []
        for rows in self.found:
            order = sorted(range(len(rows)), key=lambda r: rows[r][0])  # stable: time order within a trajectory
            rows = [rows[r] for r in order]
            out.append((np.array([r[0] for r in rows], dtype=np.int64), np.array([r[1] for r in rows], dtype=float),
                        np.array([r[2] for r in rows], dtype=float).reshape(len(rows), k),
                        np.array([r[3] for r in rows], dtype=float).reshape(len(rows), q)))
        return out


class _Solve:
    """The time loop over the working set: the trajectories still running (and some that ended, until
    the set is compressed), each row with its own time, step size, counters and cached field value.

    Row arrays (A rows): ``idx`` (the trajectory), ``t``, ``h_abs``, ``after_reject``, ``nonfinite_trial`` (the
    last trial step, inside the chart's domain, met a non-finite value: an underflow then is failure 6), ``steps``,
    ``rejected``, ``nfev``, ``xi`` (A, k), ``G`` (A, m, m) / (A, n) / None, ``gamma`` (A, n) / None,
    ``first`` (A, k) and ``have_first`` (the field at the current point, reused as the next stage 0),
    ``ev_old`` (A, E), ``next_out`` (first t_eval index not yet written), ``live``.
    """

    _ROWS = ("idx", "t", "h_abs", "after_reject", "nonfinite_trial", "steps", "rejected", "nfev", "xi", "G", "gamma",
             "first", "have_first", "ev_old", "next_out", "live")

    def __init__(self, P: Problem, done) -> None:
        self.P, self.done_cb = P, done
        B = P.B
        # the kernel's kind when the problem was built for it (tests compare the two on one Problem), else the default
        self.st = RKMKStepper(P.model, P.plan, P.chart, P.mode, kind=P.kind, rtol=P.rtol, atol=P.atol)
        self.out = _Output(P)
        self.ev = _Events(P)
        self.status = np.zeros(B, np.int64)
        self.failure = np.zeros(B, np.int64)
        self.t_stop = np.full(B, P.t1)
        self.counts = np.zeros((3, B), np.int64)  # nfev, steps, rejected
        self.renorm = max(RENORM_EVERY, P.m)
        self.ncomp = P.k + P.q
        self.n_fixed = 0
        self.tries = 0  # trial steps so far: no trajectory has made more (it makes at most one per loop)
        # a step above it is above 10 ulps of any t of the span (the underflow test)
        self.h_floor = float(control.step_floor(P.t0, P.t1))
        # the rows
        self.idx = np.arange(B)
        self.t = np.full(B, P.t0)
        self.h_abs = np.zeros(B)
        self.after_reject = np.zeros(B, dtype=bool)
        self.nonfinite_trial = np.zeros(B, dtype=bool)
        self.steps = np.zeros(B, np.int64)
        self.rejected = np.zeros(B, np.int64)
        self.nfev = np.zeros(B, np.int64)
        self.xi = P.xi0.copy()
        self.G = {"g": lambda: P.G0.reshape(B, P.m, P.m).copy(), "gamma": lambda: P.G0.copy(),
                  "none": lambda: None}[P.mode]()
        self.gamma = P.gamma if P.gamma.shape[-1] else None
        self.first = np.zeros((B, P.k))
        self.have_first = np.zeros(B, dtype=bool)
        self.ev_old = np.zeros((B, self.ev.E))
        self.next_out = np.zeros(B, np.int64)
        self.live = np.ones(B, dtype=bool)

    # ------------------------------------------------------------------ bookkeeping
    def _end(self, rows: np.ndarray, status: int, failure: int, t) -> None:
        """Trajectories at ``rows`` (working-set indices) end with ``status``, ``failure`` at time(s) ``t``."""
        if rows.size == 0:
            return
        b = self.idx[rows]
        self.status[b], self.failure[b], self.t_stop[b] = status, failure, t
        self.counts[:, b] = (self.nfev[rows], self.steps[rows], self.rejected[rows])
        self.live[rows] = False
        if self.done_cb is not None:
            self.done_cb(int(rows.size))

    def _fail(self, mask: np.ndarray, code: int, t: np.ndarray) -> None:
        rows = np.flatnonzero(mask)
        self._end(rows, STATUS_FAILED, code, t[rows])

    def _compress(self) -> None:
        """Drop the rows that ended once they are a quarter of the working set (their zero steps cost work)."""
        A = self.live.size
        dead = A - int(np.count_nonzero(self.live))
        if dead == 0 or 4 * dead < A:
            return
        keep = np.flatnonzero(self.live)
        for name in self._ROWS:
            a = getattr(self, name)
            if a is not None:
                setattr(self, name, a[keep])

    # ------------------------------------------------------------------ the loop
    def run(self) -> RawResult:
        self._start()
        while True:
            self._compress()
            if self.live.size == 0:
                break
            self._iterate()
        P = self.P
        t_out, xi_out, G_out = self.out.arrays()
        raw = RawResult(t=t_out, xi=xi_out, G=G_out, status=self.status, t_stop=self.t_stop, failure=self.failure,
                        nfev=self.counts[0], steps=self.counts[1], rejected=self.counts[2], backend="numpy")
        for index, t, x, g in self.ev.arrays(P.k, P.q):
            raw.event_index.append(index)
            raw.event_t.append(t)
            raw.event_xi.append(x)
            raw.event_G.append(g)
        return raw

    def _start(self) -> None:
        """The field at t0 (a non-finite one fails at once), the output at t0, event values, the first step."""
        P, st = self.P, self.st
        self.first = st.field(self.xi, self.G, self.gamma)
        self.have_first[:] = True
        self.nfev += 1
        # the initial state is reported even where the field fails there (NaN only after the failure time)
        if self.out.rec_all:
            self.out.record(P.t0, self.xi, self.G)
        elif P.t_eval[0] == P.t0:
            self.out.write(np.zeros(P.B, np.int64), self.idx, self.xi, self.G)
            self.next_out[:] = 1
        finite = np.all(np.isfinite(self.first), axis=1) & np.all(np.isfinite(self.xi), axis=1)
        self._fail(~finite, 1, self.t)
        live = np.flatnonzero(self.live)
        if self.ev.E:
            self.ev_old[live] = self.ev.values(self.t[live], self.xi[live], self._rows(self.G, live), self.idx[live],
                                                accepted=True, start=True)
        if not P.adaptive:
            self.h_abs[:] = P.h
            if not P.h >= self.h_floor:  # below the resolution of t: the grid would not be t0 + i h
                self._fail(self.live.copy(), 5, self.t)
            # fixed step: the grid t0 + i h (no accumulated sums), the last step shortened to land on t1
            self.n_fixed = control.fixed_steps(abs(P.t1 - P.t0), P.h, P.max_steps + 1)
        elif P.h > 0:
            self.h_abs[:] = P.h
        elif live.size:
            self.h_abs[live] = self._initial_step(live)

    @staticmethod
    def _rows(a, rows):
        return None if a is None else a[rows]

    def _initial_step(self, rows: np.ndarray) -> np.ndarray:
        """Hairer's starting step on the embedded state y = (xi, G), as scipy's (one more evaluation each)."""
        P, st = self.P, self.st
        R = rows.size
        xi, G, gamma, f0 = self.xi[rows], self._rows(self.G, rows), self._rows(self.gamma, rows), self.first[rows]

        def flat(x, g):  # (R, k + q), C-contiguous: the means below run along each trajectory's own numbers
            return np.ascontiguousarray(x if g is None else np.concatenate([x, g.reshape(R, -1)], axis=1))

        y0 = flat(xi, G)
        F0 = flat(f0, self._group_velocity(xi, G))
        sc = control.scale(y0, y0, P.rtol, P.atol)
        d0 = np.sqrt(np.mean((y0 / sc) ** 2, axis=1))
        d1 = np.sqrt(np.mean((F0 / sc) ** 2, axis=1))
        h0 = control.probe_step(d0, d1)
        y1 = y0 + (P.direction * h0)[:, None] * F0
        xi1 = np.ascontiguousarray(y1[:, : P.k])
        G1 = None if G is None else np.ascontiguousarray(y1[:, P.k:]).reshape(G.shape)
        F1 = flat(st.field(xi1, G1, gamma), self._group_velocity(xi1, G1))
        self.nfev[rows] += 1
        d2 = np.sqrt(np.mean(((F1 - F0) / sc) ** 2, axis=1)) / h0
        return control.initial_step(d0, d1, d2, h0, P.plan.order)

    def _group_velocity(self, xi: np.ndarray, G: np.ndarray | None) -> np.ndarray | None:
        """d/dt of the group part: ``g Omega`` (attitude) or ``-Omega Gamma`` (vertical), one product per trajectory."""
        if G is None:
            return None
        Om = self.P.model.omega_matrix(np.ascontiguousarray(xi)[:, None, :])[:, 0]  # (R, m, m)
        if self.P.mode == "g":
            return np.matmul(G, Om)
        return -np.matmul(Om, G[:, :, None])[:, :, 0]

    def _iterate(self) -> None:
        """One trial step of every running trajectory; the accepted ones advance."""
        P, st, plan = self.P, self.st, self.P.plan
        direction, t1, t = P.direction, P.t1, self.t
        live = self.live
        if self.tries >= P.max_steps:  # (no trajectory can have reached max_steps before)
            self._fail(live & (self.steps + self.rejected >= P.max_steps), 3, t)
        self.tries += 1
        if P.adaptive and self.h_abs.min() < self.h_floor:  # below ten ulps of t the step no longer moves t
            under = live & control.underflow(self.h_abs, t, direction)
            self._fail(under & ~self.nonfinite_trial, 2, t)
            self._fail(under & self.nonfinite_trial, 6, t)
        n_live = int(np.count_nonzero(live))
        if n_live == 0:
            return
        everyone = n_live == live.size  # then selections are slices (views), not index arrays (copies)
        if P.adaptive:
            hit = self.h_abs >= np.abs(t1 - t)
            h = np.where(hit, t1 - t, direction * self.h_abs)
        else:
            hit = self.steps + 1 >= self.n_fixed
            h = np.where(hit, t1, P.t0 + direction * self.h_abs * (self.steps + 1)) - t
        if not everyone:
            h = np.where(live, h, 0.0)  # the rows that ended take a zero step, never read
        # stage 0: the field at the current point, unless the last step left it (the plan's new-point rule)
        need = ~self.have_first if everyone else live & ~self.have_first
        sel, n = _where(need)
        if n:
            self.first[sel] = st.field(self.xi[sel], self._rows(self.G, sel), self._rows(self.gamma, sel))
            self.have_first[sel] = True
            self.nfev[sel] += 1
        step = st.trial(h, self.xi, self.G, self.gamma, self.first)
        self.nfev[_where(live)[0] if not everyone else slice(None)] += plan.step_stages - 1
        norm = None
        if P.adaptive:
            s5, s3 = step.err
            norm = np.where(step.ok, control.combine(s5, s3, self.ncomp, plan.two_estimators), np.inf)
            accepted = norm <= 1.0  # a NaN norm never is
            if not everyone:
                accepted &= live
            rej = live & ~accepted
            if rej.any():
                self.rejected[rej] += 1
                self.h_abs = np.where(rej, np.abs(h) * control.reject_factor(norm, plan.error_exponent), self.h_abs)
                self.after_reject |= rej
        else:
            accepted = live
        G1 = step.G1
        if np.isfinite(step.xi1).all() and (G1 is None or np.isfinite(G1).all()):  # one test for the batch
            finite = np.ones(live.size, dtype=bool)
        else:  # which trajectories
            finite = np.all(np.isfinite(step.xi1), axis=1)
            if G1 is not None:
                finite &= np.all(np.isfinite(G1.reshape(G1.shape[0], -1)), axis=1)
        if P.adaptive:
            self.nonfinite_trial = step.ok & ~finite
        good = accepted & finite & step.ok
        sel, n = _where(good)
        if n < np.count_nonzero(accepted):
            # fixed steps (an adaptive one beyond the domain is rejected); the domain first: a step beyond it may
            # also end non-finite, and that is not the field's fault
            self._fail(accepted & ~step.ok, 4, t)
            self._fail(accepted & step.ok & ~finite, 1, t + h)
        if n:
            self._accept(sel, n, step, h[sel], hit[sel], None if norm is None else norm[sel])

    def _accept(self, sel, R: int, step: Step, h: np.ndarray, hit: np.ndarray, norm) -> None:
        """The accepted steps of the rows ``sel`` (a slice or indices, R rows): output inside them, events,
        the next step's size and stage 0."""
        P, st, out, ev = self.P, self.st, self.out, self.ev
        direction, plan = P.direction, P.plan
        t = self.t[sel]
        t_new = np.where(hit, P.t1, t + h)
        xi1 = step.xi1[sel]
        G1 = None if step.G1 is None else step.G1[sel]
        # the output times in (t, t_new]; those inside (t, t_new) and the events crossed need the continuous
        # extension (an output time at t_new is the step's end itself)
        n_out = None
        if not out.rec_all:
            end = out.end(t_new)
            n_out = end - self.next_out[sel]
        need = None if n_out is None else out.end(t_new, closed=False) > self.next_out[sel]
        if ev.E:
            ev_new = ev.values(t_new, xi1, G1, self.idx[sel], accepted=True)
            crossed = ev.crossings(self.ev_old[sel], ev_new)
            hits = crossed.any(axis=1)
            need = hits if need is None else need | hits
        some_out = n_out is not None and n_out.any()
        rows = np.arange(self.live.size)[sel] if (need is not None and need.any()) or ev.E or some_out else None
        sub, pos = None, None  # working-set index of each accepted row (where needed); the extension
        if need is not None and need.any():
            ext = np.flatnonzero(need)  # positions among the accepted rows
            sub = step.take(rows[ext])
            st.complete(sub)
            self.nfev[rows[ext]] += plan.S - step.done
            pos = np.full(R, -1, np.int64)  # position of each accepted row in sub
            pos[ext] = np.arange(ext.size)
        # events: roots on the extension, per trajectory (few steps have a crossing)
        stop_t = None
        if ev.E and hits.any():
            stop_t = self._locate(sub, pos, self.idx[rows], crossed, t, h, t_new, self.ev_old[sel], ev_new, xi1, G1)
        # output: every (trajectory, t_eval index) pair of these steps at once
        if some_out:
            self._write(rows, n_out, t, h, t_new, xi1, G1, sub, pos, stop_t)
        if n_out is not None:
            self.next_out[sel] = end
        # the next step's stage 0: the field at the new point if this step evaluated it
        L = st.new_point_field(step)
        if L is not None:
            self.first[sel] = L[sel]
        self.have_first[sel] = L is not None
        if sub is not None:
            self.first[rows[ext]] = st.new_point_field(sub)
            self.have_first[rows[ext]] = True
        self.steps[sel] += 1
        if stop_t is not None:  # terminal events end their trajectories there; the others go on
            stopped = ~np.isnan(stop_t)
            self._end(rows[stopped], STATUS_TERMINAL, 0, stop_t[stopped])
            go = ~stopped
            sel, rows, R = rows[go], rows[go], int(np.count_nonzero(go))
            t_new, xi1, h, hit, ev_new = t_new[go], xi1[go], h[go], hit[go], ev_new[go]
            G1 = None if G1 is None else G1[go]
            norm = None if norm is None else norm[go]
        if out.rec_all and R:  # the step's own end, as an output time there gets it (before any re-projection)
            out.record(float(t_new[0]), xi1, G1)
        if P.reproject and G1 is not None:
            rp = self.steps[sel] % self.renorm == 0
            if rp.any():
                G1 = G1.copy()
                G1[rp] = P.reprojected(G1[rp])
                self.have_first[np.arange(self.live.size)[sel][rp]] = False
        self.xi[sel] = xi1
        if G1 is not None:
            self.G[sel] = G1
        self.t[sel] = t_new
        if ev.E:
            self.ev_old[sel] = ev_new
        if P.adaptive:
            h_new = np.abs(h) * control.accept_factor(norm, plan.error_exponent, self.after_reject[sel])
            self.h_abs[sel] = np.where(hit, np.maximum(self.h_abs[sel], h_new), h_new)
            self.after_reject[sel] = False
        reached = direction * (P.t1 - t_new) <= 0
        if reached.any():
            self._end(np.arange(self.live.size)[sel][reached], STATUS_REACHED, 0, P.t1)

    def _write(self, rows, n_out, t, h, t_new, xi1, G1, sub: Step | None, pos, stop_t) -> None:
        """Output at the t_eval indices of the accepted steps: the step's end where it is an output time,
        the continuous extension inside — every (trajectory, index) pair at once."""
        P, out = self.P, self.out
        rr = np.repeat(np.arange(n_out.size), n_out)  # accepted row of each pair
        i = self.next_out[rows][rr] + (np.arange(rr.size) - np.repeat(np.cumsum(n_out) - n_out, n_out))
        te = P.t_eval[i]
        if stop_t is not None:  # not past a terminal event
            keep = ~(P.direction * (te - stop_t[rr]) > 0)
            rr, i, te = rr[keep], i[keep], te[keep]
        traj = self.idx[rows]
        at_end = te == t_new[rr]
        if at_end.any():
            a = rr[at_end]
            out.write(i[at_end], traj[a], xi1[a], None if G1 is None else G1[a])
        inner = ~at_end
        if inner.any():
            a = rr[inner]
            x, g = self.st.dense(sub, (te[inner] - t[a]) / h[a], pos[a])
            out.write(i[inner], traj[a], x, g)

    def _locate(self, sub: Step, pos: np.ndarray, traj: np.ndarray, crossed: np.ndarray, t: np.ndarray,
                h: np.ndarray, t_new: np.ndarray, ev_old: np.ndarray, ev_new: np.ndarray, xi1: np.ndarray,
                G1) -> np.ndarray:
        """Locate the crossings ``crossed`` (R, E) of the R accepted steps of trajectories ``traj`` — all at once, on
        their continuous extensions (rows ``pos`` of ``sub``), each (step, event) pair by its own Illinois
        iteration (:mod:`.control`'s rules, as the kernel's) — and record them per trajectory in time order, up
        to its first terminal one. Returns (R,) the terminal times, NaN where none stopped."""
        P, st, ev = self.P, self.st, self.ev
        r, e = np.nonzero(crossed)  # the (step, event) pairs
        lo, hi = np.zeros(r.size), np.ones(r.size)
        flo, fhi = ev_old[r, e], ev_new[r, e]
        vlo, vhi = flo.copy(), fhi.copy()
        side = np.zeros(r.size, np.int64)
        theta = np.where(fhi == 0.0, 1.0, -1.0)  # (a step that starts at 0 is not a crossing)
        tr, hr = t[r], h[r]
        active = theta < 0.0
        for _ in range(300):
            a = np.flatnonzero(active)
            c = control.secant_point(lo[a], hi[a], flo[a], fhi[a])
            inside = (lo[a] < c) & (c < hi[a])  # not when the bracket is down to adjacent floats
            active[a[~inside]] = False
            a, c = a[inside], c[inside]
            if a.size == 0:
                break
            x, g = st.dense(sub, c, pos[r[a]])
            fc = np.empty(a.size)
            for ee in np.unique(e[a]):  # (a trajectory appears once per event)
                m = e[a] == ee
                fc[m] = ev.values(tr[a[m]] + c[m] * hr[a[m]], x[m], None if g is None else g[m], traj[r[a[m]]],
                                  which=[ee])[:, 0]
            zero = fc == 0.0
            theta[a[zero]] = c[zero]
            active[a[zero]] = False
            a, c, fc = a[~zero], c[~zero], fc[~zero]
            lo[a], hi[a], flo[a], fhi[a], vlo[a], vhi[a], side[a] = control.illinois_update(
                lo[a], hi[a], flo[a], fhi[a], vlo[a], vhi[a], side[a], c, fc)
            active[a[control.bracket_closed(tr[a], hr[a], lo[a], hi[a], c, P.direction)]] = False
        open_ = theta < 0.0
        theta[open_] = control.closest_end(lo[open_], hi[open_], vlo[open_], vhi[open_])
        # the states at the roots: the step's end itself at theta = 1, else the extension
        inner = np.flatnonzero(theta < 1.0)
        xs = xi1[r].copy()
        Gs = None if G1 is None else G1[r].copy()
        if inner.size:
            x, g = st.dense(sub, theta[inner], pos[r[inner]])
            xs[inner] = x
            if Gs is not None:
                Gs[inner] = g
        stop = np.full(crossed.shape[0], np.nan)  # theta of each step's first terminal crossing
        for i in np.lexsort((e, theta, r)):  # by step, then time, then event
            j = r[i]
            if stop[j] < theta[i]:  # past this trajectory's terminal crossing
                continue
            tc = t_new[j] if theta[i] == 1.0 else t[j] + theta[i] * h[j]
            if ev.record(int(e[i]), int(traj[j]), tc, xs[i], None if Gs is None else Gs[i]) and np.isnan(stop[j]):
                stop[j] = theta[i]
        return np.where(stop == 1.0, t_new, t + stop * h)
