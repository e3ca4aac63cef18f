r"""Poincaré sections: the crossings of a surface by a batch of trajectories, in one integration.

A section is a function ``s(t, Omega, Gamma, g)`` of the state whose zero set is the surface: a callable
with the integrator's event conventions (batch axes leading), or a linear functional of the state
(:func:`plane`, :func:`coordinate_plane`, :func:`gamma_crossing`, :func:`return_plane`), which the
integrator evaluates natively.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..integrators.events import coordinate_plane, gamma_crossing, return_plane  # re-exported
from . import _runner as R

__all__ = ["poincare_section", "plane", "coordinate_plane", "gamma_crossing", "return_plane"]


def plane(omega=None, Gamma=None, g=None, offset=0.0):
    r"""The section ``a . omega + b . Gamma + sum(c * g) = offset`` (a linear event).

    Parameters
    ----------
    omega : array_like, shape (..., d), optional
        ``a``, on the coordinates of Omega in the algebra basis.
    Gamma : array_like, shape (..., n), optional
        ``b``.
    g : array_like, shape (..., m, m), optional
        ``c`` (needs the attitude: :func:`poincare_section` then reconstructs g).
    offset : float or array_like, shape (...)
        ``d``. Batch axes of the coefficients give one plane per trajectory (flattened in C order).

    Returns
    -------
    LinearEvent
    """
    if omega is None and Gamma is None and g is None:
        raise ValueError("plane needs at least one of omega=, Gamma=, g= (the coefficients of the functional)")
    return R.make_plane(omega, Gamma, g, offset)


def poincare_section(system, Omega0, t_span, section, *, Gamma0=None, g0=None, direction: int = 1,
                     **options: Any):
    r"""The crossings of the surface ``section = 0`` by a batch of trajectories, in one integration.

    Parameters
    ----------
    system : SuslovSystem
    Omega0 : array_like, shape (..., n, n) or (..., d)
        Initial angular velocities in D (the batch).
    t_span : (t0, t1)
        ``t1 > t0``.
    section : callable or linear event
        ``section(t, Omega, Gamma, g) -> (...)`` with the integrator's event conventions (batch axes
        leading), or a linear event (:func:`plane`, :func:`coordinate_plane`, :func:`gamma_crossing`,
        :func:`return_plane`). A linear event's coefficients may carry the batch axes.
    Gamma0 : array_like, shape (..., n), optional
        Required when the potential needs it; given otherwise, Gamma is integrated too.
    g0 : array_like, shape (..., m, m), optional
        Initial attitude: the attitude is reconstructed (and reported at the crossings) iff given.
    direction : {1, -1, 0}
        Crossings from ``section < 0`` to ``> 0`` (1), the reverse (-1), or both (0).
    **options
        ``integrate``'s options; without any, ``method="rkmk853", rtol=1e-10, atol=1e-12``.

    Returns
    -------
    EventRecord
        ``t (K,)``, ``index (K,)`` (flat C-order batch index), ``omega (K, d)``, ``Omega (K, n, n)``,
        ``Gamma (K, n)`` or None, ``g (K, m, m)`` or None; sorted by (index, t).

    Examples
    --------
    >>> rec = poincare_section(system, Omega0, (0.0, 500.0), gamma_crossing(3), Gamma0=Gamma0)  # doctest: +SKIP
    >>> rec.Gamma[rec.index == 0]                                                               # doctest: +SKIP
    """
    if isinstance(direction, (bool, np.bool_)) or direction not in (-1, 0, 1):
        raise ValueError(f"direction must be 1 (upwards), -1 (downwards) or 0 (both), got {direction!r}")
    if not callable(section):
        raise TypeError(f"section must be a callable section(t, Omega, Gamma, g) or a linear event (ls.research."
                        f"plane(...)), got {type(section).__name__}")
    t0, t1 = R.check_span(t_span)
    opts = R.options_with_defaults(options)
    b = R.prepare(system, Omega0, Gamma0, g0)
    needs_g = getattr(section, "g", None) is not None and R._is_linear(section)
    reconstruct = b.g0 is not None or needs_g
    g = b.g0 if b.g0 is not None else (np.broadcast_to(np.eye(system.n), (b.size, system.n, system.n)).copy()
                                       if reconstruct else None)
    if R._is_linear(section):
        section = R.flat_event(section, b.shape)
    win = R.run_window(system, b.omega, b.Gamma, g, (t0, t1), section, int(direction), opts, reconstruct)
    return R.make_record(win.crossings, system.n, system.algebra.name)
