"""The front door: :func:`integrate` a scene with a Lie-group method, over a batch of initial data."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .. import groups
from .._validation import as_float_array, check_positive
from .charts import CHARTS, make_chart
from .rkmk import RKMKStepper
from .solution import Solution
from .tableaux import get_tableau

__all__ = ["integrate", "METHODS", "Method"]


@dataclass(frozen=True)
class Method:
    """A named method: a tableau (by name) and whether the step size is adapted."""

    tableau: str
    adaptive: bool
    description: str


METHODS: dict[str, Method] = {
    "lie-euler": Method("euler", False, "Lie–Euler, order 1, fixed step"),
    "rkmk2": Method("midpoint", False, "RKMK with the explicit midpoint rule, order 2, fixed step"),
    "rkmk-heun": Method("heun2", False, "RKMK with Heun's method, order 2, fixed step"),
    "rkmk3": Method("kutta3", False, "RKMK with Kutta's third-order method, fixed step"),
    "rkmk4": Method("rk4", False, "RKMK with the classical fourth-order tableau, fixed step"),
    "rkmk5": Method("dopri5", False, "RKMK with the Dormand–Prince 5 weights, order 5, fixed step"),
    "rkmk8": Method("dop853", False, "RKMK with the DOP853 weights, order 8, fixed step"),
    "rkmk23": Method("bs3", True, "RKMK with the Bogacki–Shampine 3(2) pair, adaptive"),
    "rkmk45": Method("dopri5", True, "RKMK with the Dormand–Prince 5(4) pair, adaptive"),
    "rkmk853": Method("dop853", True, "RKMK with the Dormand–Prince 8(5,3) pair, adaptive"),
}

_SAFETY, _MIN_FACTOR, _MAX_FACTOR = 0.9, 0.2, 10.0
BACKENDS = ("auto", "numpy", "numba")
# Products g <- g phi(Theta) add ~1e-16 per step to |g^T g - I| (linearly when steps are alike: 5e-13
# after 1e5 steps); a Newton-Schulz step every _RENORM steps (a change of that size, far below the
# truncation error) keeps g in SO(n) to ~1e-15 whatever the length of the run. Likewise |Gamma| = 1.
_RENORM = 64


def integrate(system, Omega0, t_span, *, Gamma0=None, g0=None, reconstruct: bool = False,
              method: str = "rkmk4", chart: str = "exp", h: float | None = None, rtol: float = 1e-8,
              atol: float = 1e-10, t_eval=None, form: str = "auto", first_step: float | None = None,
              max_steps: int = 10_000_000, progress: bool = False, backend: str = "auto") -> Solution:
    """Integrate a Suslov / Euler–Poincaré–Suslov system by a Runge–Kutta–Munthe-Kaas method.

    The smallest exact model of the scene is integrated (see ``system.model``): reduced
    coordinates ``xi`` in the constraint subspace D (so the constraints hold exactly), Gamma only
    when the potential needs it or ``Gamma0`` is given, the attitude g only when
    ``reconstruct=True`` — and then Gamma is read off it, ``Gamma = g^T gamma``.

    Parameters
    ----------
    system : SuslovSystem or Model
        A system (its smallest model is chosen) or a model object following the protocol of
        :class:`liesuslov.mechanics.Model` (``k``, ``n``, ``has_gamma``, ``algebra``, ``subspace``,
        ``xi_dot``, ``omega_matrix``, ``omega_coords``, ``xi_from_coords``, ``form``, ``state_dim``).
    Omega0 : array_like, shape (..., n, n) or (..., d)
        Initial angular velocity in D: skew matrices (so(n)) or coordinates in the algebra basis.
        A trailing (n, n) block that is skew-symmetric is read as a matrix.
    t_span : (t0, t1)
        Integration interval; ``t1 < t0`` integrates backward.
    Gamma0 : array_like, shape (..., n), optional
        Initial vertical in the body frame (unit vectors). Required when the potential is not zero.
    g0 : array_like, shape (..., m, m), optional
        Initial attitude (default the identity); only with ``reconstruct=True`` (a ValueError
        otherwise, since it would be ignored).
    reconstruct : bool
        Also integrate ``g^{-1} dg/dt = Omega`` on the group.
    method : str
        A key of :data:`METHODS` ("lie-euler", "rkmk2", "rkmk-heun", "rkmk3", "rkmk4", "rkmk5",
        "rkmk8" fixed step; "rkmk23", "rkmk45", "rkmk853" adaptive).
    chart : {"exp", "cayley"}
    h : float, optional
        Step size (positive), required by fixed-step methods; the first step of adaptive ones.
    rtol, atol : float
        Tolerances of adaptive methods (error per step, RMS over a trajectory's components,
        maximum over the batch).
    t_eval : array_like, optional
        Times at which the solution is returned, hit exactly (steps are shortened to land on
        them). Default: every step.
    form : str
        Force a model form ("auto", "reduced", "eigenspace", "symmetric", "multiplier").
    first_step : float, optional
        Initial step of adaptive methods (default: Hairer's estimate).
    max_steps : int
        Give up (failed status) after this many steps.
    progress : bool
        Show a progress bar (needs tqdm).
    backend : {"auto", "numpy", "numba"}
        Who takes the steps (the time loop, controller and output are the same). "auto" uses the
        compiled kernel (:mod:`liesuslov.integrators.compiled`, agreeing with numpy to rounding) when
        numba is installed (``liesuslov[fast]``) and the model qualifies (a polynomial field: built-in
        potentials, gyroscopic term; a group part on SO(n), n <= 24), else numpy; "numpy" forces the reference
        path; "numba" requires the kernel and raises ValueError saying why it cannot run. The first
        compiled run on a machine compiles the kernel (~10–30 s, cached on disk); ``stats["backend"]``
        says which ran.

    Returns
    -------
    Solution
        ``t (N,)``, ``omega (N, ..., d)``, ``Omega (N, ..., n, n)``, ``Gamma (N, ..., n)`` or None,
        ``g (N, ..., m, m)`` or None, ``xi``, ``stats`` (nfev, steps, rejected, …), ``status``,
        ``message``. A non-finite state or a step-size underflow ends the run with
        ``status = -1`` and a message naming the time; the arrays hold what was computed before.

    Notes
    -----
    A batch (leading axes of Omega0, Gamma0, g0, broadcast together) is advanced in one
    vectorised loop with one step size: adaptive methods choose it from the worst trajectory's
    error, so every trajectory meets the tolerance and all share the output times.
    """
    from ..mechanics import SuslovSystem

    is_model = all(hasattr(system, a) for a in ("xi_dot", "omega_matrix", "subspace", "k"))
    if not (isinstance(system, SuslovSystem) or is_model):
        raise TypeError(f"system must be a SuslovSystem (or a model such as system.model()), "
                        f"got {type(system).__name__}")
    for name, value in (("method", method), ("chart", chart), ("backend", backend), ("form", form)):
        if not isinstance(value, str):
            raise TypeError(f"{name} must be a string, got {type(value).__name__}")
    if not isinstance(reconstruct, (bool, np.bool_)):
        raise TypeError(f"reconstruct must be True or False, got {type(reconstruct).__name__}")
    if isinstance(h, (bool, np.bool_)):
        raise TypeError("h must be a positive number (the step size), got a bool")
    if method not in METHODS:
        raise ValueError(f"method must be one of {sorted(METHODS)}, got {method!r}")
    if chart not in CHARTS:
        raise ValueError(f"chart must be one of {CHARTS}, got {chart!r}")
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    meth = METHODS[method]
    t0, t1 = _check_t_span(t_span)
    direction = 1.0 if t1 > t0 else -1.0
    if meth.adaptive:
        rtol = check_positive(rtol, "rtol")
        atol = check_positive(atol, "atol")
        if h is not None and first_step is None:
            first_step = check_positive(h, "h")
        elif first_step is not None:
            first_step = check_positive(first_step, "first_step")
    else:
        if h is None:
            raise ValueError(f"h (the step size) is required by the fixed-step method {method!r}; "
                             "pass h=..., or use an adaptive method such as 'rkmk45'")
        h = check_positive(h, "h")
    t_eval = _check_t_eval(t_eval, t0, t1)

    if is_model:
        model = system
        if Gamma0 is not None and not model.has_gamma:
            raise ValueError("Gamma0 was given but this model has no Gamma; build it with system.model(gamma=True)")
    else:
        if Gamma0 is not None and not system.is_so:
            raise ValueError(f"Gamma0 must be None on {system.algebra.name}: the vertical Gamma exists only for a "
                             "body in SO(n)")
        model = system.model(gamma=True if Gamma0 is not None else None, form=form)
    alg = model.algebra
    if model.has_gamma and Gamma0 is None:
        raise ValueError("Gamma0 is required: the potential (or gyroscopic term) depends on Gamma; "
                         "pass a unit vector of shape (..., n)")
    x0 = _omega_coords(alg, Omega0)
    D = model.subspace
    inside = D.contains(x0, 1e-9)
    if not np.all(inside):
        dist = np.max(np.linalg.norm(x0 - D.project(x0), axis=-1))
        raise ValueError(f"Omega0 is not in the constraint subspace D (distance {dist:.3g}); "
                         "project it first, e.g. D.project(omega) with D = system.constraints")
    m = model.n
    skew = alg.name.startswith("so(")
    shapes = [x0.shape[:-1]]
    G0 = None
    if model.has_gamma:
        G0 = as_float_array(Gamma0, "Gamma0", ndim_min=1, tail=(m,))
        norms = np.linalg.norm(G0, axis=-1)
        dev = float(np.max(np.abs(norms - 1.0))) if norms.size else 0.0
        if dev > 1e-8:
            raise ValueError(f"Gamma0 must be a unit vector (|Gamma0| = 1 to 1e-8); the largest deviation "
                             f"| |Gamma0| - 1 | is {dev:.3g}: pass Gamma0 / |Gamma0|")
        G0 = G0 / norms[..., None]
        shapes.append(G0.shape[:-1])
    g_init = None
    if reconstruct:
        if m is None:
            raise ValueError(f"reconstruct=True needs a matrix representation of {alg.name}")
        if g0 is None:
            g_init = np.eye(m)
        else:
            g_init = as_float_array(g0, "g0", ndim_min=2, tail=(m, m))
            if skew:
                _check_rotation(g_init)
        shapes.append(g_init.shape[:-2])
    elif g0 is not None:
        raise ValueError("g0 was given but reconstruct=False; pass reconstruct=True to integrate g")
    try:
        batch_shape = np.broadcast_shapes(*shapes)
    except ValueError as exc:
        raise ValueError(f"the batch axes of Omega0, Gamma0 and g0 do not broadcast: {shapes}") from exc
    B = int(np.prod(batch_shape))
    if B == 0:
        raise ValueError(f"the batch of initial data is empty (batch shape {batch_shape}); pass at least one "
                         "Omega0")
    xi = model.xi_from_coords(np.broadcast_to(x0, batch_shape + x0.shape[-1:]).reshape(B, -1))
    xi = np.ascontiguousarray(xi, dtype=float)
    if reconstruct:
        mode = "g"
        G = np.broadcast_to(g_init, batch_shape + (m, m)).reshape(B, m, m).copy()
        gamma = None
        if model.has_gamma:
            Gam = np.broadcast_to(G0, batch_shape + (m,)).reshape(B, m)
            gamma = np.einsum("bij,bj->bi", G, Gam)  # gamma = g0 Gamma0, fixed in space
    elif model.has_gamma:
        mode = "gamma"
        G = np.broadcast_to(G0, batch_shape + (m,)).reshape(B, m).copy()
        gamma = None
    else:
        mode, G, gamma = "none", None, None

    tab = get_tableau(meth.tableau)
    ch = make_chart(chart, m, skew=skew, order=tab.order) if mode != "none" else None
    if backend == "numpy":
        stepper, used = RKMKStepper(model, tab, ch, mode, B), "numpy"
    else:  # the compiled module (and numba) is imported only here
        from .compiled import make_stepper

        stepper, used = make_stepper(backend, model, tab, ch, mode, B, rtol=rtol if meth.adaptive else None,
                                     atol=atol if meth.adaptive else None)
    runner = _Run(stepper, model, mode, xi, G, gamma, t0, direction, skew)
    start = time.perf_counter()
    bar = _progress_bar(progress, abs(t1 - t0))
    try:
        # Overflow/invalid values inside a diverging step are expected and detected by the loop
        # (non-finite state or error -> rejection or a failed status naming the time).
        with np.errstate(all="ignore"):
            _drive(runner, meth.adaptive, t1, t_eval, rtol, atol, first_step, tab, h, max_steps, bar)
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - start
    sol = runner.solution(model, batch_shape, method, chart, wall, B)
    sol.stats["backend"] = used
    return sol


class _DivergedStep(Exception):
    """Raised by :func:`_step_or_diverged` when a step's arithmetic broke down (the state is not finite)."""


_ARITHMETIC_ERRORS = (_DivergedStep, ArithmeticError, np.linalg.LinAlgError)


def _step_or_diverged(step, *args, **kwargs):
    """``step(*args)``, turning a closed form's domain error on a non-finite input into a divergence.

    ``math.sin(inf)`` raises ``ValueError('math domain error')``; any other ValueError is a real
    error (a user callable's, say) and propagates.
    """
    try:
        return step(*args, **kwargs)
    except ValueError as exc:
        if "math domain error" in str(exc):
            raise _DivergedStep(str(exc)) from exc
        raise


def _drive(runner, adaptive, t1, t_eval, rtol, atol, first_step, tab, h, max_steps, bar) -> None:
    if adaptive:
        runner.adaptive(t1, t_eval, rtol, atol, first_step, tab, max_steps, bar)
    else:
        runner.fixed(t1, t_eval, h, max_steps, bar)


# ---------------------------------------------------------------------------------------------------------
class _Run:
    """The time loop: step, control, record, stop on failure."""

    def __init__(self, stepper: RKMKStepper, model, mode, xi, G, gamma, t0, direction, skew):
        self.stepper, self.model, self.mode, self.skew = stepper, model, mode, skew
        if hasattr(stepper, "theta_out"):
            stepper.theta_out = False  # the loop never reads the increment: skip its assembly
        m = int(model.n) if mode != "none" else 0
        # components of the error norm: xi and the m×m increment Theta (whatever layout the stepper uses)
        self.ncomp = int(model.k) + (m * m if mode != "none" else 0)
        # Newton–Schulz costs O(n^3): every max(_RENORM, n) steps keeps it O(n^2) per step (the drift
        # between two re-projections stays ~n·1e-16, far below the truncation error).
        self.renorm = max(_RENORM, m)
        self.xi, self.G, self.gamma = xi, G, gamma
        self.t, self.direction = t0, direction
        self.ts, self.xis, self.Gs = [], [], []
        self.steps = self.rejected = 0
        self.status, self.message = 0, "The solver successfully reached the end of the integration interval."

    def record(self) -> None:
        self.ts.append(self.t)
        self.xis.append(self.xi)
        if self.G is not None:
            self.Gs.append(self.G)

    def _finite(self, xi1, G1) -> bool:
        # one reduction per array: a sum is finite iff every term is (an overflow of the sum itself
        # needs entries ~1e308 / size, a failed run anyway)
        return math.isfinite(xi1.sum()) and (G1 is None or math.isfinite(G1.sum()))

    def advance(self, xi1, G1, t_new: float) -> None:
        """Accept the step: move the state (re-projecting the group part every max(_RENORM, n) steps)."""
        self.stepper.accept()
        self.steps += 1
        if G1 is not None and self.steps % self.renorm == 0:
            if self.mode == "g" and self.skew:
                G1 = groups.orthonormalize(G1)
            elif self.mode == "gamma":
                G1 = G1 / np.linalg.norm(G1, axis=-1, keepdims=True)
        self.xi, self.G, self.t = xi1, G1, float(t_new)

    def _fail(self, msg: str) -> None:
        self.status, self.message = -1, msg

    # ------------------------------------------------------------------ fixed step
    def fixed(self, t1, t_eval, h, max_steps, bar) -> None:
        t0 = self.t
        if t_eval is None:
            self.record()
            n = max(1, math.ceil(abs(t1 - t0) / h - 1e-9))
            grid = t0 + self.direction * h * np.arange(n + 1, dtype=float)
            grid[-1] = t1
            stops, save_all = grid[1:], True
        else:
            if t_eval[0] == t0:
                self.record()
                t_eval = t_eval[1:]
            stops, save_all = [], False
            prev = t0
            for te in t_eval:
                n = max(1, math.ceil(abs(te - prev) / h - 1e-9))
                stops.extend(prev + (te - prev) * np.arange(1, n + 1) / n)
                stops[-1] = te
                prev = te
            targets = set(t_eval.tolist())
        if len(stops) > max_steps:
            raise ValueError(f"the grid needs {len(stops)} steps, more than max_steps = {max_steps}; "
                             "raise max_steps or the step h")
        step = self.stepper.step
        for t_next in stops:
            hh = t_next - self.t
            try:
                xi1, G1, _, _ = _step_or_diverged(step, hh, self.xi, self.G, self.gamma)
            except _ARITHMETIC_ERRORS:  # e.g. math.sin(inf) in a closed form: a diverged step
                xi1 = G1 = np.full(1, np.nan)
            if not self._finite(xi1, G1):
                self._fail(f"non-finite state at t = {t_next:.17g} (step from t = {self.t:.17g}); "
                           "the step size is probably too large for this motion")
                return
            self.advance(xi1, G1, t_next)
            if bar is not None:
                bar.update(abs(hh))
            if save_all or self.t in targets:
                self.record()

    # ------------------------------------------------------------------ adaptive
    def adaptive(self, t1, t_eval, rtol, atol, first_step, tab, max_steps, bar) -> None:
        t0 = self.t
        if t_eval is None:
            self.record()
            targets = [t1]
            save_all = True
        else:
            if t_eval[0] == t0:
                self.record()
                t_eval = t_eval[1:]
            targets = list(t_eval)
            if not targets or targets[-1] != t1:
                targets.append(t1)
            save_all = False
            wanted = set(t_eval.tolist())
        q = tab.error_order
        expo = -1.0 / (q + 1)
        h_abs = first_step if first_step is not None else self._initial_step(rtol, atol, tab.order)
        stepper = self.stepper
        k_target = 0
        while k_target < len(targets):
            target = targets[k_target]
            if self.steps + self.rejected >= max_steps:
                self._fail(f"max_steps = {max_steps} reached at t = {self.t:.17g}")
                return
            min_step = 10 * abs(math.nextafter(self.t, self.direction * math.inf) - self.t)
            if h_abs < min_step:
                self._fail(f"step size underflow at t = {self.t:.17g} (|h| = {h_abs:.3g}): the "
                           "solution is probably singular there or the tolerances are too tight")
                return
            hit = h_abs >= abs(target - self.t)
            h = (target - self.t) if hit else self.direction * h_abs
            rejected_before = False
            while True:
                try:
                    xi1, G1, _, errs = _step_or_diverged(stepper.step, h, self.xi, self.G, self.gamma,
                                                         want_error=True)
                    err = self._error_norm(errs, xi1, rtol, atol, abs(h))
                except _ARITHMETIC_ERRORS:  # a diverged trial step: reject it like an infinite error
                    stepper.reset()
                    err = np.inf
                if not np.isfinite(err):
                    err = np.inf
                if err <= 1.0:
                    factor = _MAX_FACTOR if err == 0 else min(_MAX_FACTOR, _SAFETY * err ** expo)
                    if rejected_before:
                        factor = min(1.0, factor)
                    break
                self.rejected += 1
                rejected_before = True
                h_abs = abs(h) * max(_MIN_FACTOR, _SAFETY * err ** expo)
                min_step = 10 * abs(math.nextafter(self.t, self.direction * math.inf) - self.t)
                if h_abs < min_step or self.steps + self.rejected >= max_steps:
                    what = "step size underflow" if h_abs < min_step else f"max_steps = {max_steps} reached"
                    self._fail(f"{what} at t = {self.t:.17g} (|h| = {h_abs:.3g}): the solution is "
                               "probably singular there (or non-finite) or the tolerances are too tight")
                    return
                hit = False
                h = self.direction * h_abs
            if not self._finite(xi1, G1):
                self._fail(f"non-finite state at t = {self.t + h:.17g}")
                return
            new_t = target if hit else self.t + h
            if bar is not None:
                bar.update(abs(new_t - self.t))
            self.advance(xi1, G1, new_t)
            h_abs = abs(h) * factor if not hit else max(h_abs, abs(h) * factor)
            if hit:
                k_target += 1
            if save_all or (hit and self.t in wanted):
                self.record()

    def _error_norm(self, errs, xi1, rtol, atol, h_abs) -> float:
        """Scaled RMS error of each trajectory, worst over the batch (DOP853's combination if two)."""
        fast = getattr(errs, "norm", None)
        if fast is not None:  # the compiled stepper computed this very norm inside its step
            return fast(rtol, atol)
        sc_xi = atol + rtol * np.maximum(np.abs(self.xi), np.abs(xi1))
        sc_g = atol + rtol  # group components are O(1)
        sq = []
        for ex, eg in errs:
            s = np.sum((ex / sc_xi) ** 2, axis=-1)
            if eg is not None:  # any layout whose squares sum to |err Theta|_F^2 (see RKMKStepper.step)
                s = s + np.sum(eg.reshape(eg.shape[0], -1) ** 2, axis=-1) / sc_g ** 2
            sq.append(s)
        ncomp = self.ncomp
        if len(sq) == 1:
            return float(np.sqrt(np.max(sq[0]) / ncomp))
        e5, e3 = sq
        if e5.size == 1:  # one trajectory: the combination on floats
            a, b = float(e5[0]), float(e3[0])
            d = a + 0.01 * b
            if not math.isfinite(d):  # a NaN/inf estimate must reject the step, never pass as 0
                return math.inf
            return a / math.sqrt(d * ncomp) if d > 0 else 0.0
        denom = e5 + 0.01 * e3
        per = np.where(denom > 0, e5 / np.sqrt(np.where(denom > 0, denom, 1.0) * ncomp),
                       np.where(denom == 0, 0.0, np.inf))
        return float(np.max(per))

    def _initial_step(self, rtol, atol, order) -> float:
        """Hairer's starting step from two field evaluations (as scipy's select_initial_step)."""
        st = self.stepper
        Gam = st.gamma_of(self.G, self.gamma)
        L0 = self.model.xi_dot(self.xi, Gam)
        st.nfev += 1
        if self.mode != "none":
            Om = self.model.omega_matrix(self.xi)
            f0 = np.concatenate([L0.reshape(-1), Om.reshape(-1)])
            y0 = np.concatenate([self.xi.reshape(-1), np.ones(Om.size)])
        else:
            f0, y0 = L0.reshape(-1), self.xi.reshape(-1)
        scale = atol + np.abs(y0) * rtol
        d0 = np.sqrt(np.mean((y0 / scale) ** 2))
        d1 = np.sqrt(np.mean((f0 / scale) ** 2))
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        # An explicit Euler probe (no stage of the method): xi + h f, Gamma - h Omega Gamma (dGamma/dt = -Omega
        # Gamma); only the change of the field matters here, not the structure of the probe point.
        hp = self.direction * h0
        xi1 = self.xi + hp * L0
        Gam1 = None if Gam is None else Gam - hp * np.einsum("bij,bj->bi", Om, Gam)
        L1 = self.model.xi_dot(xi1, Gam1)
        st.nfev += 1
        if self.mode != "none":
            f1 = np.concatenate([L1.reshape(-1), self.model.omega_matrix(xi1).reshape(-1)])
        else:
            f1 = L1.reshape(-1)
        d2 = np.sqrt(np.mean(((f1 - f0) / scale) ** 2)) / h0
        if d1 <= 1e-15 and d2 <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:
            h1 = (0.01 / max(d1, d2)) ** (1.0 / (order + 1))
        return float(min(100 * h0, h1))

    # ------------------------------------------------------------------ output
    def solution(self, model, batch_shape, method, chart, wall, B) -> Solution:
        N = len(self.ts)
        t = np.asarray(self.ts, dtype=float)
        xi = np.stack(self.xis) if N else np.zeros((0, B, model.k))
        omega = model.omega_coords(xi)
        Gamma = g = None
        if self.mode == "g":
            g = np.stack(self.Gs)
            if model.has_gamma:
                Gamma = np.einsum("tbji,bj->tbi", g, self.gamma)
            g = g.reshape((N,) + batch_shape + g.shape[-2:])
        elif self.mode == "gamma":
            Gamma = np.stack(self.Gs)
        if Gamma is not None:
            Gamma = Gamma.reshape((N,) + batch_shape + Gamma.shape[-1:])
        stats = {"nfev": self.stepper.nfev, "steps": self.steps, "rejected": self.rejected,
                 "method": method, "chart": chart if self.mode != "none" else None, "form": model.form,
                 "state_dim": model.state_dim + (model.n ** 2 if self.mode == "g" else 0),
                 "batch": B, "wall_time": wall}
        return Solution(t=t, xi=xi.reshape((N,) + batch_shape + (model.k,)),
                        omega=omega.reshape((N,) + batch_shape + omega.shape[-1:]), Gamma=Gamma, g=g,
                        stats=stats, status=self.status, message=self.message, n=model.n,
                        algebra_name=model.algebra.name)


# ---------------------------------------------------------------------------------------------------------
def _check_t_span(t_span) -> tuple[float, float]:
    try:
        t0, t1 = (float(v) for v in t_span)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"t_span must be a pair of numbers (t0, t1), got {t_span!r}") from exc
    if not (np.isfinite(t0) and np.isfinite(t1)):
        raise ValueError(f"t_span must be finite, got {t_span!r}")
    if t0 == t1:
        raise ValueError(f"t_span must have t0 != t1, got {t_span!r}")
    return t0, t1


def _check_t_eval(t_eval, t0: float, t1: float):
    if t_eval is None:
        return None
    te = as_float_array(t_eval, "t_eval")
    if te.ndim != 1 or te.size == 0:
        raise ValueError(f"t_eval must be a non-empty 1-D array, got shape {te.shape}")
    lo, hi = min(t0, t1), max(t0, t1)
    if te.min() < lo or te.max() > hi:
        raise ValueError(f"t_eval must lie within t_span = ({t0}, {t1})")
    d = np.diff(te) * (1.0 if t1 > t0 else -1.0)
    if np.any(d <= 0):
        raise ValueError("t_eval must be strictly increasing (decreasing for backward integration)")
    return te


def _omega_coords(alg, Omega0) -> np.ndarray:
    O = as_float_array(Omega0, "Omega0", ndim_min=1)
    m = getattr(alg, "matrix_size", None)
    d = alg.dim
    if alg.name.startswith("so(") and O.ndim >= 2 and O.shape[-2:] == (m, m):
        skew = np.allclose(O, -np.swapaxes(O, -1, -2), rtol=0, atol=1e-12 * max(1.0, np.abs(O).max()))
        if skew:
            return alg.vee(O)
        if d != m:  # so(3) is the only case where (3, 3) could also be three coordinate vectors
            raise ValueError("Omega0 given as a matrix must be skew-symmetric")
    if O.shape[-1] != d:
        raise ValueError(f"Omega0 must have shape (..., {d}) (coordinates)"
                         + (f" or (..., {m}, {m}) (a skew matrix)" if alg.name.startswith("so(") else "")
                         + f", got {O.shape}")
    return O


def _check_rotation(g: np.ndarray) -> None:
    m = g.shape[-1]
    err = np.max(np.abs(np.swapaxes(g, -1, -2) @ g - np.eye(m)))
    if err > 1e-8 or np.any(np.linalg.det(g) < 0):
        raise ValueError(f"g0 must be in SO(n): g^T g = I (max defect {err:.3g}) and det g = +1")


def _progress_bar(on: bool, total: float):
    if not on:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError as exc:
        raise ValueError("progress=True needs tqdm: pip install 'liesuslov[progress]'") from exc
    return tqdm(total=total, unit="t", leave=False)
