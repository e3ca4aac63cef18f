"""The problem a solver is handed, and what a solver hands back — the contract between the front door and the solvers.

:func:`liesuslov.integrate` validates the user's call and builds a :class:`Problem`: the model, the group
part and its chart, the flattened batch of initial states, the method's :class:`~.plan.StagePlan`, the
tolerances, the output times and the events. A solver (:func:`.solve_numpy.solve` or the compiled
:func:`.kernel.solve`) returns a :class:`RawResult`; :mod:`.integrate` turns it into a
:class:`~.solution.Solution`. Solvers know nothing of Gamma, g or the batch shape beyond what is here.

The state of one trajectory is ``(xi, G)``:

* ``xi`` (k,): coordinates of Omega in the constraint subspace D (a vector space, advanced by classical RK);
* ``G`` (q,): the group part, flattened — the attitude g (q = m*m, row-major) when ``mode == "g"``, the
  vertical Gamma (q = n) when ``mode == "gamma"``, nothing (q = 0) when ``mode == "none"``.

With ``mode == "g"`` and a vertical, ``gamma`` (n,) is the vertical in space (constant, ``gamma = g0 Gamma0``)
and the body vertical is read off the attitude, ``Gamma = g^T gamma``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validation import read_only
from .plan import StagePlan

__all__ = ["Problem", "RawResult", "STATUS_FAILED", "STATUS_REACHED", "STATUS_TERMINAL", "FAILURES", "SUCCESS_MESSAGE",
           "run_message", "RENORM_EVERY"]

STATUS_REACHED, STATUS_TERMINAL, STATUS_FAILED = 0, 1, -1
#: The message of a run in which every trajectory reached the end of t_span (scipy's words).
SUCCESS_MESSAGE = "The solver successfully reached the end of the integration interval."

#: Why a trajectory failed (``RawResult.failure`` codes; 0 = did not fail).
FAILURES = {
    1: "non-finite state",
    2: "step size underflow (the solution is probably singular there, or the tolerances are below rounding, or t "
       "is so large that few floats lie in t_span: move t_span nearer 0)",
    3: "max_steps reached",
    4: "step beyond the chart's domain (|h Omega| too large: a turn of pi for the exponential, a diverging run for "
       "the Cayley map; lower h)",
    5: "the fixed step h is below ten ulps of t within t_span (t0 + i h cannot be represented: raise h, or move "
       "t_span nearer 0)",
    6: "non-finite field beyond the state (every step tried from there, down to ten ulps of t, met a non-finite "
       "value: a singularity, or the end of the field's domain)",
}


def run_message(status: np.ndarray, t_stop: np.ndarray, failure: np.ndarray | None) -> str:
    """The message of a run from its per-trajectory ``status``, ``t_stop`` and ``failure`` codes (flat, (B,)):
    the first failure with its reason and time, else how many a terminal event stopped, else success. One
    source for :func:`~.integrate.integrate` and the ensembles (``failure`` None: the reason is not known)."""
    if not np.count_nonzero(status):  # (ndarray.any: ~3 µs on one entry)
        return SUCCESS_MESSAGE
    failed = np.flatnonzero(status < 0)
    if failed.size:
        b = int(failed[0])
        what = "failure" if failure is None else FAILURES.get(int(failure[b]), "failure")
        head = "" if status.size == 1 else (f"{failed.size} of {status.size} trajectories failed; "
                                           f"the first (index {b}): ")
        what, _, hint = what.partition(" (")
        return f"{head}{what} at t = {t_stop[b]:.17g}" + (f" ({hint}" if hint else "")
    stopped = int(np.sum(status == STATUS_TERMINAL))
    if status.size == 1:
        return f"A terminal event stopped the trajectory at t = {t_stop[0]:.17g}."
    if stopped == status.size:
        return f"A terminal event stopped all {stopped} trajectories."
    return f"A terminal event stopped {stopped} of {status.size} trajectories; the others reached the end."


#: Products ``g <- g phi(Theta)`` add ~1e-16 per step to |g^T g - I|; with ``reproject`` a Newton–Schulz step
#: (g, or Gamma / |Gamma|) every max(RENORM_EVERY, n) accepted steps keeps it at ~1e-15 over any run length.
RENORM_EVERY = 64


@dataclass(eq=False)
class Problem:
    """Everything a solver needs; arrays are C-contiguous float64 (int64 where said).

    Attributes
    ----------
    model : ModelProtocol
        The reduced model (``xi_dot``, ``omega_matrix``, ...).
    mode : {"none", "gamma", "g"}
    chart : {"exp", "cayley"} or None
        None when ``mode == "none"``.
    kind : str or None
        The group representation the kernel uses: "so3" (closed forms), "so4", "dense", "lowrank"
        (Fedorov–Kozlov, rank-2 Omega), or None (mode "none").
    skew : bool
        The algebra is so(n) (skew matrices); False for se(2), se(3) and other matrix algebras.
    plan : StagePlan
    k, m, q : int
        Dimension of xi, matrix size of the group part (0 for mode "none"), length of G.
    B : int
        Number of trajectories (the flattened batch).
    xi0 : (B, k)
    G0 : (B, q)
    gamma : (B, n) or (B, 0)
        The vertical in space (mode "g" with a vertical), else empty.
    t0, t1 : float
        Common to the batch; ``t1 < t0`` integrates backward.
    adaptive : bool
    h : float
        Fixed step (fixed-step methods) or the first step (adaptive; 0 = Hairer's estimate).
    rtol, atol : float
    max_steps : int
        Per trajectory (accepted + rejected steps).
    t_eval : (M,) or None
        Output times (sorted in the direction of integration); None: the solver records every accepted
        step (``B == 1`` only) — the front door passes ``t_eval = (t0, t1)`` for a batch without t_eval
        (any initial data with batch axes, also of one).
    events : list of callables
        The user's event functions (numpy solver).
    event_linear : list over events of ``(coef (B, k + q), offset (B,))`` or None
        The linear form of each :class:`~.events.LinearEvent` (None for any other callable).
    event_terminal : (E,) int64
        The crossing at which each event stops its trajectory (0 never, 1 the first, N the N-th).
    event_direction : (E,) int64 (-1, 0, +1)
    reproject : bool
        Re-orthonormalise g (or renormalise Gamma) every ``max(RENORM_EVERY, m)`` accepted steps.
    """

    model: object
    mode: str
    chart: str | None
    kind: str | None
    skew: bool
    plan: StagePlan
    k: int
    m: int
    q: int
    B: int
    xi0: np.ndarray
    G0: np.ndarray
    gamma: np.ndarray
    t0: float
    t1: float
    adaptive: bool
    h: float
    rtol: float
    atol: float
    max_steps: int
    t_eval: np.ndarray | None
    events: list = field(default_factory=list)
    event_linear: list = field(default_factory=list)
    event_terminal: np.ndarray | None = None
    event_direction: np.ndarray | None = None
    reproject: bool = True
    batch_shape: tuple = ()

    @property
    def direction(self) -> float:
        return 1.0 if self.t1 > self.t0 else -1.0

    # --------------------------------------------------------------- the group part (what the loops need of it)
    def reprojected(self, G: np.ndarray | None) -> np.ndarray | None:
        """One Newton–Schulz step toward SO(n) for an attitude, ``Gamma / |Gamma|`` for a vertical."""
        if G is None:
            return None
        if self.mode == "g":
            from ..groups import orthonormalize

            return orthonormalize(G) if self.skew else G
        return G / np.linalg.norm(G, axis=-1, keepdims=True)

    def user_state(self, xi: np.ndarray, G: np.ndarray | None):
        """``(Omega, Gamma, g)`` of the whole batch as an event callable sees them, from ``xi`` (B, k) and ``G``
        (B, q): Omega (B, n, n) on so(n) (coordinates (B, d) elsewhere), Gamma (B, n) or None, g (B, m, m) or
        None."""
        Omega = self.model.omega_matrix(xi) if self.skew else self.model.omega_coords(xi)
        Gamma = g = None
        if self.mode == "g":
            g = np.reshape(G, (-1, self.m, self.m))
            if self.model.has_gamma:
                Gamma = np.matmul(self.gamma[:, None, :], g)[:, 0, :]  # Gamma = g^T gamma
        elif self.mode == "gamma":
            Gamma = np.reshape(G, (xi.shape[0], -1))
        # views of the solver's state, given to user callables: read-only, so an event cannot change it
        return read_only(Omega), None if Gamma is None else read_only(Gamma), None if g is None else read_only(g)

    def call_event(self, e: int, t: np.ndarray, xi: np.ndarray, G: np.ndarray | None) -> np.ndarray:
        """The values (B,) of the user's event ``e`` at times ``t`` (B,) and states ``xi`` (B, k), ``G`` (B, q).

        It is called once, with the batch axes leading (as documented): ``t`` a float for one trajectory
        (batch shape ``()``), else an array of the batch shape; Omega, Gamma and g of shapes
        ``batch_shape + (...)`` (:meth:`user_state`).

        Raises
        ------
        ValueError
            If the returned values do not broadcast to the batch shape, or the event raised (a TypeError it
            raised stays one), with what it was called with.
        TypeError
            If they are not real numbers.
        """
        shape = self.batch_shape

        def lead(a):
            return None if a is None else a.reshape(shape + a.shape[1:])

        Omega, Gamma, g = self.user_state(xi, G)
        tt = float(t[0]) if shape == () else t.reshape(shape)
        try:
            value = self.events[e](tt, lead(Omega), lead(Gamma), lead(g))
        except Exception as exc:  # noqa: BLE001 - re-raised naming the event and what it was called with
            kind = TypeError if isinstance(exc, TypeError) else ValueError
            raise kind(f"events[{e}] raised {type(exc).__name__}: {exc} (called on a batch of shape {shape}: t "
                       f"{'a float' if shape == () else f'of shape {shape}'}, Omega of shape {np.shape(lead(Omega))}"
                       f"; in an ensemble, on one chunk of the flattened batch)") from exc
        raw = np.asarray(value)
        if value is None or raw.dtype.kind not in "iuf":  # None would be NaN, a complex value its real part
            # (booleans: a step function, whose "root" is wherever the bisection lands in the step)
            raise TypeError(f"events[{e}] must return real numbers, one per trajectory (a function whose sign "
                            f"changes at the surface, not a boolean); got {type(value).__name__}"
                            + (f" of {raw.dtype}" if value is not None else ""))
        value = raw.astype(float, copy=False)
        # exactly one value per trajectory: a () or (1,) broadcast over a batch would give every trajectory the
        # first one's value (its crossings at the first one's times)
        if value.shape != shape and not (self.B == 1 and value.size == 1):
            raise ValueError(f"events[{e}] returned values of shape {value.shape}; an event returns one value per "
                             f"trajectory: shape {shape} (the batch shape of the initial data)")
        return value.reshape(self.B)

    @property
    def n_events(self) -> int:
        return len(self.events)

    @property
    def event_coef(self) -> np.ndarray | None:
        """(B, E, k + q): every event linear in the state, ``value = coef[b, e] . (xi, G) - offset[b, e]`` (what
        the compiled kernel evaluates); None without events or when one is not a :class:`~.events.LinearEvent`."""
        if not self.event_linear or any(x is None for x in self.event_linear):
            return None
        return np.ascontiguousarray(np.stack([c for c, _ in self.event_linear], axis=1))

    @property
    def event_offset(self) -> np.ndarray | None:
        """(B, E) offsets of :attr:`event_coef` (None when it is None)."""
        if self.event_coef is None:
            return None
        return np.ascontiguousarray(np.stack([o for _, o in self.event_linear], axis=1))


@dataclass(eq=False)
class RawResult:
    """What a solver returns (flattened batch of B trajectories, M output times).

    Attributes
    ----------
    t : (M,)
        The output times: ``problem.t_eval``, or every accepted step of the one trajectory.
    xi : (M, B, k)
    G : (M, B, q)
        NaN at output times after a trajectory stopped (terminal event or failure).
    status : (B,) int64
        0 reached t1, 1 stopped by a terminal event, -1 failed.
    t_stop : (B,)
        Where each trajectory stopped (t1, the terminal event's time, or the failure time).
    failure : (B,) int64
        A key of :data:`FAILURES` (0 = none).
    nfev, steps, rejected : (B,) int64
        Field evaluations (stage 0 reused per the plan's new-point rule), accepted and rejected steps.
    event_t : list over events of (K,) arrays
        Crossing times, sorted by (trajectory index, t).
    event_index : list of (K,) int64
        The trajectory (flat batch index) of each crossing.
    event_xi : list of (K, k)
    event_G : list of (K, q)
    backend : str
        "numpy" or "numba".
    """

    t: np.ndarray
    xi: np.ndarray
    G: np.ndarray
    status: np.ndarray
    t_stop: np.ndarray
    failure: np.ndarray
    nfev: np.ndarray
    steps: np.ndarray
    rejected: np.ndarray
    event_t: list = field(default_factory=list)
    event_index: list = field(default_factory=list)
    event_xi: list = field(default_factory=list)
    event_G: list = field(default_factory=list)
    backend: str = "numpy"
