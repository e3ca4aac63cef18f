"""The step-size controller, the error norm and the event rules: one source for the numpy solver and the
compiled kernel.

Every function here is written elementwise with numpy ufuncs, so that it runs on arrays (one entry per
trajectory, in :mod:`.solve_numpy`) and, compiled by numba as it stands, on floats (:mod:`.kernel`).

The norm is a state-space norm, as scipy's: for the integrated state ``y`` (``xi`` and the group part —
the attitude g (m*m entries) or the vertical Gamma (n entries)), with the embedded estimates ``err``,

    scale = atol + rtol * max(|y0|, |y1|)          (per component)
    S     = sum((err / scale)^2)                   (one sum per estimator)
    norm  = sqrt(S / N)                            (one estimator; N = components of y)
    norm  = S5 / sqrt(N (S5 + 0.01 S3))             (DOP853's two estimators, Hairer's combination)

The group part's estimate is the chart estimate ``E`` (an algebra element) carried to the state:
``err_g = g1 E`` for the attitude, ``err_Gamma = E Gamma1`` for the vertical (the first-order change of
``g0 phi(Theta)`` and ``phi(-Theta) Gamma0`` under ``Theta -> Theta + E``; signs do not matter in a norm).

A step is accepted when ``norm <= 1`` (a NaN norm never is); the next step is ``h * factor`` with scipy's
factors (safety 0.9, between 0.2 and 10, no growth right after a rejection).

Events: a step crosses an event's surface when its value leaves one side of 0 and reaches 0 or the other
side (:func:`crossed`); the crossing is located on the step's continuous extension, theta in [0, 1], by the
Illinois variant of regula falsi (:func:`secant_point`, :func:`illinois_update`) until the bracket is a few
ulps of t wide (:func:`bracket_closed`, :func:`closest_end`).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["SAFETY", "MIN_FACTOR", "MAX_FACTOR", "select", "scale", "combine", "accept_factor", "reject_factor",
           "initial_step", "probe_step", "ulp", "underflow", "step_floor", "fixed_steps", "on_surface_at_start",
           "crossed", "secant_point", "illinois_update", "closest_end", "bracket_closed"]

SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0
_EPS = float(np.finfo(float).eps)
# Added under the square root of DOP853's combination so that S5 = S3 = 0 gives 0, not 0/0 (it changes
# nothing above 1e-284).
_TINY = 1e-300


def select(cond, a, b):
    """``a`` where ``cond``, else ``b``: ``np.where`` on arrays; the compiled kernel registers the scalar
    ``a if cond else b`` for it (numba's ``np.where`` on scalars goes through 0-d arrays, ~1 s of compilation)."""
    return np.where(cond, a, b)


def scale(y0, y1, rtol, atol):
    """``atol + rtol * max(|y0|, |y1|)``, elementwise."""
    return atol + rtol * np.maximum(np.abs(y0), np.abs(y1))


def combine(s5, s3, ncomp, two):
    """The norm from the scaled sums of squares: ``sqrt(s5 / N)``, or DOP853's ``s5 / sqrt(N (s5 + 0.01 s3))``.

    NaN or inf sums give a NaN or inf norm, which the controller rejects.
    """
    if two:
        return s5 / np.sqrt(ncomp * (s5 + 0.01 * s3) + _TINY)
    return np.sqrt(s5 / ncomp)


def accept_factor(err, exponent, after_reject):
    """Growth of the step after an accepted step: ``min(10, 0.9 err^exponent)``, capped at 1 after a rejection."""
    f = np.minimum(MAX_FACTOR, SAFETY * np.maximum(err, _TINY) ** exponent)
    return select(after_reject, np.minimum(1.0, f), f)


def reject_factor(err, exponent):
    """Shrink factor after a rejected step: ``max(0.2, 0.9 err^exponent)``; 0.2 for a NaN or inf norm."""
    return select(err < np.inf, np.maximum(MIN_FACTOR, SAFETY * err ** exponent), MIN_FACTOR)


def initial_step(d0, d1, d2, h0, order):
    """Hairer's starting step (scipy's ``select_initial_step``) from its three norms.

    ``d0 = |y0|``, ``d1 = |f(y0)|`` (scaled RMS), ``h0`` the probe step (``0.01 d0 / d1``, or 1e-6), and
    ``d2 = |f(y0 + h0 f0) - f(y0)| / h0``; returns ``min(100 h0, (0.01 / max(d1, d2))^(1 / (order + 1)))``.
    """
    big = np.maximum(d1, d2)
    h1 = select(big <= 1e-15, np.maximum(1e-6, h0 * 1e-3), (0.01 / np.maximum(big, 1e-300)) ** (1.0 / (order + 1)))
    h = np.minimum(100.0 * h0, h1)
    # NaN when a norm overflowed (a field far beyond atol + rtol |y|): 0, which the step-size floor fails at
    # once (no step would pass the error test), where a NaN step would be rejected forever
    return select(h > 0.0, h, 0.0)


def ulp(t, direction):
    """The spacing of the floats at ``t`` in the direction of integration: ``|nextafter(t, direction inf) - t|``."""
    return np.abs(np.nextafter(t, direction * np.inf) - t)


def underflow(h, t, direction):
    """The step ``h`` is below ten ulps of ``t``: it no longer moves t by its size (the run fails there)."""
    return np.abs(h) < 10.0 * ulp(t, direction)


def step_floor(t0, t1):
    """Ten ulps of the largest ``|t|`` of the span: a step above it passes :func:`underflow` at every t of the
    span (a fixed step below it fails at once; an adaptive one is tested against its own t)."""
    return 10.0 * ulp(max(abs(t0), abs(t1)), 1.0)


def fixed_steps(span, h, cap):
    """Steps of a fixed-step run over ``span = |t1 - t0|``: ``ceil(span / h)``, at least 1 (the grid
    ``t0 + i h``, the last step shortened to land on t1), or ``cap`` when that is fewer — ``span / h`` may
    exceed any integer, and a run never takes more than max_steps (``cap`` = max_steps + 1)."""
    ratio = span / h
    if not ratio < cap:
        return cap
    return max(1, int(math.ceil(ratio - 1e-9)))


def probe_step(d0, d1):
    """The probe step of :func:`initial_step`: ``0.01 d0 / d1``, or 1e-6 when either norm is below 1e-5."""
    return select((d0 < 1e-5) | (d1 < 1e-5), 1e-6, 0.01 * d0 / np.maximum(d1, 1e-300))


def on_surface_at_start(value, magnitude, nterms):
    """A linear event's value at t0: 0 where it is within its rounding of 0, else the value.

    ``magnitude`` is ``|offset| + sum |coef * state|`` and ``nterms`` the number of products: a dot product
    of that many terms is exact to ``nterms * eps * magnitude`` (plus the state's own few ulps). A plane
    through the initial state (a return plane) then starts on its surface — not one rounding-level crossing
    at t ~ 1e-16 on some trajectories, a different set for each solver's order of summation.
    """
    return select(np.abs(value) <= (nterms + 4.0) * _EPS * magnitude, 0.0, value)


def crossed(old, new, direction):
    """The step crosses the event's surface: the value goes from below 0 to 0 or above (up), or from above
    to 0 or below (down), in the event's ``direction`` (+1 up, -1 down, 0 both; scipy's convention).

    A value that is exactly 0 at the start of a step is not a crossing: the trajectory started on the
    surface (at t0), or the crossing was the previous step's, which ended on it — so a root that falls on a
    step's end is found once, not twice (scipy reports it twice).
    """
    return (((old < 0.0) & (new >= 0.0) & (direction >= 0))
            | ((old > 0.0) & (new <= 0.0) & (direction <= 0)))


def secant_point(lo, hi, flo, fhi):
    """The next point of regula falsi in the bracket ``[lo, hi]`` with values ``flo``, ``fhi`` of opposite
    signs: ``(lo fhi - hi flo) / (fhi - flo)``, or the midpoint where rounding puts it outside ``(lo, hi)``."""
    c = (lo * fhi - hi * flo) / (fhi - flo)
    return select((lo < c) & (c < hi), c, 0.5 * (lo + hi))


def illinois_update(lo, hi, flo, fhi, vlo, vhi, side, c, fc):
    """The bracket after the value ``fc`` at ``c``: ``c`` replaces the end whose value has the sign of ``fc``.
    ``flo``, ``fhi`` are the values the secant uses: when the same end is replaced twice running (``side``:
    +1 hi, -1 lo, 0 neither yet) the other end's is halved (Illinois), which keeps the convergence
    superlinear where plain regula falsi stalls; ``vlo``, ``vhi`` are the ends' true values (for
    :func:`closest_end`).

    Returns ``(lo, hi, flo, fhi, vlo, vhi, side)``.
    """
    right = (fc > 0.0) == (fhi > 0.0)  # c and hi on the same side of the root
    flo_kept = select(side == 1, 0.5 * flo, flo)  # lo kept a second time running: halved
    fhi_kept = select(side == -1, 0.5 * fhi, fhi)
    return (select(right, lo, c), select(right, c, hi), select(right, flo_kept, fc), select(right, fc, fhi_kept),
            select(right, vlo, fc), select(right, fc, vhi), select(right, 1, -1))


def closest_end(lo, hi, vlo, vhi):
    """The root of a closed bracket: the end whose true value is the smaller in magnitude."""
    return select(np.abs(vlo) < np.abs(vhi), lo, hi)


def bracket_closed(t, h, lo, hi, c, direction):
    """The bracket ``[lo, hi]`` of theta spans at most 4 ulps of the time ``t + c h`` (a step of size ``h`` from
    ``t``, integrating in ``direction``): the root is located to rounding in t."""
    return np.abs(h) * (hi - lo) <= 4.0 * ulp(t + c * h, direction)
