"""Models: the smallest exact form of a scene's equations, as the integrators consume it.

A :class:`Model` is built by :meth:`SuslovSystem.model`; it carries the reduced field
``xi_dot(xi, Gamma)`` in coordinates ``xi`` of D (``Omega = xi @ D.basis``) and the maps between
``xi``, coordinates and matrices. The forms, with ``B = D.basis`` (k, d), ``K_D = B K B^T``,
``L = K_D^-1 B`` and ``tau(Gamma) = vee(dV/dGamma ∧ Gamma)`` (+ the gyroscopic term)::

    reduced     K_D xi' = B (ad*_x K x + tau)                 any D (exact in the constraints)
    eigenspace  same equation with J(D) ⊂ D (2.3):            M = (xi K_D) B lies in D
    symmetric   K_D xi' = B tau                              J(D) ⊂ D and D = p of a symmetric pair (4.3)
    multiplier  K x' = ad*_x K x + tau + A^T lambda,  A x' = 0 (k = d, the reference)

Everything is precomputed at construction; the hot functions are closures over constant arrays,
with no validation. The Fedorov–Kozlov symmetric form with a diagonal ``K_D`` is O(n):
``xi_i' = (dV_i Gamma_n - Gamma_i dV_n) / (I_i + I_n)``, specialised further for linear and diagonal
quadratic potentials (two or three numpy operations per call). ``K_D`` comes from the inertia's
action (:meth:`Inertia.restrict`), never from the d×d matrix K: O(n²) for a diagonal mass tensor, so
a body in SO(256) builds its model without the 32640² matrix.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from .._rows import rows_at
from ..algebra import Subspace
from .forces import gyroscopic_torque, wedge_coordinates

if TYPE_CHECKING:  # the system builds its models: a run-time import would be a cycle
    from .system import SuslovSystem

__all__ = ["Model", "build_model"]

# Quadratic term: a dense (k*k, k) tensor below this k, matrix commutators on so(n) above it.
_TENSOR_MAX_K = 16
# Fedorov–Kozlov Omega(xi) by one matmul with the (n - 1, n*n) basis up to this n, by two writes into
# a zero matrix above it (the basis would hold ~n^3 numbers).
_FK_MATMUL_MAX_N = 32


class Model:
    """The exact reduced equations of a scene, in the form an integrator runs.

    Implements :class:`~liesuslov.mechanics.protocol.ModelProtocol`.

    Attributes
    ----------
    form : str
        ``"symmetric"``, ``"eigenspace"``, ``"reduced"`` or ``"multiplier"``.
    k : int
        Dimension of ``xi`` (``d`` for "multiplier").
    has_gamma : bool
        Whether ``Gamma`` is part of the state.
    n : int or None
        Matrix size of the algebra's representation (n for so(n), 3 for se(2), 4 for se(3)).
    state_dim : int
        ``k + n`` with ``Gamma``, else ``k``.
    algebra : LieAlgebra
    subspace : Subspace
        The D used (the whole algebra for "multiplier").
    system : SuslovSystem
        Back-reference.
    fedorov_kozlov : bool
        True iff ``xi`` are the Fedorov–Kozlov coordinates: ``Omega = sum_i xi_i E_in``, i.e.
        ``Omega = u e_n^T - e_n u^T`` with ``u = (xi, 0)`` (False for "multiplier").
    reduced_inertia : ndarray, shape (k, k)
        ``K_D`` (the full K for "multiplier").
    path : str
        Which specialised code runs ``xi_dot`` (for :meth:`description` and tests).

    Notes
    -----
    The maps are instance attributes (closures over precomputed arrays), all batched over leading
    axes, with ``Gamma`` None when not ``has_gamma``:

    * ``xi_dot(xi, Gamma) -> (..., k)``: the reduced field (hot path, no validation). Pass ``xi`` and
      ``Gamma`` with the same batch shape: where the field does not depend on ``xi`` (symmetric
      form) the result takes Gamma's.
    * ``omega_matrix(xi) -> (..., n, n)``: Omega in the representation, linear in ``xi`` (one matmul with
      the flattened basis; the RKMK kernels read that basis off ``omega_matrix(eye(k))`` once).
    * ``omega_coords(xi) -> (..., d)``: Omega in the algebra's coordinates.
    * ``xi_from_coords(x) -> (..., k)``: ``xi`` of a point ``x`` of D (the caller checks ``x`` in D).
    * ``Gamma_dot(xi, Gamma) -> (..., n)``: ``-Omega Gamma`` (reference; integrators move Gamma by
      the group action).

    A model pickles as its recipe ``(system, has_gamma, form)`` and is rebuilt on unpickling (the
    maps are closures over precomputed arrays; rebuilding gives the same arrays, so the same numbers).
    """

    def __init__(self, *, system: SuslovSystem, form: str, subspace: Subspace, has_gamma: bool,
                 fedorov_kozlov: bool, reduced_inertia: np.ndarray, xi_dot: Callable,
                 omega_matrix: Callable, omega_coords: Callable, xi_from_coords: Callable,
                 Gamma_dot: Callable, path: str) -> None:
        self.system = system
        self.form = form
        self.subspace = subspace
        self.algebra = system.algebra
        self.k = subspace.dim
        self.has_gamma = bool(has_gamma)
        self.n = system.n
        self.state_dim = self.k + (self.n if self.has_gamma else 0)
        self.fedorov_kozlov = bool(fedorov_kozlov)
        self.reduced_inertia = reduced_inertia
        self.xi_dot = xi_dot
        self.omega_matrix = omega_matrix
        self.omega_coords = omega_coords
        self.xi_from_coords = xi_from_coords
        self.Gamma_dot = Gamma_dot
        self.path = path

    def __reduce__(self):
        # Closures do not pickle; the system (which pickles without its model cache) rebuilds them.
        return _rebuild_model, (self.system, self.has_gamma, self.form)

    def vector_field(self, t, y) -> np.ndarray:
        """``dy/dt`` for the flat state ``y = concat(xi, Gamma)``, shape (state_dim,) or (..., state_dim)."""
        y = np.asarray(y, dtype=float)
        xi = y[..., :self.k]
        if not self.has_gamma:
            return self.xi_dot(xi, None)
        G = y[..., self.k:]
        return np.concatenate([self.xi_dot(xi, G), self.Gamma_dot(xi, G)], axis=-1)

    def description(self) -> str:
        """One line: the form, the state and what the model leaves out."""
        sysm = self.system
        d = self.algebra.dim
        state = f"xi ({self.k})" + (f" + Gamma ({self.n})" if self.has_gamma else "")
        dropped = []
        if self.form != "multiplier" and self.k < d:
            r = d - self.k
            dropped.append(f"{r} constrained coordinate(s) of Omega and the multiplier(s)")
        if not self.has_gamma and sysm.is_so:
            dropped.append("Gamma (V = 0)")
        if self.form == "symmetric":
            dropped.append("the quadratic term pr_D[J Omega, Omega] (identically 0)")
        text = f"{self.form} form on {self.algebra.name} [{self.path}]: state {state} = {self.state_dim}"
        return text + ("; dropped: " + ", ".join(dropped) if dropped else "")

    def __repr__(self) -> str:
        return f"Model({self.description()})"


# ====================================================================== construction
def _rebuild_model(system: SuslovSystem, has_gamma: bool, form: str) -> Model:
    """Unpickling: the system's (cached) model of ``form`` with or without Gamma."""
    return system.model(gamma=has_gamma, form=form)


def build_model(system: SuslovSystem, form: str, has_gamma: bool) -> Model:
    """Build the :class:`Model` of ``system`` in ``form`` (already checked to hold)."""
    if form == "multiplier":
        return _multiplier_model(system, has_gamma)
    D = system.constraints
    B = np.ascontiguousarray(D.basis)
    # K_D = B K B^T from the inertia's action (O(n^2) for the Fedorov–Kozlov D and a diagonal mass
    # tensor): the d×d matrix K is never formed here.
    KD = system.inertia.restrict(D)
    fk = system.is_fedorov_kozlov
    maps = _fk_maps(system) if fk else _basis_maps(system, B)
    if fk and form == "symmetric":
        xi_dot, path = _fk_symmetric_field(system, KD)
    else:
        xi_dot, path = _general_field(system, B, KD, form)
    return Model(system=system, form=form, subspace=D, has_gamma=has_gamma, fedorov_kozlov=fk,
                 reduced_inertia=KD, xi_dot=xi_dot, path=path, **maps)


# ---------------------------------------------------------------------- coordinate maps
def _fk_maps(system: SuslovSystem) -> dict:
    """Maps for Omega = sum_i xi_i E_in: only the last row and column of Omega are nonzero."""
    n = system.n
    m = n - 1
    d = system.algebra.dim
    idx = np.array([system.algebra.index(i, m) for i in range(m)])
    if n <= _FK_MATMUL_MAX_N:
        R = np.zeros((m, n, n))  # R[i] = E_in
        R[np.arange(m), np.arange(m), m] = 1.0
        R[np.arange(m), m, np.arange(m)] = -1.0
        R = R.reshape(m, n * n)
        nn = (n, n)

        def omega_matrix(xi):  # one matmul with the flattened basis E_in (entries 0, ±1: exact)
            return (xi @ R).reshape(xi.shape[:-1] + nn)
    else:
        def omega_matrix(xi):  # O(n^2) memory, no (n - 1, n^2) basis
            X = np.zeros(xi.shape[:-1] + (n, n))
            X[..., :m, m] = xi
            X[..., m, :m] = -xi
            return X

    # x_j = xi_i at j = idx[i], 0 elsewhere: a take from (xi, 0) (~0.5 µs less than x[..., idx] = xi)
    from_padded = np.full(d, m)
    from_padded[idx] = np.arange(m)

    def omega_coords(xi):
        padded = np.zeros(xi.shape[:-1] + (m + 1,))
        padded[..., :m] = xi
        return padded.take(from_padded, axis=-1)

    def xi_from_coords(x):
        return np.asarray(x).take(idx, axis=-1)  # (x[..., idx] is ~1.5 µs slower on one vector)

    def Gamma_dot(xi, G):  # -Omega Gamma: (-xi_i Gamma_n, sum_i xi_i Gamma_i)
        return np.concatenate([-xi * G[..., m:], np.sum(xi * G[..., :m], axis=-1, keepdims=True)], axis=-1)

    return dict(omega_matrix=omega_matrix, omega_coords=omega_coords, xi_from_coords=xi_from_coords,
                Gamma_dot=Gamma_dot)


def _basis_maps(system: SuslovSystem, B: np.ndarray) -> dict:
    """Maps through the basis rows B (k, d) of D: x = xi @ B."""
    alg = system.algebra
    Bt = np.ascontiguousarray(B.T)
    r = alg.matrix_size
    if r is None:
        def omega_matrix(xi):
            raise ValueError(f"{alg.name} has no matrix representation: no omega_matrix")
        Gamma_dot = omega_matrix
    else:
        BR = alg.hat(B).reshape(B.shape[0], r * r)  # hat of the basis rows (no (d, r, r) basis tensor on so(n))

        def omega_matrix(xi):
            return rows_at(xi, BR).reshape(xi.shape[:-1] + (r, r))

        def Gamma_dot(xi, G):
            return -(rows_at(xi, BR).reshape(xi.shape[:-1] + (r, r)) @ G[..., :, None])[..., 0]

    def omega_coords(xi):
        return rows_at(xi, B)

    def xi_from_coords(x):
        return rows_at(x, Bt)

    return dict(omega_matrix=omega_matrix, omega_coords=omega_coords, xi_from_coords=xi_from_coords,
                Gamma_dot=Gamma_dot)


# ---------------------------------------------------------------------- general fields
def _general_field(system: SuslovSystem, B, KD, form: str):
    """xi' = L (ad*_x K x + tau(Gamma) + gyro) for any D, as a sum of precomputed terms."""
    alg = system.algebra
    k = B.shape[0]
    L = np.linalg.solve(KD, B)  # K_D^-1 B, (k, d)
    Lt = np.ascontiguousarray(L.T)  # (d, k): row-vector form, out = f @ Lt
    # B K: the rows J(B_a) (K symmetric); eigenspace: J(D) ⊂ D, so B K = K_D B exactly in D
    BK = KD @ B if form == "eigenspace" else system.inertia(B)
    terms: list[Callable] = []
    parts: list[str] = []
    if form != "symmetric":
        if k <= _TENSOR_MAX_K or not system.is_so:
            # Q[a, b] = L ad*_{B_a} K B_b, symmetrised: xi' = (xi ⊗ xi) @ Q
            a1, b1 = np.broadcast_arrays(B[:, None, :], BK[None, :, :])
            Q = alg.coad(a1, b1) @ Lt  # (k, k, k)
            Qf = np.ascontiguousarray((0.5 * (Q + Q.transpose(1, 0, 2))).reshape(k * k, k))
            kk = k * k

            def quadratic(xi, G):
                return rows_at((xi[..., :, None] * xi[..., None, :]).reshape(xi.shape[:-1] + (kk,)), Qf)
            parts.append("quadratic tensor")
        else:  # so(n) with a large D: [M, X] = P - P^T with P = M X, one matmul
            n = system.n
            BR, BKR = alg.hat(B).reshape(k, n * n), alg.hat(BK).reshape(k, n * n)
            W = _skew_map(n, Lt)

            def quadratic(xi, G):
                sh = xi.shape[:-1]
                X = rows_at(xi, BR).reshape(sh + (n, n))
                M = rows_at(xi, BKR).reshape(sh + (n, n))
                return rows_at((M @ X).reshape(sh + (n * n,)), W)
            parts.append("quadratic by commutators")
        terms.append(quadratic)
    pot = system.potential
    if system.has_potential:
        n = system.n
        if pot.kind == "linear":
            T1 = wedge_coordinates(pot.B, np.eye(n)) @ Lt  # (n, k): tau is linear in Gamma

            def potential_term(xi, G):
                return rows_at(G, T1)
            parts.append("linear potential")
        elif pot.kind == "quadratic":
            S = pot.matrix  # tau = sum_lm G_l G_m vee(S e_l ∧ e_m)
            T2 = (wedge_coordinates(S.T[:, None, :], np.eye(n)[None, :, :]) @ Lt).reshape(n * n, k)
            nn = n * n

            def potential_term(xi, G):
                return rows_at((G[..., :, None] * G[..., None, :]).reshape(G.shape[:-1] + (nn,)), T2)
            parts.append("quadratic potential")
        else:
            W = _skew_map(n, Lt)
            grad = pot.grad
            nn = n * n

            def potential_term(xi, G):
                g = grad(G)
                return rows_at((g[..., :, None] * G[..., None, :]).reshape(G.shape[:-1] + (nn,)), W)
            parts.append("potential gradient")
        terms.append(potential_term)
    if system.gyroscopic != 0.0:
        # bilinear: gyro[a, j] = L eps vee(w(B_a) ∧ e_j), xi' = (xi ⊗ Gamma) @ Gf
        Gf = gyroscopic_torque(B[:, None, :], np.eye(3)[None, :, :], system.gyroscopic) @ Lt
        Gf = Gf.reshape(3 * k, k)
        k3 = 3 * k

        def gyro_term(xi, G):
            return rows_at((xi[..., :, None] * G[..., None, :]).reshape(G.shape[:-1] + (k3,)), Gf)
        terms.append(gyro_term)
        parts.append("gyroscopic")
    return _sum_terms(terms), ", ".join(parts) or "zero field"


def _sum_terms(terms: list[Callable]) -> Callable:
    if not terms:
        def xi_dot(xi, G):
            return np.zeros_like(xi)
        return xi_dot
    if len(terms) == 1:
        return terms[0]
    if len(terms) == 2:
        t0, t1 = terms

        def xi_dot(xi, G):
            return t0(xi, G) + t1(xi, G)
        return xi_dot
    first, rest = terms[0], terms[1:]

    def xi_dot(xi, G):
        out = first(xi, G)
        for t in rest:
            out = out + t(xi, G)
        return out
    return xi_dot


def _skew_map(n: int, Lt: np.ndarray) -> np.ndarray:
    """W (n*n, k) with ``P.ravel() @ W == vee(P - P^T) @ Lt`` for any n×n matrix P."""
    r, c = np.triu_indices(n, 1)
    W = np.zeros((n * n, Lt.shape[1]))
    W[r * n + c] += Lt
    W[c * n + r] -= Lt
    return W


# ---------------------------------------------------------------------- Fedorov–Kozlov (4.3)
def _fk_symmetric_field(system: SuslovSystem, KD: np.ndarray):
    """(4.3): K_D xi' = t with t_i = dV_i Gamma_n - Gamma_i dV_n (+ gyroscopic), O(n) for diagonal K_D."""
    n = system.n
    m = n - 1
    pot = system.potential
    eps = system.gyroscopic
    kd = np.diag(KD).copy()
    diagonal = np.array_equal(KD, np.diag(kd))
    KDinv = None if diagonal else np.linalg.inv(KD)  # O(n^3): only when K_D is not diagonal
    field: Callable | None = None
    if not system.has_potential:
        path = "V = 0"
    elif diagonal and pot.kind == "linear":
        b = pot.B
        c1, c2 = b[:m] / kd, b[m] / kd
        if b[m] == 0.0:  # Kharlamova: xi_i' = B_i Gamma_n / (I_i + I_n)
            def field(xi, G):
                return G[..., m:] * c1
        elif not np.any(b[:m]):  # Lagrange: xi_i' = -B_n Gamma_i / (I_i + I_n)
            c2n = -c2

            def field(xi, G):
                return G[..., :m] * c2n
        else:
            def field(xi, G):
                return G[..., m:] * c1 - G[..., :m] * c2
        path = "Fedorov–Kozlov O(n), linear potential"
    elif diagonal and pot.kind == "quadratic" and pot.diagonal is not None:
        c = (pot.diagonal[:m] - pot.diagonal[m]) / kd  # Klebsh–Tisserand: xi_i' = c_i Gamma_i Gamma_n

        def field(xi, G):
            return G[..., :m] * G[..., m:] * c
        path = "Fedorov–Kozlov O(n), diagonal quadratic potential"
    else:
        grad = pot.grad if pot.kind != "quadratic" else (lambda G, S=pot.matrix: rows_at(G, S))
        if diagonal:
            inv = 1.0 / kd

            def field(xi, G):
                g = grad(G)
                return (g[..., :m] * G[..., m:] - G[..., :m] * g[..., m:]) * inv
            path = "Fedorov–Kozlov O(n), potential gradient"
        else:
            def field(xi, G):
                g = grad(G)
                return rows_at(g[..., :m] * G[..., m:] - G[..., :m] * g[..., m:], KDinv)
            path = "Fedorov–Kozlov O(n^2) (K_D not diagonal), potential gradient"
    if eps == 0.0:
        if field is None:
            def field(xi, G):
                return np.zeros_like(xi)
        return field, path
    # n = 3: eps vee(w ∧ Gamma) on (E_13, E_23) is eps Gamma_3 (w_1, w_2) = eps Gamma_3 (-xi_2, xi_1)
    sign = eps * np.array([-1.0, 1.0])
    if diagonal:
        cg = sign / kd

        def gyro(xi, G):
            return G[..., 2:3] * xi[..., ::-1] * cg
    else:
        Cg = np.diag(sign) @ KDinv

        def gyro(xi, G):
            return rows_at(G[..., 2:3] * xi[..., ::-1], Cg)
    if field is None:
        return gyro, path + " + gyroscopic"
    base = field

    def field_gyro(xi, G):
        return base(xi, G) + gyro(xi, G)
    return field_gyro, path + " + gyroscopic"


# ---------------------------------------------------------------------- reference
def _multiplier_model(system: SuslovSystem, has_gamma: bool) -> Model:
    """The reference: full coordinates, multipliers from the constraints (cross-checks)."""
    alg = system.algebra
    d = alg.dim
    whole = Subspace(alg, np.eye(d))
    A, Kinv, Sinv = system.reaction
    torque = system.torque

    def xi_dot(x, G):
        f = torque(x, G)
        lam = -rows_at(rows_at(rows_at(f, Kinv), A.T), Sinv)
        return rows_at(f + rows_at(lam, A), Kinv)

    def omega_coords(x):
        return np.array(x, dtype=float, copy=True)

    if alg.representation is None:
        def omega_matrix(x):
            raise ValueError(f"{alg.name} has no matrix representation: no omega_matrix")
        Gamma_dot = omega_matrix
    else:
        omega_matrix = alg.hat

        def Gamma_dot(x, G):
            return -(alg.hat(x) @ G[..., :, None])[..., 0]

    return Model(system=system, form="multiplier", subspace=whole, has_gamma=has_gamma, fedorov_kozlov=False,
                 reduced_inertia=system.inertia.matrix, xi_dot=xi_dot, omega_matrix=omega_matrix,
                 omega_coords=omega_coords, xi_from_coords=omega_coords, Gamma_dot=Gamma_dot,
                 path="reference, multipliers solved at each call")
