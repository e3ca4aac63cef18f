r"""Poincaré sections: the crossings of a surface by a batch of trajectories, in one integration.

A section is a function ``s(t, Omega, Gamma, g)`` of the state whose zero set is the surface: a callable
with the integrator's event conventions (batch axes leading), or a linear functional of the state
(:func:`plane`, :func:`coordinate_plane`, :func:`gamma_crossing`, :func:`return_plane`), which the
integrator evaluates natively.
"""

from __future__ import annotations

import warnings
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
        Initial attitude. The attitude is reconstructed (and reported at the crossings) iff ``g0`` is given
        or ``section`` is a linear event with ``g`` coefficients (then from the identity). A callable
        section is called with ``g=None`` without ``g0``: one that reads g raises a ValueError telling to
        pass ``g0`` (e.g. ``np.eye(n)``).
    direction : {1, -1, 0}
        Crossings from ``section < 0`` to ``> 0`` (1), the reverse (-1), or both (0). The section is used as a
        surface: its own ``direction`` and ``terminal`` attributes (an event of ``integrate`` reused here) are
        not read — this argument decides, and every crossing over ``t_span`` is collected.
    **options
        ``integrate``'s options; ``method="rkmk853", rtol=1e-10, atol=1e-12`` where not given.

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
    if isinstance(direction, (bool, np.bool_)) or not isinstance(direction, (int, np.integer)):
        raise TypeError(f"direction must be the integer 1 (upwards), -1 (downwards) or 0 (both), got {direction!r}")
    if direction not in (-1, 0, 1):
        raise ValueError(f"direction must be 1 (upwards), -1 (downwards) or 0 (both), got {direction!r}")
    if not callable(section):
        raise TypeError(f"section must be a callable section(t, Omega, Gamma, g) or a linear event (ls.research."
                        f"plane(...)), got {type(section).__name__}")
    t0, t1 = R.check_span(t_span)
    opts = R.options_with_defaults(options)
    b = R.prepare(system, Omega0, Gamma0, g0)
    linear = R._is_linear(section)
    if linear:
        _check_plane(section, system, b.Gamma is not None)
    needs_g = linear and section.g is not None
    reconstruct = b.g0 is not None or needs_g
    g = b.g0 if b.g0 is not None else (np.broadcast_to(np.eye(system.n), (b.size, system.n, system.n)).copy()
                                       if reconstruct else None)
    if linear:
        section = R.flat_event(section, b.shape)
    elif not reconstruct:
        section = _without_attitude(section, system.n)
    win = R.run_window(system, b.omega, b.Gamma, g, (t0, t1), section, int(direction), opts, reconstruct)
    # (a plane through the start is not crossed at t0: integrate's rule for linear events within their
    # rounding of 0 at t0, control.on_surface_at_start)
    cr = win.crossings
    status = win.status.reshape(b.shape)
    if np.any(status < 0):
        warnings.warn(f"poincare_section: {win.message} (its crossings stop there; record.status says which "
                      "trajectories failed)", RuntimeWarning, stacklevel=2)
    return R.make_record(cr, system.n, system.algebra.name, status=status, message=win.message)


def _check_plane(section, system, has_gamma: bool) -> None:
    """A linear section's coefficients have the state's shapes: omega (..., d), Gamma (..., n), g (..., m, m)."""
    d, n = system.algebra.dim, system.n
    for name, tail, what in (("omega", (d,), f"one per coordinate of Omega, d = {d}"),
                             ("Gamma", (n,), f"one per component of Gamma, n = {n}"),
                             ("g", (n, n), f"one per entry of the attitude, m = {n}")):
        val = getattr(section, name, None)
        if val is None:
            continue
        if name != "omega" and n is None:
            raise ValueError(f"section reads {name}, which {system.algebra.name} does not have (no matrix "
                             "representation): use omega= coefficients only")
        shape = np.shape(val)
        if shape[len(shape) - len(tail):] != tail or len(shape) < len(tail):
            raise ValueError(f"section: its {name} coefficients have shape {shape}, expected (..., "
                             f"{', '.join(map(str, tail))}) ({what}; leading axes are batch axes)")
    if getattr(section, "Gamma", None) is not None and not has_gamma:
        raise ValueError("section reads Gamma, but no Gamma0 was given (this scene does not need it): pass "
                         f"Gamma0, a unit vector of shape (..., {n})")


def _without_attitude(section, n):
    """A callable section called with ``g=None`` (no attitude): a failure that may come from reading g names g0."""
    def ev(t, Omega, Gamma, g, _f=section):
        try:
            return _f(t, Omega, Gamma, g)
        except (TypeError, AttributeError, IndexError) as exc:
            fix = (f"If the section reads g, pass g0 (e.g. g0=np.eye({n}))" if n is not None
                   else "This algebra has no matrix representation: there is no attitude to read")
            raise ValueError(f"section(t, Omega, Gamma, g) raised {type(exc).__name__}: {exc}. It was called with "
                             f"g=None: the attitude is reconstructed only when g0 is given. {fix}") from exc

    return ev
