"""Recognising the multidimensional Lagrange case: :func:`lagrange_parameters`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..algebra import Inertia, SpecialOrthogonalAlgebra, suslov_distribution
from ..mechanics import Case, SuslovSystem

__all__ = ["LagrangeParameters", "lagrange_parameters"]


@dataclass(frozen=True)
class LagrangeParameters:
    """The parameters of a Lagrange scene: ``I = diag(I1, …, I1, In)``, ``V = Bn Γn``; ``m = I1 + In``."""

    n: int
    I1: float
    In: float
    Bn: float

    @property
    def m(self) -> float:
        """The pendulum's mass ``I1 + In``."""
        return self.I1 + self.In


def _mass_tensor(inertia: Inertia) -> np.ndarray:
    """The mass tensor of an inertia on so(n); recovered from K = diag(I_i + I_j) when not stored."""
    if inertia.mass_tensor is not None:
        return np.asarray(inertia.mass_tensor, dtype=float)
    alg = inertia.algebra
    n = alg.n
    K = inertia.matrix
    r, c = np.triu_indices(n, 1)
    A = np.zeros((alg.dim, n))
    A[np.arange(alg.dim), r] = 1.0
    A[np.arange(alg.dim), c] = 1.0
    Id = np.linalg.lstsq(A, np.diag(K), rcond=None)[0]
    K2 = Inertia.from_mass_tensor(Id).matrix
    if not np.allclose(K, K2, rtol=1e-10, atol=1e-12 * float(np.max(np.abs(K)))):
        raise ValueError("the inertia is not that of a rigid body with a diagonal mass tensor "
                         "(K is not diag(I_i + I_j)); the Lagrange case needs I = diag(I1, ..., I1, In)")
    return np.diag(Id)


def lagrange_parameters(system_or_case) -> LagrangeParameters:
    """Check that a scene is the multidimensional Lagrange case and return its parameters.

    The Lagrange case: a body in SO(n), n >= 3, with mass tensor ``I = diag(I1, …, I1, In)``,
    potential ``V = Bn Γn`` (a :class:`~liesuslov.LinearPotential` with ``B = (0, …, 0, Bn)``, or
    V = 0 meaning Bn = 0), the Fedorov–Kozlov constraints (``Ω_ij = 0`` for i, j ≤ n−1) and no
    gyroscopic term.

    Parameters
    ----------
    system_or_case : SuslovSystem or Case
        E.g. ``ls.cases.lagrange(n, I1, In, Bn)`` or ``ls.cases.lagrange3(J1, J3, B3)``.

    Returns
    -------
    LagrangeParameters

    Raises
    ------
    TypeError
        Not a SuslovSystem or Case.
    ValueError
        Saying what differs from the Lagrange case.
    """
    system = system_or_case.system if isinstance(system_or_case, Case) else system_or_case
    if not isinstance(system, SuslovSystem):
        raise TypeError("system_or_case must be a SuslovSystem or a Case (e.g. ls.cases.lagrange(4, 1, 2, 1))"
                        f", got {type(system_or_case).__name__}")
    alg = system.algebra
    if not isinstance(alg, SpecialOrthogonalAlgebra) or alg.n < 3:
        raise ValueError(f"not the Lagrange case: the body must be in SO(n) with n >= 3, got {alg.name}")
    n = alg.n
    I = _mass_tensor(system.inertia)
    scale = float(np.max(np.abs(I)))
    off = I - np.diag(np.diag(I))
    if np.max(np.abs(off)) > 1e-12 * scale:
        i, j = np.unravel_index(int(np.argmax(np.abs(off))), off.shape)
        raise ValueError("not the Lagrange case: the mass tensor must be diagonal, I = diag(I1, ..., I1, In);"
                         f" got I[{i + 1},{j + 1}] = {I[i, j]:.6g}")
    diag = np.diag(I)
    dev = np.abs(diag[: n - 1] - diag[0])
    if np.max(dev) > 1e-10 * scale:
        i = int(np.argmax(dev > 1e-10 * scale))  # the first that differs
        raise ValueError("not the Lagrange case: the mass tensor must be diag(I1, ..., I1, In) (symmetric "
                         f"about e_n); got I_{i + 1} = {diag[i]:.10g} != I_1 = {diag[0]:.10g}")
    D = system.constraints
    fk = suslov_distribution(n).basis
    if D.dim != n - 1 or not np.allclose(D.basis.T @ D.basis, fk.T @ fk, rtol=0, atol=1e-10):
        raise ValueError(f"not the Lagrange case: the constraints must be the Fedorov–Kozlov ones "
                         f"(Omega_ij = 0 for i, j <= n-1, ls.suslov_distribution({n})); got a D of dimension "
                         f"{D.dim} that differs from it")
    if system.gyroscopic != 0.0:
        raise ValueError(f"not the Lagrange case: there is a gyroscopic term (eps = {system.gyroscopic:g})")
    pot = system.potential
    if pot.is_zero:
        Bn = 0.0
    elif pot.kind == "linear":
        b = np.asarray(pot.B, dtype=float)
        bscale = float(np.max(np.abs(b)))
        if np.max(np.abs(b[: n - 1])) > 1e-12 * bscale:
            i = int(np.argmax(np.abs(b[: n - 1]) > 1e-12 * bscale))
            raise ValueError("not the Lagrange case: the potential must be V = Bn Gamma_n (centre of mass "
                             f"on the symmetry axis e_n); got B_{i + 1} = {b[i]:.6g} != 0")
        Bn = float(b[-1])
    else:
        raise ValueError("not the Lagrange case: the potential must be V = Bn Gamma_n (a LinearPotential "
                         f"with B = (0, ..., 0, Bn)), got a {pot.kind} potential {pot!r}")
    return LagrangeParameters(n=n, I1=float(diag[0]), In=float(diag[-1]), Bn=Bn)
