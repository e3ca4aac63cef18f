"""Events: surfaces ``event(t, Omega, Gamma, g) = 0`` crossed by a trajectory, located on its continuous extension.

scipy's conventions: an event is a callable with optional attributes ``terminal`` (bool: stop the
trajectory at its first crossing; or an int N >= 0: stop it at its N-th crossing, 0 never) and
``direction`` (+1: only crossings where the value goes up, -1: down, 0: both, along the integration). It is
called with the batch axes leading — ``t`` a float (one trajectory) or an array of
the batch shape (...) (each trajectory's own time), ``Omega`` (..., n, n) (coordinates (..., d) on
algebras other than so(n)), ``Gamma`` (..., n) or None, ``g`` (..., m, m) or None — and returns one value
per trajectory, (...): it may use per-trajectory parameters of the batch's shape (the trajectories not
being evaluated are passed at their last accepted points; their values are not read). A crossing is a
step whose value leaves one side of 0 and reaches 0 or the other side (:func:`.control.crossed`: a root
on a step's end is one crossing, and a value exactly 0 at t0 is none); its time is located by a
bracketing root finder (Illinois) on the continuous extension to near rounding in t.

:class:`LinearEvent` — a linear function of the state, ``a . omega + b . Gamma + sum(c * g) - offset`` — is
what the built-in helpers return and what the compiled kernel evaluates natively; any other callable
runs on the numpy solver. :class:`EventRecord` holds the located crossings.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._rows import real_floats
from .._validation import as_float_array, unit_vectors
from ..algebra.elements import omega_coordinates

__all__ = ["EventRecord", "LinearEvent", "coordinate_plane", "gamma_crossing", "return_plane", "event_flags",
           "initial_velocity"]


@dataclass
class EventRecord:
    """The crossings of one event function, for all trajectories, sorted by (index, t).

    Within a trajectory ``t`` increases, also when integrating backward (``t_span[1] < t_span[0]``: the
    reverse of the order the integration met them, which is scipy's ``t_events`` order).

    Attributes
    ----------
    t : (K,) ndarray
    index : (K,) ndarray of int
        Flat (C-order) batch index of the trajectory that crossed.
    omega : (K, d) ndarray
        Coordinates of Omega at the crossing.
    Gamma : (K, n) ndarray or None
    g : (K, m, m) ndarray or None
    n : int or None
        Matrix size (for :attr:`Omega`).
    algebra_name : str
    status : ndarray of int, shape (...), or None
        Set by :func:`~liesuslov.research.poincare_section` (a record that stands for a whole integration):
        per trajectory 0 reached the end of t_span, -1 failed (its crossings stop at the failure).
    message : str
        With ``status``: the integration's message (the first failure, its reason and time).
    """

    t: np.ndarray
    index: np.ndarray
    omega: np.ndarray
    Gamma: np.ndarray | None = None
    g: np.ndarray | None = None
    n: int | None = None
    algebra_name: str = ""
    status: np.ndarray | None = None
    message: str = ""

    @property
    def Omega(self) -> np.ndarray | None:
        """Omega at the crossings as skew matrices (K, n, n) on so(n); None on other algebras."""
        if not self.algebra_name.startswith("so(") or self.n is None:
            return None
        from ..algebra import so

        return so(self.n).hat(self.omega)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def __repr__(self) -> str:
        return f"EventRecord({len(self)} crossings of {len(np.unique(self.index))} trajectories)"


def terminal_count(terminal, name: str = "event.terminal") -> int:
    """The crossing at which an event stops its trajectory: ``True`` 1, ``False`` 0 (never), an int N >= 0
    the N-th (scipy's ``terminal``).

    Raises
    ------
    TypeError
        If ``terminal`` is neither a bool nor an integer.
    ValueError
        If it is a negative integer.
    """
    if isinstance(terminal, (bool, np.bool_)):
        return int(terminal)
    if not isinstance(terminal, (int, np.integer)):
        raise TypeError(f"{name} must be a bool or an int >= 0 (stop at that crossing), got "
                        f"{type(terminal).__name__} {terminal!r}")
    if terminal < 0:
        raise ValueError(f"{name} must be a bool or an int >= 0 (stop at that crossing), got {terminal}")
    return int(terminal)


def event_flags(event) -> tuple[int, int]:
    """``(terminal, direction)`` of an event callable (scipy's attributes; defaults False and 0), the first as
    :func:`terminal_count` (0: not terminal, N: stop at the N-th crossing).

    Raises
    ------
    TypeError
        If ``event`` is not callable, or its ``terminal`` neither a bool nor an int.
    ValueError
        If ``direction`` is not -1, 0 or +1, or ``terminal`` a negative int.
    """
    if not callable(event):
        raise TypeError(f"events must be callables event(t, Omega, Gamma, g) (or a list of them), got "
                        f"{type(event).__name__}")
    terminal = terminal_count(getattr(event, "terminal", False))
    direction = getattr(event, "direction", 0)
    if isinstance(direction, (bool, np.bool_)):  # True would be read as +1
        raise ValueError(f"event.direction must be -1, 0 or +1, got {direction!r}")
    try:
        direction = float(direction)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"event.direction must be -1, 0 or +1, got {direction!r}") from exc
    if direction not in (-1.0, 0.0, 1.0):
        raise ValueError(f"event.direction must be -1, 0 or +1, got {direction!r}")
    return terminal, int(direction)


class LinearEvent:
    """The event ``a . omega + b . Gamma + sum(c * g) - offset`` (a hyperplane in the state).

    Parameters
    ----------
    omega : array_like, shape (..., d), optional
        Coefficients ``a`` on Omega's coordinates in the algebra basis.
    Gamma : array_like, shape (..., n), optional
        Coefficients ``b`` on the vertical (body frame).
    g : array_like, shape (..., m, m), optional
        Coefficients ``c`` on the attitude's entries.
    offset : float or array_like, shape (...)
    terminal : bool or int
        Stop the trajectory at its first crossing (True), or at its N-th (an int N >= 0; 0 never).
    direction : {-1, 0, 1}
        Only crossings where the value goes down (-1), up (+1), or both (0).

    Notes
    -----
    Leading axes of the coefficients are batch axes: a per-trajectory plane (e.g. through each initial
    state) broadcasts against the batch of ``integrate``. Callable like any event:
    ``event(t, Omega, Gamma, g)`` with Omega as skew matrices or coordinates; the compiled kernel reads
    the coefficients instead of calling it.
    """

    def __init__(self, omega=None, Gamma=None, g=None, offset=0.0, *, terminal: bool | int = False,
                 direction: int = 0) -> None:
        if omega is None and Gamma is None and g is None:
            raise ValueError("LinearEvent needs at least one of omega=, Gamma=, g= (its coefficients)")
        self.omega = None if omega is None else _real(omega, "omega")
        self.Gamma = None if Gamma is None else _real(Gamma, "Gamma")
        self.g = None if g is None else _real(g, "g")
        self.offset = _real(offset, "offset")
        # a zero normal makes the constant -offset: no surface to cross (never one, or, at offset 0, everywhere)
        norm2 = sum(np.sum(c * c, axis=tuple(range(c.ndim - core, c.ndim)))
                    for c, core in ((self.omega, 1), (self.Gamma, 1), (self.g, 2)) if c is not None)
        if np.any(norm2 == 0.0):
            raise ValueError("LinearEvent: its coefficients (omega=, Gamma=, g=) are all 0"
                             + (" for some trajectory" if np.ndim(norm2) else "")
                             + ": the event is a constant, not a surface; pass a nonzero normal")
        count = terminal_count(terminal, "terminal")
        self.terminal = bool(count) if isinstance(terminal, (bool, np.bool_)) else count
        self.direction = direction
        event_flags(self)

    def __call__(self, t, Omega, Gamma, g):
        val = -self.offset
        if self.omega is not None:
            x = np.asarray(Omega)
            d, n = self.omega.shape[-1], x.shape[-1] if x.ndim >= 2 else 0
            # as integrate calls it: skew (..., n, n) on so(n), coordinates (..., d) elsewhere. A size test alone
            # misread so(3) (n = d = 3) matrices as three coordinate vectors; a batch of coordinate vectors that is
            # exactly skew (zero diagonal, x_ij = -x_ji) is the one input read the other way
            if n * (n - 1) // 2 == d and x.shape[-2] == n and np.array_equal(x, -np.swapaxes(x, -1, -2)):
                from ..algebra import so

                x = so(n).vee(x)
            val = val + np.sum(self.omega * x, axis=-1)
        if self.Gamma is not None:
            if Gamma is None:
                raise ValueError("this LinearEvent reads Gamma, but the scene has none")
            val = val + np.sum(self.Gamma * Gamma, axis=-1)
        if self.g is not None:
            if g is None:
                raise ValueError("this LinearEvent reads g: integrate with reconstruct=True")
            val = val + np.sum(self.g * g, axis=(-2, -1))
        return val

    def __repr__(self) -> str:
        parts = [name for name in ("omega", "Gamma", "g") if getattr(self, name) is not None]
        return f"LinearEvent({'+'.join(parts)}, terminal={self.terminal}, direction={self.direction})"


def _real(x, name: str) -> np.ndarray:
    arr = np.array(real_floats(x, f"LinearEvent {name}"))  # (a copy: the event keeps its coefficients)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"LinearEvent {name} must be finite")
    return arr


def coordinate_plane(variable: str, index: int, value: float = 0.0, *, dim: int, terminal: bool | int = False,
                     direction: int = 0) -> LinearEvent:
    """The plane ``omega[index] = value`` or ``Gamma[index] = value``.

    Parameters
    ----------
    variable : {"omega", "Gamma"}
    index : int
        Component (negative counts from the end, ``-1`` is Gamma_n).
    value : float
    dim : int
        The dimension of the variable (d for omega, n for Gamma).
    terminal : bool or int
        scipy's convention: True stops a trajectory at its first crossing, an integer N >= 0 at its N-th
        (0 never); default False.
    direction : {-1, 0, 1}
        Only crossings where the value goes down (-1), up (+1), or both (0), along the integration.

    Returns
    -------
    LinearEvent
    """
    if variable not in ("omega", "Gamma"):
        raise ValueError(f"variable must be 'omega' or 'Gamma', got {variable!r}")
    for name, val in (("dim", dim), ("index", index)):
        if isinstance(val, (bool, np.bool_)) or not isinstance(val, (int, np.integer)):
            raise TypeError(f"{name} must be an integer, got {type(val).__name__} {val!r}")
    if dim < 1:
        raise ValueError(f"dim must be >= 1 (the dimension of {variable}), got {dim}")
    if not -dim <= index < dim:
        raise ValueError(f"index {index} is out of range for {variable} of dimension {dim}")
    coef = np.zeros(dim)
    coef[index] = 1.0
    return LinearEvent(**{variable: coef}, offset=value, terminal=terminal, direction=direction)


def gamma_crossing(n: int, index: int = -1, *, terminal: bool | int = False, direction: int = 0) -> LinearEvent:
    """``Gamma[index] = 0`` (default the last component, Gamma_n: the Klebsh–Tisserand section)."""
    if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)):
        raise TypeError(f"n must be an integer >= 2 (the dimension of Gamma), got {type(n).__name__} {n!r}")
    if n < 2:
        raise ValueError(f"n must be an integer >= 2 (the dimension of Gamma), got {n}")
    return coordinate_plane("Gamma", index, 0.0, dim=n, terminal=terminal, direction=direction)


def return_plane(system, Omega0, Gamma0=None, *, terminal: bool | int = False, direction: int = 1) -> LinearEvent:
    """The plane through each initial reduced state, normal to the reduced velocity there.

    ``<v0, (omega, Gamma) - (omega0, Gamma0)> = 0`` with ``v0 = (d omega / dt, d Gamma / dt)`` at t0: the
    flow crosses it upward at t0, so the first upward crossing after t0 is a first return (for a
    periodic reduced motion, at its period). Batch axes of Omega0 and Gamma0 give one plane per trajectory.

    Parameters
    ----------
    system : SuslovSystem
    Omega0 : array_like, shape (..., n, n) or (..., d)
    Gamma0 : array_like, shape (..., n), optional
    terminal : bool or int
        scipy's convention: True stops a trajectory at its first crossing, an integer N >= 0 at its N-th
        (0 never); default False.
    direction : {-1, 0, 1}
        Only crossings where the value goes down (-1), up (+1), or both (0), along the integration; default +1 (the
        side the flow leaves at t0, so a return crosses it upward).

    Returns
    -------
    LinearEvent
        One plane per trajectory (coefficients and offset with the batch axes of the initial data).

    Raises
    ------
    ValueError
        If an initial state is an equilibrium (zero reduced velocity: no transverse plane).
    """
    omega0, Gamma0_, domega, dGamma = initial_velocity(system, Omega0, Gamma0)
    offset = np.sum(domega * omega0, axis=-1)
    kwargs = {"omega": domega}
    if Gamma0_ is not None:
        kwargs["Gamma"] = dGamma
        offset = offset + np.sum(dGamma * Gamma0_, axis=-1)
    scale = np.sqrt(np.sum(domega ** 2, axis=-1) + (np.sum(dGamma ** 2, axis=-1) if Gamma0_ is not None else 0.0))
    if np.any(scale == 0):
        raise ValueError("return_plane: the initial state is an equilibrium (zero velocity); no section "
                         "through it is transverse to the flow")
    kwargs = {key: v / scale[..., None] for key, v in kwargs.items()}
    return LinearEvent(**kwargs, offset=offset / scale, terminal=terminal, direction=direction)


def initial_velocity(system, Omega0, Gamma0=None):
    """``(omega0 (..., d), Gamma0 (..., n) or None, d omega/dt (..., d), d Gamma/dt (..., n) or None)`` at t0.

    The reduced velocity of the smallest model of ``system`` (``d Gamma / dt = -Omega Gamma``); used by
    :func:`return_plane`.
    """
    model = system.model(gamma=True if Gamma0 is not None else None)
    x0 = omega_coordinates(model.algebra, Omega0, "Omega0")
    G0 = None
    if model.has_gamma:
        if Gamma0 is None:
            raise ValueError("Gamma0 is required: the potential (or gyroscopic term) depends on Gamma")
        G0 = unit_vectors(as_float_array(Gamma0, "Gamma0", ndim_min=1, tail=(model.n,)), "Gamma0")
        lead = np.broadcast_shapes(x0.shape[:-1], G0.shape[:-1])
        x0 = np.broadcast_to(x0, lead + x0.shape[-1:])
        G0 = np.broadcast_to(G0, lead + G0.shape[-1:])
    xi = model.xi_from_coords(x0)
    dxi = model.xi_dot(xi, G0)
    domega = model.omega_coords(dxi)
    dG = None
    if G0 is not None:
        Om = model.omega_matrix(xi)
        dG = -np.matmul(Om, G0[..., None])[..., 0]
    return x0, G0, domega, dG
