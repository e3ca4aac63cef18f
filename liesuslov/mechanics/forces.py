"""The force terms on so(n) shared by the system and its models (no dependence on either).

``wedge_coordinates`` gives ``a ∧ b = a b^T - b a^T`` in so(n) coordinates (the potential torque is
``vee(dV/dGamma ∧ Gamma)``); ``gyroscopic_torque`` the so(3) force ``eps * Gamma x w``. Both live below
:mod:`.system` and :mod:`.models` so that neither imports the other for them.
"""

from __future__ import annotations

import numpy as np

__all__ = ["wedge_coordinates", "gyroscopic_torque"]


def wedge_coordinates(a, b) -> np.ndarray:
    """Coordinates of ``a ∧ b = a b^T - b a^T`` on so(n): (..., n), (..., n) -> (..., n(n-1)/2)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    r, c = np.triu_indices(a.shape[-1], 1)
    return a[..., r] * b[..., c] - a[..., c] * b[..., r]


def gyroscopic_torque(x, Gamma, eps: float) -> np.ndarray:
    """so(3) coordinates of the gyroscopic force ``eps * Gamma x w`` (w the vector form of x).

    ``Gamma x w = vee(w ∧ Gamma)``; components written out: (..., 3), (..., 3) -> (..., 3).
    """
    x = np.asarray(x, dtype=float)
    G = np.asarray(Gamma, dtype=float)
    w0, w1, w2 = -x[..., 2], x[..., 1], -x[..., 0]
    g0, g1, g2 = G[..., 0], G[..., 1], G[..., 2]
    return eps * np.stack([w0 * g1 - w1 * g0, w0 * g2 - w2 * g0, w1 * g2 - w2 * g1], axis=-1)
