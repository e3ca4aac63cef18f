"""Coordinate charts of the group near the identity: the exponential and the Cayley map.

A chart is a field of the method, not a new integrator (Lielab's design): the RKMK stepper asks it
for ``phi(Theta)`` (the group increment), ``phi(Theta) v`` on vectors, and the inverse derivative
``dphi^{-1}`` that turns the left-trivialised velocity Omega into ``dTheta/dt``.

Side of the action: the attitude obeys ``g^{-1} dg/dt = Omega`` and a step writes
``g = g0 phi(Theta)`` (right multiplication), so ``dTheta/dt = dphi^{-1}_{-Theta}(Omega)``
— for the exponential ``Omega + 1/2 [Theta, Omega] + 1/12 [Theta, [Theta, Omega]] + …``; with the
other sign of the odd terms RKMK4 silently drops to order 2. The vertical in the body frame moves
by the inverse: ``Gamma = phi(Theta)^T Gamma0 = phi(-Theta) Gamma0`` for orthogonal groups.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .. import groups

__all__ = ["Chart", "make_chart", "CHARTS"]

CHARTS = ("exp", "cayley")


@dataclass(frozen=True)
class Chart:
    """A chart bundled for one algebra representation and one method order.

    Attributes
    ----------
    name : {"exp", "cayley"}
    phi : callable (..., m, m) -> (..., m, m)
        The map algebra -> group.
    phi_vec : callable ((..., m, m), (..., m)) -> (..., m)
        ``phi(Theta) v`` without forming more than needed.
    dinv : callable ((..., m, m), (..., m, m)) -> (..., m, m)
        ``dphi^{-1}_{-Theta}(Omega)`` (right-trivialised, see the module docstring), exact for
        Cayley and for the so(3) exponential, truncated at the order the method needs otherwise.
    """

    name: str
    phi: Callable[[np.ndarray], np.ndarray]
    phi_vec: Callable[[np.ndarray, np.ndarray], np.ndarray]
    dinv: Callable[[np.ndarray, np.ndarray], np.ndarray]


def make_chart(name: str, m: int, *, skew: bool, order: int) -> Chart:
    """Build the chart ``name`` for m×m representation matrices.

    Parameters
    ----------
    name : {"exp", "cayley"}
    m : int
        Matrix size.
    skew : bool
        True on so(n) (closed forms, orthogonal output); False for general matrix groups.
    order : int
        Order p of the RK method; the exponential's dexp^{-1} series keeps the terms up to
        ``ad^{p-2}`` (sufficient for order p, Munthe-Kaas 1999; Hairer–Lubich–Wanner IV.8).
    """
    if name == "exp":
        if skew and m == 3:
            return Chart("exp", groups.expm_skew, groups.expm_skew_apply,
                         lambda T, A: groups.dexpinv_skew3(T, A, side="right"))
        terms = max(order - 1, 1)
        phi = groups.expm_skew if skew else groups.expm
        phi_vec = groups.expm_skew_apply if skew else (lambda T, v: (phi(T) @ v[..., None])[..., 0])
        return Chart("exp", phi, phi_vec, lambda T, A: groups.dexpinv(T, A, terms, side="right"))
    if name == "cayley":
        return Chart("cayley", groups.cayley, groups.cayley_apply,
                     lambda T, A: groups.dcayinv(T, A, side="right"))
    raise ValueError(f"chart must be one of {CHARTS}, got {name!r}")
