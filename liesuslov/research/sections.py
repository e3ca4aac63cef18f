r"""Poincaré sections: the crossings of a surface by a batch of trajectories, in one integration.

A section is a function ``s(t, Omega, Gamma, g)`` of the state whose zero set is the surface: a callable
with the integrator's event conventions (batch axes leading), or a linear functional of the state
(:func:`plane`, :func:`coordinate_plane`, :func:`gamma_plane`, :func:`return_plane`), which the
integrator evaluates natively.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _runner as R

__all__ = ["poincare_section", "plane", "coordinate_plane", "gamma_plane", "return_plane", "reduced_velocity"]


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
    The integrator's ``LinearEvent`` (or an equivalent callable).
    """
    if omega is None and Gamma is None and g is None:
        raise ValueError("plane needs at least one of omega=, Gamma=, g= (the coefficients of the functional)")
    return R.make_plane(omega, Gamma, g, offset)


def coordinate_plane(system, *, omega: int | None = None, Gamma: int | None = None, value: float = 0.0):
    """The section ``omega_i = value`` (an algebra coordinate) or ``Gamma_i = value``.

    Parameters
    ----------
    system : SuslovSystem
    omega : int, optional
        Index of the coordinate of Omega in the algebra basis (so(3): ``(Omega_12, Omega_13, Omega_23)``).
    Gamma : int, optional
        Index of the component of Gamma (exactly one of ``omega``, ``Gamma``).
    value : float
    """
    if (omega is None) == (Gamma is None):
        raise ValueError("coordinate_plane needs exactly one of omega=i or Gamma=i (the index of the coordinate)")
    d, n = system.algebra.dim, system.n
    if omega is not None:
        i = _index(omega, d, "omega")
        a = np.zeros(d)
        a[i] = 1.0
        return R.make_plane(omega=a, offset=float(value))
    if n is None or not system.is_so:
        raise ValueError(f"Gamma= needs a body in SO(n); {system.algebra.name} has no Gamma")
    i = _index(Gamma, n, "Gamma")
    b = np.zeros(n)
    b[i] = 1.0
    return R.make_plane(Gamma=b, offset=float(value))


def gamma_plane(n: int, i: int | None = None):
    """The section ``Gamma_i = 0`` (default ``i = n - 1``: the last component, the paper's ``Gamma_n``)."""
    if not isinstance(n, (int, np.integer)) or n < 2:
        raise ValueError(f"n must be an integer >= 2 (the size of Gamma), got {n!r}")
    i = n - 1 if i is None else _index(i, n, "i")
    b = np.zeros(n)
    b[i] = 1.0
    return R.make_plane(Gamma=b)


def _index(i, size: int, name: str) -> int:
    if isinstance(i, (bool, np.bool_)) or not isinstance(i, (int, np.integer)):
        raise TypeError(f"{name} must be an integer index, got {type(i).__name__}")
    if not -size <= i < size:
        raise ValueError(f"{name} = {i} is out of range for a vector of size {size}")
    return int(i) % size


def reduced_velocity(system, omega: np.ndarray, Gamma: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """``(d omega/dt (..., d), d Gamma/dt (..., n) or None)`` of the reduced flow at a state (coordinates)."""
    return system.rhs(omega, Gamma)


def return_plane(system, Omega0, Gamma0=None):
    r"""The plane through the initial reduced state ``s0 = (omega0, Gamma0)`` normal to the reduced velocity.

    ``v0 . (s - s0) = 0`` with ``v0 = (d omega/dt, d Gamma/dt)`` at ``s0``: a periodic trajectory
    crosses it upwards (from ``v0 . (s - s0) < 0``) when it returns. One plane per trajectory of the batch.
    """
    b = R.prepare(system, Omega0, Gamma0)
    xdot, Gdot = system.rhs(b.omega, b.Gamma)
    off = np.sum(xdot * b.omega, axis=-1)
    if Gdot is not None:
        off = off + np.sum(Gdot * b.Gamma, axis=-1)
    shape = b.shape
    return R.make_plane(omega=xdot.reshape(shape + xdot.shape[-1:]),
                        Gamma=None if Gdot is None else Gdot.reshape(shape + Gdot.shape[-1:]),
                        offset=off.reshape(shape), direction=1)


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
        leading), or a linear event (:func:`plane`, :func:`coordinate_plane`, :func:`gamma_plane`,
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
    >>> rec = poincare_section(system, Omega0, (0.0, 500.0), gamma_plane(3), Gamma0=Gamma0)  # doctest: +SKIP
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
