r"""The largest Lyapunov exponent of the reduced flow, by Benettin's renormalisation of a nearby trajectory.

The reduced state is ``s = (xi, Gamma)``: ``xi`` the coordinates of Omega in the orthonormal basis of D
(so the metric is the pairing restricted to D) and ``Gamma`` on the sphere (omitted when the scene has
none). A companion trajectory starts at ``s0 + delta e`` with ``e`` a random unit tangent vector (tangent
to D and to the sphere at ``Gamma0``; drawn per trajectory from the seed and the trajectory's own ``s0``,
so a trajectory's estimate does not depend on its batch mates); every ``tau`` time units the separation
``d_k = |s' - s|`` is measured and the companion is put back at distance ``delta`` along the separation
(``Gamma'`` renormalised onto the sphere). Then

.. math::

    \lambda(t_K) = \frac{1}{t_K - t_0}\sum_{k=1}^{K} \log\frac{d_k}{\delta}.

For an integrable motion on a torus the separation grows linearly (shear), so ``lambda(t) ~ log(t)/t``
tends to 0; on a chaotic orbit it converges to a positive number. The convergence estimate reported is
the change of the running estimate over the second half of the run.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._progress import progress_bar
from .._rows import rows_at
from ..integrators import integrate
from ..integrators.problem import FAILURES
from . import _runner as R

__all__ = ["lyapunov_exponent", "LyapunovResult"]


@dataclass
class LyapunovResult:
    """The exponent with its history (``lyapunov_exponent(..., return_history=True)``).

    Attributes
    ----------
    exponent : ndarray, shape (...)
        ``lambda(t1)``.
    times : ndarray, shape (K,)
        Renormalisation times ``t_k`` (``t_K = t1``).
    history : ndarray, shape (K, ...)
        The running estimate ``lambda(t_k)``.
    spread : ndarray, shape (...)
        ``max - min`` of the running estimate over the second half of the run: the convergence estimate (NaN
        with fewer than 3 renormalisation intervals). It bounds the last oscillations, not a slow drift (a
        measured case in ``docs/reconstruction.md``).
    log_t_over_t : float
        ``log(t1 - t0) / (t1 - t0)``: the size of the estimate an integrable (linearly shearing) motion
        leaves at this length.
    status : ndarray of int, shape (...)
        0, or -1 when an integration failed (the exponent is then NaN).
    t_stop : ndarray, shape (...)
        The time of each trajectory's failure (NaN where it did not fail).
    message : str
        What failed first, and when (empty when nothing did).
    """

    exponent: np.ndarray
    times: np.ndarray
    history: np.ndarray
    spread: np.ndarray
    log_t_over_t: float
    status: np.ndarray
    t_stop: np.ndarray = field(default_factory=lambda: np.full((), np.nan))
    message: str = ""


#: Most renormalisation intervals of one run: each is an integrate call on the batch (~0.5 ms for one
#: trajectory), so 1e6 of them are minutes; a longer run asks for a longer ``renormalize_every``.
MAX_INTERVALS = 1_000_000
#: Smallest delta, relative to the state's size: the companion's distance must be far above rounding.
DELTA_FLOOR = 1e-12
#: Smallest ``delta * T`` relative to the state's size: rounding's share ``eps |s| / (delta T)`` of the estimate
#: stays below ~2e-4.
NOISE_FLOOR = 1e-12


def _seed_key(seed) -> tuple[int, tuple[int, ...]]:
    """The user's ``seed`` as ``(entropy, spawn_key)`` of a :class:`numpy.random.SeedSequence`.

    None draws fresh entropy; a Generator gives one draw of its stream (one per call, whatever the batch).
    """
    if seed is None:
        ss = np.random.SeedSequence()
        return int(ss.entropy), ()
    if isinstance(seed, np.random.Generator):
        return int(seed.integers(0, 2 ** 63, dtype=np.int64)), ()
    if isinstance(seed, np.random.SeedSequence):
        # (entropy may be a sequence of ints: its first state word stands for it, a function of all of them)
        entropy = seed.entropy if isinstance(seed.entropy, (int, np.integer)) else \
            int(np.random.SeedSequence(seed.entropy).generate_state(2, np.uint64).view(np.uint64)[0])
        return int(entropy), tuple(int(v) for v in seed.spawn_key)
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"seed must be None, a non-negative integer, a numpy Generator or SeedSequence, got "
                        f"{type(seed).__name__} {seed!r}")
    if seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed}")
    return int(seed), ()


def _tangent(seed_key: tuple[int, tuple[int, ...]], s0: np.ndarray, k: int, Gamma: np.ndarray | None) -> np.ndarray:
    """Random unit tangent vectors ``(B, k [+ n])``: any direction in D, tangent to the sphere at Gamma.

    Each trajectory draws from its own stream, the seed's entropy with the bits of its own initial reduced
    state ``s0`` as spawn key: the same initial data and seed give the same vector alone or in any batch.
    """
    entropy, key = seed_key
    e = np.empty_like(s0)
    for b, row in enumerate(s0):
        words = np.ascontiguousarray(row + 0.0, dtype=np.float64).view(np.uint32)   # + 0.0: -0.0 -> 0.0
        rng = np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=key + tuple(int(w) for w in words)))
        eb = rng.standard_normal(row.size)
        if Gamma is not None:
            G = Gamma[b]
            eb[k:] = eb[k:] - np.sum(eb[k:] * G) * G
        e[b] = eb / np.linalg.norm(eb)
    return e


def lyapunov_exponent(system, Omega0, t_span, *, Gamma0=None, seed=None, renormalize_every: float | None = None,
                      delta: float = 1e-7, return_history: bool = False, **options: Any):
    r"""Largest Lyapunov exponent of the reduced flow ``(Omega, Gamma)`` over ``t_span`` (a batch).

    Parameters
    ----------
    system : SuslovSystem
    Omega0 : array_like, shape (..., n, n) or (..., d)
        Initial angular velocities in D.
    t_span : (t0, t1)
        ``t1 > t0``.
    Gamma0 : array_like, shape (..., n), optional
        Required when the potential needs it; given otherwise, Gamma is part of the state.
    seed : int, numpy Generator or SeedSequence, optional
        Seed of the random initial tangent vectors (a non-negative integer). Each trajectory draws its own
        vector from the seed and the bits of its own initial state ``(xi0, Gamma0)``, so a trajectory's
        exponent is the same alone or in any batch; None: fresh entropy (a different vector each call).
    renormalize_every : float, optional
        ``tau``, the time between renormalisations (default about 5; a given one is rounded to
        ``(t1 - t0) / round((t1 - t0) / tau)``, so that the intervals divide ``t_span`` evenly — 4 over
        ``t_span = (0, 10)`` is 5: with ``delta = 1e-7`` the separation stays in the linear regime for exponents
        up to ~2).
    delta : float
        Separation of the companion trajectory (in the Euclidean metric of ``(xi, Gamma)``).
    return_history : bool
        Return a :class:`LyapunovResult` (the running estimate and its convergence) instead of the array.
    **options
        ``integrate``'s options; ``method="rkmk853", rtol=1e-10, atol=1e-12`` where not given; ``progress=True``
        shows one bar over the renormalisation intervals (needs tqdm). Each interval
        is one ``integrate`` call on the batch of ``2B`` trajectories (reference and companion): ``max_steps``
        bounds each interval's steps, and a run has at most :data:`MAX_INTERVALS` intervals.

    Returns
    -------
    ndarray, shape (...)
        ``lambda`` in natural log per unit time (NaN where an integration failed, with a RuntimeWarning
        saying what failed and when); or a :class:`LyapunovResult` with ``return_history=True`` (its
        ``status``, ``t_stop`` and ``message`` say it).

    Raises
    ------
    ValueError
        Bad arguments, naming them; more than :data:`MAX_INTERVALS` renormalisation intervals.
    """
    t0, t1 = R.check_span(t_span)
    if not isinstance(return_history, (bool, np.bool_)):
        raise TypeError(f"return_history must be True or False, got {type(return_history).__name__}")
    delta = R.positive(delta, "delta")
    if delta >= 1e-2:
        raise ValueError(f"delta must be small (the companion's distance, e.g. 1e-7), got {delta:g}")
    opts = R.options_with_defaults(options)
    # one bar over the renormalisation intervals (integrate's own, per call, would be K bars of 2B trajectories)
    progress = opts.pop("progress", False)
    if not isinstance(progress, (bool, np.bool_)):
        raise TypeError(f"progress must be True or False, got {type(progress).__name__}")
    b = R.prepare(system, Omega0, Gamma0)
    span = t1 - t0
    # the rounding of the states, ~eps |s|, must stay far below delta, and its share of the estimate,
    # ~eps |s| / (delta T), far below any exponent of interest (below: 1.4 at delta = 1e-14, 1e290 at T = 1e-300)
    s0 = b.reduced(b.omega, b.Gamma)  # (B, k [+ n])
    sizes = np.linalg.norm(s0, axis=-1)
    largest = int(np.argmax(sizes)) if sizes.size else 0
    size = float(sizes[largest]) if sizes.size else 0.0
    # (one delta for the batch: the largest state decides; the message names it, for a batch of mixed scales)
    which = "" if b.size == 1 else f" of trajectory {largest} (flat index), the batch's largest"
    if delta < DELTA_FLOOR * max(size, 1.0):
        raise ValueError(f"delta = {delta:g} is within the rounding of the state{which} (|s| = {size:.3g}): pass "
                         f"delta >= {DELTA_FLOOR * max(size, 1.0):.3g} (the default 1e-7 is safe up to |s| = 1e5)"
                         + ("" if b.size == 1 else ", or estimate that trajectory on its own with a larger delta"))
    if span * delta < NOISE_FLOOR * max(size, 1.0):
        raise ValueError(f"t_span is too short (T = {span:g}) for an exponent with delta = {delta:g}: rounding alone "
                         f"would move it by ~{2.2e-16 * max(size, 1.0) / (delta * span):.3g} (|s| = {size:.3g}"
                         f"{which}); integrate over T >= {NOISE_FLOOR * max(size, 1.0) / delta:.3g}")
    if renormalize_every is None:
        K = max(1, int(round(span / 5.0)))
    else:
        tau = R.positive(renormalize_every, "renormalize_every")
        if tau > span:
            raise ValueError(f"renormalize_every = {tau:g} is longer than t_span ({span:g})")
        K = max(1, int(round(span / tau)))
    if K > MAX_INTERVALS:
        raise ValueError(f"t_span / renormalize_every = {K:.3g} renormalisation intervals, each an integrate call "
                         f"(~0.5 ms): more than {MAX_INTERVALS:.0e}; pass renormalize_every >= "
                         f"{span / MAX_INTERVALS:.3g} (the exponent does not depend on it while the separation "
                         "stays linear) or a shorter t_span")
    h = opts.get("h")
    if R.adaptive(opts["method"]) is False and isinstance(h, (int, float, np.integer, np.floating)) \
            and not isinstance(h, (bool, np.bool_)) and abs(h) > span / K:
        # each interval is its own integrate call: a longer fixed step would silently become the interval
        raise ValueError(f"h = {h:g} is longer than the renormalisation interval ({span / K:g}), which would cut "
                         f"every step to it; pass h <= {span / K:g}, or renormalize_every >= {abs(h):g}")
    seed_key = _seed_key(seed)
    B = b.size
    Dbasis = system.constraints.basis
    k = Dbasis.shape[0]
    xi0 = s0[:, :k]
    xi = xi0
    G = b.Gamma
    e = _tangent(seed_key, s0, k, G)
    xi_p = xi + delta * e[:, :k]
    G_p = None
    if G is not None:
        G_p = G + delta * e[:, k:]
        G_p = G_p / np.linalg.norm(G_p, axis=-1, keepdims=True)
    logsum = np.zeros(B)
    # the running estimate at every renormalisation only when asked for (K can be ~t / 5: 2e8 rows for t = 1e9)
    hist = np.empty((K if return_history else 1, B))
    status = np.zeros(B, dtype=int)
    t_stop = np.full(B, np.nan)
    message = ""
    t_prev = 0.0
    bar = progress_bar(K, "interval", "lyapunov_exponent") if progress else None
    for j in range(K):
        t_next = span * (j + 1) / K  # the interval's end, from t0 (an array of K would be 1.6 GB at t = 1e9)
        om = rows_at(np.concatenate([xi, xi_p]), Dbasis)
        kw = dict(opts)
        if G is not None:
            kw["Gamma0"] = np.concatenate([G, G_p])
        # the system is autonomous: times from t0, so that a large t0 costs no resolution in t
        sol = integrate(system, om, (t_prev, t_next), **kw)
        st = np.broadcast_to(np.asarray(sol.status), (2 * B,))
        bad = (st[:B] < 0) | (st[B:] < 0)
        om_end = sol.omega[-1]
        xi_all = rows_at(om_end, Dbasis.T)
        xi, xi_q = xi_all[:B], xi_all[B:]
        d = xi_q - xi
        if G is not None:
            G_all = sol.Gamma[-1]
            G, G_q = G_all[:B], G_all[B:]
            d = np.concatenate([d, G_q - G], axis=-1)
        dist = np.linalg.norm(d, axis=-1)
        bad |= ~np.isfinite(dist) | (dist == 0.0)
        new = bad & (status == 0)
        if np.any(new):
            # the integration's own stop time where it failed, else the interval's end (a vanished separation)
            stops = np.asarray(sol.stats.get("t_stop", np.full(2 * B, np.nan)), dtype=float).reshape(-1)
            stops = stops if stops.size == 2 * B else np.full(2 * B, np.nan)
            when = np.fmin(stops[:B], stops[B:])
            t_stop[new] = t0 + np.where(np.isfinite(when[new]), when[new], t_next)
            if not message:
                i = int(np.flatnonzero(new)[0])
                codes = np.asarray(sol.stats.get("failure", np.zeros(2 * B)), dtype=int).reshape(-1)
                code = next((int(c) for c in codes[[i, B + i]] if c), 0) if codes.size == 2 * B else 0
                why = FAILURES.get(code, "the separation became 0 or non-finite" if not code else "failure")
                message = (f"{int(np.count_nonzero(new))} of {B} trajectories failed; the first (index {i}) at "
                           f"t = {t_stop[i]:.6g}: {why} (integrating it or its companion); their exponents are "
                           "NaN")
        status[bad] = -1
        logsum = logsum + np.log(np.where(bad, 1.0, dist) / delta)
        logsum[status < 0] = np.nan
        hist[j if return_history else 0] = logsum / t_next
        unit = d / np.where(bad, 1.0, dist)[:, None]
        xi_p = xi + delta * unit[:, :k]
        if G is not None:
            G_p = G + delta * unit[:, k:]
            G_p = G_p / np.linalg.norm(G_p, axis=-1, keepdims=True)
        # a failed trajectory keeps NaN; restart it from finite numbers so the batch call stays valid
        if np.any(bad):
            xi = np.where(bad[:, None], xi0, xi)
            xi_p = np.where(bad[:, None], xi, xi_p)
            if G is not None:
                G = np.where(bad[:, None], b.Gamma, G)
                G_p = np.where(bad[:, None], G, G_p)
        t_prev = t_next
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    lam = hist[-1].reshape(b.shape)
    if not return_history:
        if message:
            warnings.warn(f"lyapunov_exponent: {message}", RuntimeWarning, stacklevel=2)
        return lam
    half = hist[K // 2:]
    # (one value in the second half, K < 3: no convergence estimate — it was 0, which reads as converged)
    spread = (np.max(half, axis=0) - np.min(half, axis=0) if half.shape[0] > 1 else np.full(B, np.nan)).reshape(b.shape)
    times = t0 + span * np.arange(1, K + 1) / K
    return LyapunovResult(exponent=lam, times=times, history=hist.reshape((K,) + b.shape), spread=spread,
                          log_t_over_t=float(np.log(span) / span) if span > 1 else float("nan"),
                          status=status.reshape(b.shape), t_stop=t_stop.reshape(b.shape), message=message)
