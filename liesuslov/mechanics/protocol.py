"""What an integrator needs of a model: :class:`ModelProtocol`.

A *model* is the exact reduced form of a scene's equations that a Runge–Kutta–Munthe-Kaas stepper
runs: a field ``xi' = f(xi, Gamma)`` on coordinates ``xi`` of the constraint fibre D, the linear map
``xi -> Omega`` into the algebra (and its matrix representation), and ``Gamma`` moved by the group
action, ``Gamma' = -Omega Gamma``. :class:`~liesuslov.mechanics.models.Model` (built by
:meth:`SuslovSystem.model <liesuslov.mechanics.system.SuslovSystem.model>`) and
:class:`~liesuslov.reduction.PendulumModel` implement it; :func:`liesuslov.integrate` accepts any
object that does (``isinstance(obj, ModelProtocol)``).

This module imports nothing from the rest of the package, so every layer may use it.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["ModelProtocol"]


@runtime_checkable
class ModelProtocol(Protocol):
    """The contract between a model and the integrators (structural: no base class needed).

    Attributes
    ----------
    k : int
        Dimension of ``xi`` (``dim D``).
    n : int or None
        Size ``m`` of the matrices of the algebra's representation (n for so(n), 3 for se(2), 4 for
        se(3)); None when the algebra has no representation (then no reconstruction, no ``Gamma``).
    has_gamma : bool
        Whether ``Gamma`` (shape ``(..., n)``) is part of the state.
    form : str
        Which form of the equations this is (``"symmetric"``, ``"eigenspace"``, ``"reduced"``,
        ``"multiplier"``, or a model's own name such as ``"spherical-pendulum"``).
    state_dim : int
        ``k + n`` with ``Gamma``, else ``k``.
    algebra : LieAlgebra
        The algebra ``g`` with ``dim d``; ``omega_coords`` maps into its coordinates.
    subspace : Subspace
        The fibre D in ``g`` whose coordinates are ``xi`` (the whole algebra for ``"multiplier"``).
    fedorov_kozlov : bool
        True iff ``Omega = sum_i xi_i E_in`` (``Omega = u e_n^T - e_n u^T``, ``u = (xi, 0)``): kernels
        may then write ``Omega`` into the last row and column directly.
    system : object
        The system the model was built from (a :class:`~liesuslov.SuslovSystem`, or the model's own
        owner), for diagnostics.

    Notes
    -----
    Every method is batched over leading axes ``(...)``, takes float arrays and does no validation (it
    is the hot path). ``Gamma`` is None when ``has_gamma`` is False.

    A model is the same for every trajectory: the integrator may call it on one trajectory at a time
    (``xi`` of shape (1, k)) or on any sub-batch, so it must not carry per-trajectory parameters (a
    field that differs between trajectories belongs in the state, or in a frame change done outside,
    as :func:`~liesuslov.reduction.integrate_pendulum` does for a batch of field directions).
    """

    k: int
    n: int | None
    has_gamma: bool
    form: str
    state_dim: int
    algebra: Any
    subspace: Any
    fedorov_kozlov: bool
    system: Any

    def xi_dot(self, xi: np.ndarray, Gamma: np.ndarray | None) -> np.ndarray:
        """The reduced field ``d xi / dt``.

        Parameters
        ----------
        xi : ndarray, shape (..., k)
        Gamma : ndarray of shape (..., n), or None
            The same batch shape as ``xi`` (where the field does not depend on ``xi`` the result
            takes Gamma's batch shape).

        Returns
        -------
        ndarray, shape (..., k)
        """
        ...

    def omega_matrix(self, xi: np.ndarray) -> np.ndarray:
        """``Omega`` in the matrix representation, linear in ``xi``: (..., k) -> (..., n, n).

        Kernels may read the basis once as ``omega_matrix(eye(k))`` (shape (k, n, n)).
        """
        ...

    def omega_coords(self, xi: np.ndarray) -> np.ndarray:
        """``Omega`` in the algebra's coordinates, ``omega = xi @ B`` for a basis B of D: (..., k) -> (..., d)."""
        ...

    def xi_from_coords(self, x: np.ndarray) -> np.ndarray:
        """``xi`` of a point ``x`` of D (the caller checks ``x`` in D): (..., d) -> (..., k)."""
        ...
