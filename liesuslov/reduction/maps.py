"""The reduction maps of the Lagrange case: ``(g, Ω) ↦ (q, v)``, the pendulum's energy and momentum,
the SO(n−1) momentum map Φ, and the lift ``(q, v) ↦ (g, Ω)`` (a right inverse of the reduction)."""

from __future__ import annotations

import numpy as np

from .._validation import as_float_array, check_positive, check_real, check_rotations
from ..algebra import Inertia, SpecialOrthogonalAlgebra, omega_coordinates, so
from ._checks import ORTHO_TOL, tangent, unit

__all__ = ["to_spherical_pendulum", "pendulum_energy", "pendulum_momentum", "momentum_map", "lift"]


def _skew(Omega, n: int, name: str) -> np.ndarray:
    """``Omega`` as skew matrices (..., n, n), from matrices or so(n) coordinates (..., d)."""
    alg = so(n)
    return alg.hat(omega_coordinates(alg, Omega, name))


def to_spherical_pendulum(g, Omega) -> tuple[np.ndarray, np.ndarray]:
    """The reduction map ``(g, Ω) ↦ (q, v)`` of the Lagrange case onto the spherical pendulum.

    ``q = g e_n`` (the symmetry axis in space, a point of S^{n−1}) and ``v = q̇ = g Ω e_n`` (its
    velocity, tangent: ``⟨q, v⟩ = (gᵀg)_{n·} Ω e_n = Ω_nn = 0``). It is the tangent map of the
    bundle projection ``SO(n) → SO(n)/SO(n−1) = S^{n−1}``, so it is defined for any Ω; on
    Suslov states (Ω in the Fedorov–Kozlov D) it is the SO(n−1) quotient map.

    Parameters
    ----------
    g : array_like, shape (..., n, n)
        Attitudes in SO(n) (checked: ``|gᵀg − I| <= 1e-8``, ``det g = +1``).
    Omega : array_like, shape (..., n, n) or (..., d)
        Body angular velocities ``g⁻¹ ġ``: skew matrices or so(n) coordinates (``d = n(n−1)/2``;
        a trailing skew (n, n) block is read as a matrix). Batch axes broadcast with those of g.

    Returns
    -------
    q : ndarray, shape (..., n)
        ``g[..., :, n−1]``.
    v : ndarray, shape (..., n)
        ``g Ω e_n = g @ Omega[..., :, n−1]``.

    Raises
    ------
    ValueError
        ``g`` not square, not in SO(n); ``Omega`` not skew or of the wrong shape; batch axes
        that do not broadcast; non-finite values.

    Examples
    --------
    >>> import numpy as np, liesuslov as ls
    >>> q, v = ls.to_spherical_pendulum(np.eye(4), ls.wedge([1.0, 0, 0, 0], [0, 0, 0, 1.0]))
    >>> q, v
    (array([0., 0., 0., 1.]), array([1., 0., 0., 0.]))
    """
    G = as_float_array(g, "g", ndim_min=2)
    n = G.shape[-1]
    if G.shape[-2] != n or n < 2:
        raise ValueError(f"g must be square rotation matrices (..., n, n) with n >= 2, got shape {G.shape}")
    check_rotations(G, "g", tol=ORTHO_TOL)
    X = _skew(Omega, n, "Omega")
    try:
        shape = np.broadcast_shapes(G.shape[:-2], X.shape[:-2])
    except ValueError as exc:
        raise ValueError(f"the batch axes of g {G.shape[:-2]} and Omega {X.shape[:-2]} "
                         "do not broadcast") from exc
    q = np.broadcast_to(G[..., :, -1], shape + (n,)).copy()
    v = np.einsum("...ij,...j->...i", G, X[..., :, -1])
    return q, np.broadcast_to(v, shape + (n,)).copy()


def pendulum_energy(q, v, m, B, gamma) -> np.ndarray:
    """Energy of the spherical pendulum ``H = ½ m |v|² + B ⟨γ, q⟩``.

    For the Lagrange case, ``m = I1 + In``, ``B = Bn``, ``γ = g Γ`` (the vertical in space), and
    ``H(q, v)`` equals the Suslov energy ``½⟨J Ω, Ω⟩ + Bn Γn`` at every state: ``⟨J Ω, Ω⟩ =
    Σ_i (I1 + In) Ω_in² = m |g Ω e_n|²`` and ``Γn = ⟨gᵀγ, e_n⟩ = ⟨γ, q⟩``.

    Parameters
    ----------
    q, v : array_like, shape (..., n)
        Point and velocity (not checked to lie on T S^{n−1}).
    m : float
        Mass (positive).
    B : float
        Potential coefficient.
    gamma : array_like, shape (..., n)
        The direction of the field; batch axes broadcast.

    Returns
    -------
    ndarray, shape (...)
    """
    q = as_float_array(q, "q", ndim_min=1)
    n = q.shape[-1]
    v = as_float_array(v, "v", ndim_min=1, tail=(n,))
    gam = as_float_array(gamma, "gamma", ndim_min=1, tail=(n,))
    m = check_positive(m, "m")
    B = check_real(B, "B")
    return 0.5 * m * np.sum(v * v, axis=-1) + B * np.sum(gam * q, axis=-1)


def pendulum_momentum(v, m) -> np.ndarray:
    """The cotangent (Legendre) image ``p = m v`` of a pendulum velocity, shape (..., n).

    ``T*S^{n−1}`` is identified with ``T S^{n−1} ⊂ R^n × R^n`` by the round metric; under the
    reduction ``p`` is the image of the body momentum ``M = J(Ω)``: ``p = g M e_n`` (the last
    column of M is ``(I1 + In) Ω e_n`` on Suslov states).
    """
    v = as_float_array(v, "v", ndim_min=1)
    return check_positive(m, "m") * v


def momentum_map(Omega, inertia, *, as_matrix: bool = False) -> np.ndarray:
    """The momentum map Φ of the right SO(n−1) action: the so(n−1) block of ``M = J(Ω)``.

    ``Φ(Ω) = (M_ij)_{i, j ≤ n−1}`` with ``M = I Ω + Ω I`` (or ``K x`` for a general inertia in
    coordinates), a left-invariant function on ``T*SO(n)``. For a diagonal mass tensor and Ω in
    the Fedorov–Kozlov D (``Ω_ij = 0`` for i, j ≤ n−1), ``M_ij = (I_i + I_j) Ω_ij = 0``: every
    Suslov state lies on ``Φ⁻¹(0)``, where the Lagrange case reduces to the spherical pendulum.

    Parameters
    ----------
    Omega : array_like, shape (..., n, n) or (..., d)
        Body angular velocities (skew matrices or so(n) coordinates), any Ω in so(n).
    inertia : Inertia or array_like
        An :class:`~liesuslov.algebra.Inertia` on so(n), or a mass tensor (n, n) or its diagonal (n,).
    as_matrix : bool
        Return the (n−1)×(n−1) skew block instead of its so(n−1) coordinates.

    Returns
    -------
    ndarray, shape (..., (n−1)(n−2)/2) or (..., n−1, n−1)
        Coordinates in the basis ``E_ij`` of so(n−1) (i < j ≤ n−1, lexicographic: the entries
        ``M_ij`` of the block's upper triangle), or the block itself. For n = 3, the single
        coordinate ``M_12``.
    """
    if not isinstance(inertia, Inertia):
        inertia = Inertia.from_mass_tensor(as_float_array(inertia, "inertia"))
    alg = inertia.algebra
    if not isinstance(alg, SpecialOrthogonalAlgebra) or alg.n < 3:
        raise ValueError(f"inertia must act on so(n) with n >= 3, got {alg.name}")
    n = alg.n
    X = _skew(Omega, n, "Omega")
    M = alg.hat(inertia(alg.vee(X)))
    block = M[..., : n - 1, : n - 1]
    return block if as_matrix else so(n - 1).vee(block)


def axis_rotation(q: np.ndarray) -> np.ndarray:
    """A deterministic ``g_q ∈ SO(n)`` with ``g_q e_n = q`` for unit ``q`` (..., n).

    ``q_n >= 0``: the rotation in the plane span{e_n, q} taking e_n to q and fixing its orthogonal
    complement, ``R(q) = I + K + K² / (1 + q_n)`` with ``K = q e_nᵀ − e_n qᵀ`` (identity at q = e_n).
    ``q_n < 0``: ``R(−q) F`` with ``F = diag(−1, 1, …, 1, −1)`` (the half-turn in the (e_1, e_n)
    plane), which avoids the singularity of ``R`` at ``q = −e_n``.
    """
    n = q.shape[-1]
    neg = q[..., -1] < 0
    s = np.where(neg, -1.0, 1.0)[..., None]
    p = s * q  # p_n >= 0
    e = np.zeros(n)
    e[-1] = 1.0
    K = p[..., :, None] * e - e[:, None] * p[..., None, :]
    R = np.eye(n) + K + (K @ K) / (1.0 + p[..., -1])[..., None, None]
    F = np.ones(n)
    F[0] = F[-1] = -1.0
    return np.where(neg[..., None, None], R * F, R)  # R F scales the columns of R


def lift(q, v, fibre=None) -> tuple[np.ndarray, np.ndarray]:
    """A Suslov state ``(g, Ω)`` over a pendulum state ``(q, v)``: a right inverse of the reduction.

    ``g = g_q · diag(R, 1)`` with ``g_q`` a deterministic rotation taking ``e_n`` to ``q`` and
    ``R = fibre ∈ SO(n−1)`` the point of the fibre (the SO(n−1) orbit), and ``Ω = ū ∧ e_n =
    ū e_nᵀ − e_n ūᵀ ∈ D`` with ``ū = gᵀ v`` (whose last entry ``⟨q, v⟩`` is 0). Then
    ``to_spherical_pendulum(g, Ω) == (q, v)`` for every fibre. To start the Suslov system, take
    ``Γ0 = gᵀ γ``.

    Parameters
    ----------
    q : array_like, shape (..., n)
        Unit vectors (checked to 1e-8, normalised).
    v : array_like, shape (..., n)
        Tangent vectors at q (``|⟨q, v⟩| <= 1e-8 max(1, |v|)``, the residue projected out).
    fibre : array_like, shape (..., n−1, n−1), optional
        Rotations in SO(n−1) (checked); default the identity.

    Returns
    -------
    g : ndarray, shape (..., n, n)
        In SO(n), ``g e_n = q``. For the default fibre: the rotation in the plane span{e_n, q}
        when ``q_n >= 0`` (the identity at q = e_n); ``R(−q) diag(−1, 1, …, 1, −1)`` when ``q_n < 0``.
    Omega : ndarray, shape (..., n, n)
        In the Fedorov–Kozlov D, with ``g Ω e_n = v``.
    """
    qa = as_float_array(q, "q", ndim_min=1)
    n = qa.shape[-1]
    if n < 2:
        raise ValueError(f"q must have shape (..., n) with n >= 2, got {qa.shape}")
    qa = unit(qa, "q")
    va = as_float_array(v, "v", ndim_min=1, tail=(n,))
    shapes = [qa.shape[:-1], va.shape[:-1]]
    Rf = None
    if fibre is not None:
        Rf = as_float_array(fibre, "fibre", ndim_min=2, tail=(n - 1, n - 1))
        check_rotations(Rf, "fibre", tol=ORTHO_TOL)
        shapes.append(Rf.shape[:-2])
    try:
        shape = np.broadcast_shapes(*shapes)
    except ValueError as exc:
        raise ValueError(f"the batch axes of q, v and fibre do not broadcast: {shapes}") from exc
    qa = np.broadcast_to(qa, shape + (n,))
    va = tangent(qa, np.broadcast_to(va, shape + (n,)), "q", "v")
    g = axis_rotation(qa)
    if Rf is not None:
        g = g.copy()
        g[..., :, : n - 1] = g[..., :, : n - 1] @ Rf
    u = np.einsum("...ji,...j->...i", g, va)
    u[..., -1] = 0.0
    Omega = np.zeros(shape + (n, n))
    Omega[..., :, -1] = u
    Omega[..., -1, :] = -u
    return g, Omega
