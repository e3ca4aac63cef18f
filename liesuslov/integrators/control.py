"""The step-size controller and the error norm: one source for the numpy solver and the compiled kernel.

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
"""

from __future__ import annotations

import numpy as np

__all__ = ["SAFETY", "MIN_FACTOR", "MAX_FACTOR", "select", "scale", "combine", "accept_factor", "reject_factor",
           "initial_step", "probe_step"]

SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0
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
    return np.minimum(100.0 * h0, h1)


def probe_step(d0, d1):
    """The probe step of :func:`initial_step`: ``0.01 d0 / d1``, or 1e-6 when either norm is below 1e-5."""
    return select((d0 < 1e-5) | (d1 < 1e-5), 1e-6, 0.01 * d0 / np.maximum(d1, 1e-300))
