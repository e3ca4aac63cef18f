"""Acceptance-style contract tests: the public API exactly as ``../shared/API.md`` writes it.

Every check compares against references written here from ``../shared/MATH.md`` and the paper (own
hat/vee in lexicographic order, own equations of motion integrated by scipy at rtol 1e-12, closed
forms derived by hand), never against ``ls.analytic`` or library internals.
"""

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg

import liesuslov as ls

# ======================================================================================== references


def ref_pairs(n):
    """Lexicographic (i, j), i < j, 0-based: the basis order fixed by MATH.md."""
    return [(i, j) for i in range(n) for j in range(i + 1, n)]


def ref_hat(x, n):
    x = np.asarray(x, dtype=float)
    X = np.zeros(x.shape[:-1] + (n, n))
    for k, (i, j) in enumerate(ref_pairs(n)):
        X[..., i, j] = x[..., k]
        X[..., j, i] = -x[..., k]
    return X


def ref_vee(X):
    n = X.shape[-1]
    return np.stack([X[..., i, j] for (i, j) in ref_pairs(n)], axis=-1)


def cross_mat(w):
    """hat(w) with hat(w) v = w x v."""
    w = np.asarray(w, dtype=float)
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def w_of(x):
    """so(3) coordinates (O12, O13, O23) -> w = (-O23, O13, -O12)."""
    x = np.asarray(x, dtype=float)
    return np.stack([-x[..., 2], x[..., 1], -x[..., 0]], axis=-1)


def x_of(w):
    """w -> so(3) coordinates (O12, O13, O23) = (-w3, w2, -w1)."""
    w = np.asarray(w, dtype=float)
    return np.stack([-w[..., 2], w[..., 1], -w[..., 0]], axis=-1)


def ref_K(I):
    """Matrix of J(Omega) = I Omega + Omega I in the basis, K[a, b] = -1/2 tr(E_a (I E_b + E_b I))."""
    n = I.shape[0]
    d = n * (n - 1) // 2
    E = ref_hat(np.eye(d), n)
    JE = I @ E + E @ I
    return -0.5 * np.einsum("aij,bji->ab", E, JE)


def fk_rows(n):
    """Coordinates of E_in, i < n (my own basis of the Fedorov-Kozlov D)."""
    pairs = ref_pairs(n)
    rows = np.zeros((n - 1, len(pairs)))
    for i in range(n - 1):
        rows[i, pairs.index((i, n - 1))] = 1.0
    return rows


def rand_rot(rng, n):
    Q, R = np.linalg.qr(rng.standard_normal((n, n)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Q


def unit(rng, shape, n):
    G = rng.standard_normal(tuple(shape) + (n,))
    return G / np.linalg.norm(G, axis=-1, keepdims=True)


def rand_spd(rng, n, lo=1.0):
    A = rng.standard_normal((n, n))
    return A @ A.T / n + lo * np.eye(n)


def solve_ref(f, y0, t_eval):
    t_eval = np.asarray(t_eval, dtype=float)
    r = scipy.integrate.solve_ivp(f, (t_eval[0], t_eval[-1]), y0, method="DOP853", t_eval=t_eval,
                                  rtol=1e-12, atol=1e-13)
    assert r.success
    return r.y.T


def suslov_ref(I, rows, *, grad=None, eps=0.0, with_g=False):
    """(2.2) on so(n) eliminated on D = span(rows): (d^T K d) xi' = d^T([M, Omega] + dV ∧ Gamma (+ eps Gamma x w)).

    State y = (x in so(n) coordinates (d,), Gamma (n,), g (n*n,) optional); x stays in D.
    """
    n = I.shape[0]
    K = ref_K(I)
    B = np.asarray(rows, dtype=float)
    KD = B @ K @ B.T

    def f(t, y):
        d = K.shape[0]
        x = y[:d]
        G = y[d:d + n]
        X = ref_hat(x, n)
        M = I @ X + X @ I
        T = M @ X - X @ M
        if grad is not None:
            dV = grad(G)
            T = T + np.outer(dV, G) - np.outer(G, dV)
        if eps:
            T = T + cross_mat(eps * np.cross(G, w_of(x)))
        xidot = np.linalg.solve(KD, B @ ref_vee(T))
        out = [xidot @ B, -X @ G]
        if with_g:
            g = y[d + n:].reshape(n, n)
            out.append((g @ X).ravel())
        return np.concatenate(out)

    return f


def frob(A):
    return float(np.max(np.abs(A)))


# ======================================================================================== algebra


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_so_dim_and_basis_order(n):
    alg = ls.so(n)
    d = n * (n - 1) // 2
    assert alg.dim == d
    E = alg.hat(np.eye(d))
    assert E.shape == (d, n, n)
    for k, (i, j) in enumerate(ref_pairs(n)):
        want = np.zeros((n, n))
        want[i, j], want[j, i] = 1.0, -1.0  # E_ij = e_i e_j^T - e_j e_i^T
        np.testing.assert_array_equal(E[k], want)


@pytest.mark.parametrize("n", [3, 4, 5])
def test_hat_vee_two_batch_axes(n):
    rng = np.random.default_rng(n)
    alg = ls.so(n)
    x = rng.standard_normal((2, 3, alg.dim))
    X = alg.hat(x)
    assert X.shape == (2, 3, n, n)
    np.testing.assert_allclose(X, ref_hat(x, n), rtol=0, atol=1e-15)
    v = alg.vee(X)
    assert v.shape == (2, 3, alg.dim)
    np.testing.assert_allclose(v, x, rtol=0, atol=1e-15)
    np.testing.assert_allclose(alg.vee(ref_hat(x, n)), x, rtol=0, atol=1e-15)


@pytest.mark.parametrize("n", [3, 4, 5])
def test_pairing_is_dot_of_coordinates(n):
    rng = np.random.default_rng(10 + n)
    alg = ls.so(n)
    x, y = rng.standard_normal((2, 4, alg.dim))
    pair = -0.5 * np.einsum("...ij,...ji->...", alg.hat(x), alg.hat(y))
    np.testing.assert_allclose(pair, np.sum(x * y, axis=-1), rtol=1e-13)
    E = alg.hat(np.eye(alg.dim))
    np.testing.assert_allclose(-0.5 * np.einsum("aij,bji->ab", E, E), np.eye(alg.dim), atol=1e-15)


@pytest.mark.parametrize("n", [3, 4, 5])
def test_bracket_is_commutator(n):
    rng = np.random.default_rng(20 + n)
    alg = ls.so(n)
    x, y = rng.standard_normal((2, 2, 3, alg.dim))
    b = alg.bracket(x, y)
    assert b.shape == (2, 3, alg.dim)
    X, Y = ref_hat(x, n), ref_hat(y, n)
    np.testing.assert_allclose(b, ref_vee(X @ Y - Y @ X), rtol=0, atol=1e-13)


@pytest.mark.parametrize("n", [3, 4, 5])
def test_structure_constants_convention(n):
    alg = ls.so(n)
    d = alg.dim
    C = np.asarray(alg.structure_constants)
    assert C.shape == (d, d, d)
    E = ref_hat(np.eye(d), n)
    comm = np.einsum("iab,jbc->ijac", E, E) - np.einsum("jab,ibc->ijac", E, E)
    np.testing.assert_allclose(comm, np.einsum("ijk,kab->ijab", C, E), rtol=0, atol=1e-14)
    # [E_12, E_13] = -E_23 (hand computation): C[(1,2), (1,3), (2,3)] = -1
    p = ref_pairs(n)
    assert C[p.index((0, 1)), p.index((0, 2)), p.index((1, 2))] == pytest.approx(-1.0)


def test_so3_vector_form():
    so3 = ls.so(3)
    rng = np.random.default_rng(3)
    a, b, v = rng.standard_normal((3, 3))
    # hat(w) v = w x v with w = (-O23, O13, -O12)
    np.testing.assert_allclose(so3.hat(x_of(a)) @ v, np.cross(a, v), rtol=1e-14)
    np.testing.assert_allclose(so3.hat(x_of(a)), cross_mat(a), rtol=0, atol=0)
    # [hat a, hat b] = hat(a x b)
    np.testing.assert_allclose(so3.bracket(x_of(a), x_of(b)), x_of(np.cross(a, b)), rtol=1e-13)
    # coordinate 0 is Omega_12 = -w3
    assert so3.hat([1.0, 0.0, 0.0])[0, 1] == 1.0
    np.testing.assert_allclose(w_of(np.array([1.0, 0.0, 0.0])), [0.0, 0.0, -1.0])


def test_wedge_convention():
    rng = np.random.default_rng(4)
    x, y = rng.standard_normal((2, 2, 3, 5))
    np.testing.assert_allclose(ls.wedge(x, y), x[..., :, None] * y[..., None, :] - y[..., :, None] * x[..., None, :])
    a, b = rng.standard_normal((2, 3))
    np.testing.assert_allclose(ls.wedge(a, b), cross_mat(np.cross(b, a)), atol=1e-15)


def test_lie_algebra_from_structure_constants():
    so3 = ls.so(3)
    alg = ls.LieAlgebra(so3.structure_constants)
    assert alg.dim == 3
    rng = np.random.default_rng(5)
    x, y = rng.standard_normal((2, 2, 3, 3))
    np.testing.assert_allclose(alg.bracket(x, y), so3.bracket(x, y), rtol=0, atol=1e-13)
    np.testing.assert_allclose(np.asarray(alg.structure_constants), so3.structure_constants)
    # [e_i, e_j] = sum_k C[i, j, k] e_k for an arbitrary (solvable) algebra: [e1, e2] = e2, [e1, e3] = 2 e3
    C = np.zeros((3, 3, 3))
    C[0, 1, 1], C[1, 0, 1] = 1.0, -1.0
    C[0, 2, 2], C[2, 0, 2] = 2.0, -2.0
    a = ls.LieAlgebra(C)
    np.testing.assert_allclose(a.bracket([1.0, 0, 0], [0, 1.0, 0]), [0, 1.0, 0])
    np.testing.assert_allclose(a.bracket([0, 0, 1.0], [1.0, 0, 0]), [0, 0, -2.0])


def test_lie_algebra_rejects_bad_constants():
    with pytest.raises(ValueError):
        ls.LieAlgebra(np.ones((3, 3, 3)))  # not antisymmetric
    rng = np.random.default_rng(6)
    C = rng.standard_normal((3, 3, 3))
    C = C - C.transpose(1, 0, 2)  # antisymmetric, Jacobi fails almost surely
    with pytest.raises(ValueError, match="(?i)jacobi"):
        ls.LieAlgebra(C)


@pytest.mark.parametrize("n,d,m", [(2, 3, 3), (3, 6, 4)])
def test_se_algebras(n, d, m):
    alg = ls.se(n)
    assert alg.dim == d
    C = np.asarray(alg.structure_constants)
    np.testing.assert_allclose(C, -C.transpose(1, 0, 2), atol=1e-14)
    rng = np.random.default_rng(7)
    x, y = rng.standard_normal((2, 2, 3, d))
    X, Y = alg.hat(x), alg.hat(y)
    assert X.shape == (2, 3, m, m)
    np.testing.assert_allclose(X[..., -1, :], 0.0, atol=1e-15)  # affine: last row zero
    np.testing.assert_allclose(X @ Y - Y @ X, alg.hat(alg.bracket(x, y)), atol=1e-12)
    np.testing.assert_allclose(alg.vee(X), x, atol=1e-12)
    rot = X[..., :n, :n]
    np.testing.assert_allclose(rot, -np.swapaxes(rot, -1, -2), atol=1e-15)


# ======================================================================================== subspaces


def test_annihilator_basis():
    so4 = ls.so(4)
    rng = np.random.default_rng(8)
    A = rng.standard_normal((2, 6))
    D = ls.Subspace.annihilator(so4, A)
    assert D.dim == 4
    B = np.asarray(D.basis)
    assert B.shape == (4, 6)
    np.testing.assert_allclose(A @ B.T, 0.0, atol=1e-12)
    np.testing.assert_allclose(B @ B.T, np.eye(4), atol=1e-12)
    Bm = so4.hat(B)  # orthonormal for -1/2 tr(AB)
    np.testing.assert_allclose(-0.5 * np.einsum("aij,bji->ab", Bm, Bm), np.eye(4), atol=1e-12)


def test_subspace_span_of_rows():
    so4 = ls.so(4)
    rng = np.random.default_rng(9)
    R = rng.standard_normal((3, 6))
    S = ls.Subspace(so4, R)
    assert S.dim == 3
    B = np.asarray(S.basis)
    np.testing.assert_allclose(B @ B.T, np.eye(3), atol=1e-12)
    P = B.T @ B  # same span as R
    np.testing.assert_allclose(R @ P, R, atol=1e-12)
    # dependent spanning rows: the span has the rank
    S2 = ls.Subspace(so4, np.vstack([R[:2], R[0] + 2 * R[1]]))
    assert S2.dim == 2


def test_whole_algebra_subspaces():
    so3 = ls.so(3)
    assert ls.Subspace(so3, np.eye(3)).dim == 3
    assert ls.Subspace.annihilator(so3, np.zeros((0, 3))).dim == 3


def test_is_subalgebra():
    so3, so4 = ls.so(3), ls.so(4)
    assert ls.suslov_distribution(3).is_subalgebra() is False  # Suslov: nonholonomic
    assert ls.suslov_distribution(4).is_subalgebra() is False
    assert ls.Subspace(so3, [[1.0, 0.0, 0.0]]).is_subalgebra() is True
    p = ref_pairs(4)
    so3_block = np.eye(6)[[p.index((0, 1)), p.index((0, 2)), p.index((1, 2))]]
    assert ls.Subspace(so4, so3_block).is_subalgebra() is True
    assert ls.Subspace.annihilator(so4, fk_rows(4)).is_subalgebra() is True  # = so(3) block
    assert ls.Subspace(so4, np.eye(6)[[0, 5]]).is_subalgebra() is True  # E12, E34 commute
    assert ls.Subspace(so4, np.eye(6)[[0, 1]]).is_subalgebra() is False  # [E12, E13] = -E23


@pytest.mark.parametrize("n", [3, 4, 5])
def test_is_symmetric_pair(n):
    alg = ls.so(n)
    p = ls.suslov_distribution(n)
    k = ls.Subspace.annihilator(alg, fk_rows(n))  # so(n-1)
    assert ls.is_symmetric_pair(k, p) is True
    if n >= 4:
        assert ls.is_symmetric_pair(p, k) is False
    half = ls.Subspace(alg, np.eye(alg.dim)[: alg.dim // 2])
    rest = ls.Subspace(alg, np.eye(alg.dim)[alg.dim // 2:])
    if n >= 4:
        assert ls.is_symmetric_pair(half, rest) is False
    # not a direct sum of the whole algebra
    assert ls.is_symmetric_pair(k, ls.Subspace(alg, np.asarray(p.basis)[:-1])) is False
    # dimensions add up but the sum is not direct
    assert ls.is_symmetric_pair(ls.Subspace(alg, np.asarray(p.basis)[:1] + 0 * np.asarray(k.basis)[:1]), p) is False


@pytest.mark.parametrize("n", [3, 4, 5, 7])
def test_suslov_distribution(n):
    alg = ls.so(n)
    D = ls.suslov_distribution(n)
    assert D.dim == n - 1
    B = np.asarray(D.basis)
    np.testing.assert_allclose(B @ B.T, np.eye(n - 1), atol=1e-14)
    X = alg.hat(B)
    np.testing.assert_array_equal(X[:, : n - 1, : n - 1], 0.0)  # Omega_ij = 0 for i, j <= n-1
    np.testing.assert_allclose(B.T @ B @ fk_rows(n).T, fk_rows(n).T, atol=1e-14)  # spans every E_in


# ======================================================================================== inertia


@pytest.mark.parametrize("n", [3, 4, 5, 12])
def test_inertia_from_mass_tensor(n):
    rng = np.random.default_rng(30 + n)
    I = rand_spd(rng, n)
    J = ls.Inertia.from_mass_tensor(I)
    sys = ls.SuslovSystem(J, constraints=ls.Subspace(ls.so(n), np.eye(n * (n - 1) // 2)))
    x = rng.standard_normal((2, 3, n * (n - 1) // 2))
    X = ref_hat(x, n)
    want = 0.5 * (-0.5) * np.einsum("...ij,...ji->...", I @ X + X @ I, X)  # 1/2 <J Omega, Omega>
    E = sys.energy(x)
    assert E.shape == (2, 3)
    np.testing.assert_allclose(E, want, rtol=1e-12)
    np.testing.assert_allclose(sys.energy(X), want, rtol=1e-12)
    np.testing.assert_allclose(J(x), ref_vee(I @ X + X @ I), rtol=1e-12, atol=1e-13)


def test_inertia_3d_principal_moments():
    """J = tr(I) Id - I acts on w: 1/2 <J Omega, Omega> = 1/2 w^T J w."""
    rng = np.random.default_rng(31)
    I = rand_spd(rng, 3)
    Jw = np.trace(I) * np.eye(3) - I
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), constraints=ls.Subspace(ls.so(3), np.eye(3)))
    w = rng.standard_normal((4, 3))
    np.testing.assert_allclose(sys.energy(x_of(w)), 0.5 * np.einsum("bi,ij,bj->b", w, Jw, w), rtol=1e-12)


def test_inertia_general_K_and_accepts_indefinite_mass_tensor():
    rng = np.random.default_rng(32)
    so4 = ls.so(4)
    K = rand_spd(rng, 6)
    sys = ls.SuslovSystem(ls.Inertia(so4, K), constraints=ls.Subspace(so4, np.eye(6)))
    x = rng.standard_normal((2, 3, 6))
    np.testing.assert_allclose(sys.energy(x), 0.5 * np.einsum("...i,ij,...j->...", x, K, x), rtol=1e-12)
    ls.Inertia.from_mass_tensor(np.diag([-0.1, 1.0, 2.0]))  # lambda_i + lambda_j > 0: J > 0


# ======================================================================================== potentials, energy


def test_potentials_and_energy():
    rng = np.random.default_rng(40)
    n = 4
    I = np.diag([1.0, 2.0, 3.0, 4.0])
    J = ls.Inertia.from_mass_tensor(I)
    xi = rng.standard_normal((2, 3, n - 1))
    x = xi @ fk_rows(n)
    G = unit(rng, (2, 3), n)
    T = 0.5 * np.sum(xi ** 2 * (np.diag(I)[:3] + I[3, 3]), axis=-1)
    B = rng.standard_normal(n)
    S = rand_spd(rng, n)
    cases = [
        (None, np.zeros((2, 3))),
        (ls.LinearPotential(B), G @ B),
        (ls.QuadraticPotential(B), 0.5 * np.sum(B * G ** 2, axis=-1)),
        (ls.QuadraticPotential(S), 0.5 * np.einsum("...i,ij,...j->...", G, S, G)),
        (ls.Potential(lambda g: np.sum(g ** 3, axis=-1), lambda g: 3 * g ** 2), np.sum(G ** 3, axis=-1)),
    ]
    for pot, V in cases:
        sys = ls.SuslovSystem(J, constraints=ls.suslov_distribution(n), potential=pot, gyroscopic=0.0)
        E = sys.energy(x, G) if pot is not None else sys.energy(x)
        assert E.shape == (2, 3)
        np.testing.assert_allclose(E, T + V, rtol=1e-12)
        np.testing.assert_allclose(sys.energy(ref_hat(x, n), Gamma=G), T + V, rtol=1e-12)


def test_system_defaults():
    J = ls.Inertia.from_mass_tensor([1.0, 2.0, 3.0, 4.0])
    sys = ls.SuslovSystem(J)
    bad = np.zeros(6)
    bad[0] = 1.0  # Omega_12 != 0: not in the default Fedorov-Kozlov D
    with pytest.raises(ValueError, match="Omega0"):
        ls.integrate(sys, bad, (0.0, 1.0), h=0.1)
    sol = ls.integrate(sys, fk_rows(4)[0] + 2 * fk_rows(4)[2], (0.0, 1.0), h=0.1)
    assert sol.Gamma is None and sol.g is None
    # gyroscopic (n = 3 only) and potential=None on a general algebra
    with pytest.raises(ValueError, match="gyroscopic"):
        ls.SuslovSystem(J, gyroscopic=0.5)
    alg = ls.se(3)
    Jg = ls.Inertia(alg, np.eye(6))
    D = ls.Subspace.annihilator(alg, np.eye(6)[:1])
    ls.SuslovSystem(Jg, constraints=D)
    with pytest.raises(ValueError, match="potential"):
        ls.SuslovSystem(Jg, constraints=D, potential=ls.LinearPotential([0.0, 0.0, 1.0]))


# ======================================================================================== integrate: shapes


def _heavy4(seed=50):
    rng = np.random.default_rng(seed)
    I = rand_spd(rng, 4)
    B = rng.standard_normal(4)
    return rng, I, B, ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), constraints=ls.suslov_distribution(4),
                                      potential=ls.LinearPotential(B))


def test_integrate_two_batch_axes_shapes_and_batch_independence():
    rng, I, B, sys = _heavy4()
    xi = rng.standard_normal((2, 3, 3))
    Om = ref_hat(xi @ fk_rows(4), 4)
    G0 = unit(rng, (2, 3), 4)
    g0 = np.stack([np.stack([rand_rot(rng, 4) for _ in range(3)]) for _ in range(2)])
    te = np.linspace(0.0, 1.0, 6)
    sol = ls.integrate(sys, Om, (0.0, 1.0), Gamma0=G0, g0=g0, reconstruct=True, method="rkmk4", chart="exp",
                       h=0.05, t_eval=te)
    N = len(te)
    np.testing.assert_array_equal(sol.t, te)
    assert sol.omega.shape == (N, 2, 3, 6)
    assert sol.Omega.shape == (N, 2, 3, 4, 4)
    assert sol.Gamma.shape == (N, 2, 3, 4)
    assert sol.g.shape == (N, 2, 3, 4, 4)
    np.testing.assert_allclose(sol.Omega, ref_hat(sol.omega, 4), atol=1e-15)
    np.testing.assert_allclose(sol.omega[0], ref_vee(Om), atol=1e-14)
    np.testing.assert_allclose(sol.Gamma[0], G0, atol=1e-14)
    np.testing.assert_allclose(sol.g[0], g0, atol=1e-14)
    for key in ("nfev", "steps", "rejected"):
        assert key in sol.stats
    # element (1, 2) of the batch = the same scene integrated alone (fixed step)
    one = ls.integrate(sys, ref_vee(Om[1, 2]), (0.0, 1.0), Gamma0=G0[1, 2], g0=g0[1, 2], reconstruct=True,
                       h=0.05, t_eval=te)
    assert one.omega.shape == (N, 6) and one.Gamma.shape == (N, 4) and one.g.shape == (N, 4, 4)
    np.testing.assert_allclose(one.omega, sol.omega[:, 1, 2], atol=1e-12)
    np.testing.assert_allclose(one.Gamma, sol.Gamma[:, 1, 2], atol=1e-12)
    np.testing.assert_allclose(one.g, sol.g[:, 1, 2], atol=1e-12)
    # the constraints hold exactly along the way
    np.testing.assert_array_equal(sol.Omega[..., :3, :3], 0.0)


def test_integrate_none_rules_and_default_grid():
    rng, I, B, sys = _heavy4(51)
    free = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I))
    x0 = rng.standard_normal(3) @ fk_rows(4)
    s = ls.integrate(free, x0, (0.0, 1.0), h=0.1)
    assert s.Gamma is None and s.g is None
    assert s.t.shape == (11,) and s.omega.shape == (11, 6) and s.Omega.shape == (11, 4, 4)
    np.testing.assert_allclose(s.t, np.linspace(0.0, 1.0, 11), atol=1e-14)
    assert s.t[0] == 0.0 and s.t[-1] == 1.0
    assert s.stats["steps"] == 10 and s.stats["rejected"] == 0 and s.stats["nfev"] >= 40
    G0 = unit(rng, (), 4)
    s = ls.integrate(free, x0, (0.0, 1.0), Gamma0=G0, h=0.1)
    assert s.Gamma.shape == (11, 4) and s.g is None
    s = ls.integrate(free, x0, (0.0, 1.0), reconstruct=True, h=0.1)
    assert s.g.shape == (11, 4, 4)
    np.testing.assert_allclose(s.g[0], np.eye(4), atol=1e-15)  # g0 defaults to the identity
    s = ls.integrate(sys, x0, (0.0, 1.0), Gamma0=G0, method="rkmk45", rtol=1e-8, atol=1e-10)
    assert s.t[0] == 0.0 and s.t[-1] == 1.0 and np.all(np.diff(s.t) > 0)
    assert s.stats["steps"] == len(s.t) - 1
    s = ls.integrate(sys, x0, (0.0, 1.0), Gamma0=G0, method="lie-euler", h=0.25)
    assert s.t.shape == (5,) and s.stats["steps"] == 4


@pytest.mark.parametrize("method", ["lie-euler", "rkmk4", "rkmk45"])
@pytest.mark.parametrize("chart", ["exp", "cayley"])
def test_integrate_every_method_chart_t_eval(method, chart):
    rng, I, B, sys = _heavy4(52)
    x0 = rng.standard_normal(3) @ fk_rows(4)
    G0 = unit(rng, (), 4)
    te = np.array([0.0, 0.1, 0.35, 0.7, 1.0])
    h = 1e-3 if method == "lie-euler" else 0.01
    sol = ls.integrate(sys, x0, (0.0, 1.0), Gamma0=G0, g0=None, reconstruct=True, method=method, chart=chart,
                       h=h, rtol=1e-9, atol=1e-11, t_eval=te)
    np.testing.assert_array_equal(sol.t, te)
    E = sys.energy(sol.omega, sol.Gamma)
    tol = 2e-2 if method == "lie-euler" else 1e-7
    np.testing.assert_allclose(E, E[0], rtol=0, atol=tol)
    G = sol.g
    np.testing.assert_allclose(np.swapaxes(G, -1, -2) @ G, np.broadcast_to(np.eye(4), G.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(sol.Gamma, axis=-1), 1.0, atol=1e-12)
    ref = solve_ref(suslov_ref(I, fk_rows(4), grad=lambda g: B, with_g=True),
                    np.concatenate([x0, G0, np.eye(4).ravel()]), te)
    tol = 2e-2 if method == "lie-euler" else 1e-6
    np.testing.assert_allclose(sol.omega, ref[:, :6], atol=tol)
    np.testing.assert_allclose(sol.Gamma, ref[:, 6:10], atol=tol)
    np.testing.assert_allclose(sol.g.reshape(len(te), 16), ref[:, 10:], atol=tol)


def test_backward_integration():
    rng, I, B, sys = _heavy4(53)
    x0 = rng.standard_normal(3) @ fk_rows(4)
    G0 = unit(rng, (), 4)
    fwd = ls.integrate(sys, x0, (0.0, 1.0), Gamma0=G0, h=0.01)
    back = ls.integrate(sys, fwd.omega[-1], (1.0, 0.0), Gamma0=fwd.Gamma[-1], h=0.01)
    assert back.t[0] == 1.0 and back.t[-1] == 0.0
    np.testing.assert_allclose(back.omega[-1], x0, atol=1e-8)
    np.testing.assert_allclose(back.Gamma[-1], G0, atol=1e-8)


def test_omega0_matrix_equals_coordinates():
    rng, I, B, sys = _heavy4(54)
    x0 = rng.standard_normal((2, 3)) @ fk_rows(4)
    G0 = unit(rng, (2,), 4)
    a = ls.integrate(sys, x0, (0.0, 0.5), Gamma0=G0, h=0.05)
    b = ls.integrate(sys, ref_hat(x0, 4), (0.0, 0.5), Gamma0=G0, h=0.05)
    np.testing.assert_allclose(a.omega, b.omega, atol=1e-14)
    np.testing.assert_allclose(a.Gamma, b.Gamma, atol=1e-14)


# ======================================================================================== errors


def test_errors_name_the_argument():
    rng, I, B, sys = _heavy4(60)
    x0 = rng.standard_normal(3) @ fk_rows(4)
    G0 = unit(rng, (), 4)
    so4 = ls.so(4)
    with pytest.raises(ValueError, match="Omega0"):
        ls.integrate(sys, np.ones(6), (0.0, 1.0), Gamma0=G0, h=0.1)
    with pytest.raises(ValueError, match="Omega0"):
        ls.integrate(sys, ref_hat(np.ones(6), 4), (0.0, 1.0), Gamma0=G0, h=0.1)
    with pytest.raises(ValueError, match="Gamma0"):
        ls.integrate(sys, x0, (0.0, 1.0), Gamma0=2 * G0, h=0.1)
    with pytest.raises(ValueError, match="Gamma0"):
        ls.integrate(sys, x0, (0.0, 1.0), h=0.1)
    for m in ("rkmk4", "lie-euler"):
        with pytest.raises(ValueError, match=r"\bh\b"):
            ls.integrate(sys, x0, (0.0, 1.0), Gamma0=G0, method=m)
    with pytest.raises(ValueError, match="Omega0"):
        ls.integrate(sys, x0 * np.nan, (0.0, 1.0), Gamma0=G0, h=0.1)
    with pytest.raises(ValueError, match="Gamma0"):
        ls.integrate(sys, x0, (0.0, 1.0), Gamma0=G0 * np.inf, h=0.1)
    with pytest.raises(ValueError, match="t_span"):
        ls.integrate(sys, x0, (0.0, np.nan), Gamma0=G0, h=0.1)
    with pytest.raises(ValueError, match=r"\bh\b"):
        ls.integrate(sys, x0, (0.0, 1.0), Gamma0=G0, h=np.nan)
    with pytest.raises(ValueError, match="g0"):
        ls.integrate(sys, x0, (0.0, 1.0), Gamma0=G0, h=0.1, reconstruct=True, g0=2 * np.eye(4))
    with pytest.raises(ValueError, match="method"):
        ls.integrate(sys, x0, (0.0, 1.0), Gamma0=G0, h=0.1, method="rk4-nonexistent")
    with pytest.raises(ValueError, match="chart"):
        ls.integrate(sys, x0, (0.0, 1.0), Gamma0=G0, h=0.1, chart="quaternion")
    with pytest.raises(ValueError, match="t_eval"):
        ls.integrate(sys, x0, (0.0, 1.0), Gamma0=G0, h=0.1, t_eval=[0.0, 2.0])
    with pytest.raises(TypeError, match="system"):
        ls.integrate("not a system", x0, (0.0, 1.0), Gamma0=G0, h=0.1)
    with pytest.raises(TypeError, match="Omega0"):
        ls.integrate(sys, "abc", (0.0, 1.0), Gamma0=G0, h=0.1)
    # mass tensor: not symmetric, J not positive definite, non-finite, wrong type
    with pytest.raises(ValueError, match="(?i)mass tensor|\\bI\\b"):
        ls.Inertia.from_mass_tensor([[1.0, 0.2, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match="(?i)positive definite"):
        ls.Inertia.from_mass_tensor(np.diag([-1.0, 0.5, 2.0]))
    with pytest.raises(ValueError, match="(?i)mass tensor|\\bI\\b"):
        ls.Inertia.from_mass_tensor(np.diag([np.nan, 1.0, 2.0]))
    with pytest.raises(TypeError):
        ls.Inertia.from_mass_tensor("abc")
    with pytest.raises(ValueError, match="K"):
        ls.Inertia(so4, -np.eye(6))
    with pytest.raises(ValueError, match="K"):
        ls.Inertia(so4, np.triu(np.ones((6, 6))))
    # dependent constraint covectors
    with pytest.raises(ValueError, match="(?i)covector"):
        ls.Subspace.annihilator(so4, np.array([[1.0, 0, 0, 0, 0, 0], [2.0, 0, 0, 0, 0, 0]]))
    with pytest.raises(ValueError, match="B"):
        ls.LinearPotential([1.0, np.nan, 0.0])
    with pytest.raises(TypeError, match="constraints"):
        ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), constraints=np.eye(6))
    with pytest.raises(TypeError, match="potential"):
        ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), potential=3.0)
    with pytest.raises(ValueError, match="Gamma"):
        sys.energy(x0)
    with pytest.raises(ValueError, match="g"):
        ls.to_spherical_pendulum(2 * np.eye(4), np.zeros(6))
    with pytest.raises(ValueError, match="Omega"):
        ls.to_spherical_pendulum(np.eye(4), np.ones((4, 4)))


@pytest.mark.parametrize("size", [1, 3, 32, 33, 500])  # Python floats up to 32 entries, the ufunc beyond
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_one_non_finite_entry_anywhere_is_found(size, bad):
    from liesuslov._validation import all_finite, as_float_array

    rng = np.random.default_rng(size)
    for shape in ((size,), (size, 1)):
        a = rng.standard_normal(shape) * 1e300  # large finite entries: no overflow in the test itself
        assert all_finite(a)
        for pos in {0, size // 2, size - 1}:
            b = a.copy()
            b.flat[pos] = bad
            assert not all_finite(b)
            with pytest.raises(ValueError, match="Omega0 contains NaN or infinite"):
                as_float_array(b, "Omega0")


@pytest.mark.parametrize("n", range(1, 10))  # Python floats up to 7 entries, numpy's reduction beyond
def test_unit_vectors_of_one_vector_is_bitwise_a_row_of_the_batch(n):
    """One vector (a sum on Python floats up to 7 entries) normalised exactly as the same vector in a batch
    (numpy's reduction): a trajectory's Gamma0, hence its whole run, does not depend on its batch mates; a
    vector off the unit sphere is rejected on both paths, with its norm."""
    from liesuslov._validation import unit_vectors

    rng = np.random.default_rng(40 + n)
    X = rng.standard_normal((300, n))
    X /= np.linalg.norm(X, axis=1, keepdims=True)
    X *= 1.0 + rng.uniform(-5e-9, 5e-9, (300, 1))  # within the tolerance, not exactly unit
    batch = unit_vectors(X, "Gamma0")
    for x, row in zip(X, batch, strict=True):
        one = unit_vectors(x, "Gamma0")
        assert one.shape == (n,) and np.array_equal(one, row)
    for bad in (2.0 * X[:1], np.full((1, n), np.nan)):
        for arg in (bad, bad[0]):
            with pytest.raises(ValueError, match="Gamma0 must be a unit vector"):
                unit_vectors(arg, "Gamma0")


# ======================================================================================== references: (a) free body


@pytest.mark.parametrize("whole", ["rows", "annihilator"])
def test_free_rigid_body_so3_vs_euler_equations(whole):
    """D = so(3): J w' = J w x w (Euler), g' = g hat(w), Gamma = g^T gamma, against scipy at 1e-12."""
    rng = np.random.default_rng(70)
    I = rand_spd(rng, 3)
    Jw = np.trace(I) * np.eye(3) - I
    so3 = ls.so(3)
    D = ls.Subspace(so3, np.eye(3)) if whole == "rows" else ls.Subspace.annihilator(so3, np.zeros((0, 3)))
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), constraints=D)
    w0 = rng.standard_normal(3)
    g0 = rand_rot(rng, 3)
    gamma = unit(rng, (), 3)
    G0 = g0.T @ gamma
    te = np.linspace(0.0, 3.0, 13)

    def euler(t, y):
        w, g = y[:3], y[3:].reshape(3, 3)
        wd = np.linalg.solve(Jw, np.cross(Jw @ w, w))
        return np.concatenate([wd, (g @ cross_mat(w)).ravel()])

    ref = solve_ref(euler, np.concatenate([w0, g0.ravel()]), te)
    sol = ls.integrate(sys, x_of(w0), (0.0, 3.0), Gamma0=G0, g0=g0, reconstruct=True, method="rkmk45",
                       rtol=1e-11, atol=1e-13, t_eval=te)
    np.testing.assert_allclose(w_of(sol.omega), ref[:, :3], atol=1e-8)
    np.testing.assert_allclose(sol.g.reshape(-1, 9), ref[:, 3:], atol=1e-8)
    gref = ref[:, 3:].reshape(-1, 3, 3)
    np.testing.assert_allclose(sol.Gamma, np.einsum("tji,j->ti", gref, gamma), atol=1e-8)
    # without reconstruction, Gamma' = -Omega Gamma is integrated directly: same Gamma
    s2 = ls.integrate(sys, x_of(w0), (0.0, 3.0), Gamma0=G0, method="rkmk45", rtol=1e-11, atol=1e-13, t_eval=te)
    assert s2.g is None
    np.testing.assert_allclose(s2.Gamma, sol.Gamma, atol=1e-8)
    # energy and |M| (Casimir) conserved
    E = sys.energy(sol.omega)
    np.testing.assert_allclose(E, E[0], rtol=1e-10)


def test_free_rigid_body_so4_vs_matrix_euler():
    """so(4), D = whole algebra, non-diagonal I: M' = [M, Omega], against scipy."""
    rng = np.random.default_rng(71)
    I = rand_spd(rng, 4)
    so4 = ls.so(4)
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), constraints=ls.Subspace(so4, np.eye(6)))
    x0 = rng.standard_normal(6)
    te = np.linspace(0.0, 2.0, 9)
    ref = solve_ref(suslov_ref(I, np.eye(6), with_g=True), np.concatenate([x0, np.eye(4)[3], np.eye(4).ravel()]),
                    te)
    sol = ls.integrate(sys, x0, (0.0, 2.0), reconstruct=True, method="rkmk45", rtol=1e-11, atol=1e-13, t_eval=te)
    np.testing.assert_allclose(sol.omega, ref[:, :6], atol=1e-8)
    np.testing.assert_allclose(sol.g.reshape(-1, 16), ref[:, 10:], atol=1e-8)


def test_reconstruction_side_by_finite_differences():
    """g^{-1} g' = Omega (body, left-trivialised) and Gamma' = -Omega Gamma, Gamma = g^T gamma."""
    rng, I, B, sys = _heavy4(72)
    x0 = rng.standard_normal(3) @ fk_rows(4)
    g0 = rand_rot(rng, 4)
    G0 = unit(rng, (), 4)
    dt = 1e-4
    te = np.array([0.0, 0.5 - dt, 0.5, 0.5 + dt, 1.0])
    sol = ls.integrate(sys, x0, (0.0, 1.0), Gamma0=G0, g0=g0, reconstruct=True, method="rkmk45", rtol=1e-12,
                       atol=1e-14, t_eval=te)
    g, Om, G = sol.g, sol.Omega, sol.Gamma
    gdot = (g[3] - g[1]) / (2 * dt)
    np.testing.assert_allclose(g[2].T @ gdot, Om[2], atol=1e-6)
    Gdot = (G[3] - G[1]) / (2 * dt)
    np.testing.assert_allclose(Gdot, -Om[2] @ G[2], atol=1e-6)
    gamma = g0 @ G0
    np.testing.assert_allclose(G, np.einsum("tji,j->ti", g, gamma), atol=1e-10)
    # the same without reconstruction
    s2 = ls.integrate(sys, x0, (0.0, 1.0), Gamma0=G0, method="rkmk45", rtol=1e-12, atol=1e-14, t_eval=te)
    np.testing.assert_allclose(s2.Gamma, G, atol=1e-9)
    np.testing.assert_allclose(s2.omega, sol.omega, atol=1e-9)


# ======================================================================================== (b) constant Omega


@pytest.mark.parametrize("n", [3, 5])
@pytest.mark.parametrize("method,chart,tol", [("rkmk4", "exp", 1e-12), ("lie-euler", "exp", 1e-12),
                                              ("rkmk45", "exp", 1e-11), ("rkmk4", "cayley", 1e-7),
                                              ("rkmk45", "cayley", 1e-7)])
def test_constant_omega_exact_exponential(n, method, chart, tol):
    """Diagonal I, Fedorov-Kozlov D is an eigenspace of J, V = 0: Omega constant, g = g0 exp(t Omega)."""
    rng = np.random.default_rng(80 + n)
    I = np.diag(rng.uniform(1.0, 3.0, n))
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I))
    x0 = rng.standard_normal(n - 1) @ fk_rows(n)
    g0 = rand_rot(rng, n)
    G0 = unit(rng, (), n)
    te = np.linspace(0.0, 2.0, 5)
    sol = ls.integrate(sys, ref_hat(x0, n), (0.0, 2.0), Gamma0=G0, g0=g0, reconstruct=True, method=method,
                       chart=chart, h=0.05, rtol=1e-10, atol=1e-12, t_eval=te)
    X = ref_hat(x0, n)
    np.testing.assert_allclose(sol.omega, np.broadcast_to(x0, sol.omega.shape), atol=1e-13)
    want = np.stack([g0 @ scipy.linalg.expm(t * X) for t in te])
    np.testing.assert_allclose(sol.g, want, atol=tol)
    np.testing.assert_allclose(sol.Gamma, np.stack([scipy.linalg.expm(-t * X) @ G0 for t in te]), atol=tol)
    s2 = ls.integrate(sys, x0, (0.0, 2.0), Gamma0=G0, method=method, chart=chart, h=0.05, rtol=1e-10, atol=1e-12,
                      t_eval=te)
    np.testing.assert_allclose(s2.Gamma, np.stack([scipy.linalg.expm(-t * X) @ G0 for t in te]), atol=tol)


# ======================================================================================== (c) 3-D Suslov, V = 0


def _suslov3_closed_form(J1, J2, J13, J23, w0, t):
    """omega_3 = 0, J1 w1' = -(J13 w1 + J23 w2) w2, J2 w2' = (J13 w1 + J23 w2) w1 (derived by hand).

    u = sqrt(J1) w1 = R cos(phi), v = sqrt(J2) w2 = R sin(phi); phi' = (J13 w1 + J23 w2)/sqrt(J1 J2)
    = k cos(phi - phi0); sin(psi) = tanh(k t + artanh(sin psi0)), sign(cos psi) constant.
    """
    R = np.hypot(np.sqrt(J1) * w0[0], np.sqrt(J2) * w0[1])
    a, b = J13 / np.sqrt(J1), J23 / np.sqrt(J2)
    rho, phi0 = np.hypot(a, b), np.arctan2(b, a)
    k = R * rho / np.sqrt(J1 * J2)
    psi0 = np.arctan2(np.sqrt(J2) * w0[1], np.sqrt(J1) * w0[0]) - phi0
    s = np.tanh(k * t + np.arctanh(np.sin(psi0)))
    c = np.sign(np.cos(psi0)) * np.sqrt(1.0 - s ** 2)
    phi_c, phi_s = np.cos(phi0) * c - np.sin(phi0) * s, np.sin(phi0) * c + np.cos(phi0) * s
    return np.stack([R * phi_c / np.sqrt(J1), R * phi_s / np.sqrt(J2), 0 * t], axis=-1)


@pytest.mark.parametrize("w0", [(0.7, -1.1), (-1.3, -0.4)])
def test_suslov3_free_closed_form_and_limits(w0):
    J1, J2, J3, J13, J23 = 2.0, 3.0, 4.0, 0.5, -0.7
    Jw = np.array([[J1, 0.0, J13], [0.0, J2, J23], [J13, J23, J3]])
    I = 0.5 * np.trace(Jw) * np.eye(3) - Jw  # J = tr(I) Id - I
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I))  # default D: w3 = -Omega_12 = 0
    w0 = np.array([w0[0], w0[1], 0.0])
    te = np.linspace(0.0, 6.0, 13)
    sol = ls.integrate(sys, x_of(w0), (0.0, 6.0), method="rkmk45", rtol=1e-11, atol=1e-13, t_eval=te)
    w = w_of(sol.omega)
    np.testing.assert_array_equal(w[:, 2], 0.0)  # the constraint exactly
    np.testing.assert_allclose(w, _suslov3_closed_form(J1, J2, J13, J23, w0, te), atol=1e-8)
    E = sys.energy(sol.omega)
    np.testing.assert_allclose(E, 0.5 * (J1 * w0[0] ** 2 + J2 * w0[1] ** 2), rtol=1e-10)
    # limits: w_+ = mu (-J23, J13, 0) (mu > 0) as t -> +inf, w_- = -w_+ as t -> -inf
    d = np.array([-J23, J13, 0.0])
    mu = np.sqrt(2 * E[0] / (J1 * d[0] ** 2 + J2 * d[1] ** 2))
    fwd = ls.integrate(sys, x_of(w0), (0.0, 100.0), method="rkmk45", rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(w_of(fwd.omega[-1]), mu * d, atol=1e-7)
    back = ls.integrate(sys, x_of(w0), (0.0, -100.0), method="rkmk45", rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(w_of(back.omega[-1]), -mu * d, atol=1e-7)


# ======================================================================================== (d) Lagrange top / pendulum


def test_lagrange3_vs_unconstrained_heavy_top():
    """n = 3, J1 = J2, V = B3 Gamma3: the Suslov motion is the heavy top's with w3 = 0 (lambda = 0)."""
    J1, J3, B3 = 2.0, 3.0, 1.7
    Jw = np.diag([J1, J1, J3])
    I = 0.5 * np.trace(Jw) * np.eye(3) - Jw
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), potential=ls.LinearPotential([0.0, 0.0, B3]))
    rng = np.random.default_rng(90)
    w0 = np.array([0.8, -0.5, 0.0])
    G0 = unit(rng, (), 3)
    te = np.linspace(0.0, 5.0, 11)

    def top(t, y):
        w, G = y[:3], y[3:]
        dV = np.array([0.0, 0.0, B3])
        return np.concatenate([np.linalg.solve(Jw, np.cross(Jw @ w, w) + np.cross(G, dV)), np.cross(G, w)])

    ref = solve_ref(top, np.concatenate([w0, G0]), te)
    sol = ls.integrate(sys, x_of(w0), (0.0, 5.0), Gamma0=G0, method="rkmk45", rtol=1e-11, atol=1e-13, t_eval=te)
    np.testing.assert_allclose(w_of(sol.omega), ref[:, :3], atol=1e-8)
    np.testing.assert_allclose(sol.Gamma, ref[:, 3:], atol=1e-8)
    F = np.einsum("ij,tj,ti->t", Jw, w_of(sol.omega), sol.Gamma)  # F = <J w, Gamma>
    np.testing.assert_allclose(F, F[0], atol=1e-9)
    E = sys.energy(sol.omega, sol.Gamma)
    np.testing.assert_allclose(E, 0.5 * w0 @ Jw @ w0 + B3 * G0[2], atol=1e-9)


@pytest.mark.parametrize("n", [3, 4, 5])
def test_lagrange_nd_spherical_pendulum(n):
    """I = diag(I1, ..., I1, In), V = Bn Gamma_n: q = g e_n obeys the spherical pendulum (scipy reference)."""
    rng = np.random.default_rng(100 + n)
    I1, In, Bn = 1.3, 0.6, 2.1
    m = I1 + In
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag([I1] * (n - 1) + [In])),
                          potential=ls.LinearPotential(np.eye(n)[n - 1] * Bn))
    x0 = rng.standard_normal(n - 1) @ fk_rows(n)
    g0 = rand_rot(rng, n)
    G0 = unit(rng, (), n)
    gamma = g0 @ G0
    te = np.linspace(0.0, 4.0, 9)
    sol = ls.integrate(sys, x0, (0.0, 4.0), Gamma0=G0, g0=g0, reconstruct=True, method="rkmk45", rtol=1e-11,
                       atol=1e-13, t_eval=te)
    q, v = ls.to_spherical_pendulum(sol.g, sol.Omega)
    assert q.shape == (len(te), n) and v.shape == (len(te), n)
    np.testing.assert_allclose(q, sol.g[..., :, n - 1], atol=1e-15)
    np.testing.assert_allclose(v, np.einsum("tij,tj->ti", sol.g, sol.Omega[..., :, n - 1]), atol=1e-14)
    q2, v2 = ls.to_spherical_pendulum(sol.g, sol.omega)  # coordinates accepted too
    np.testing.assert_allclose(q2, q, atol=0)
    np.testing.assert_allclose(v2, v, atol=1e-15)
    H = 0.5 * m * np.sum(v ** 2, -1) + Bn * q @ gamma
    np.testing.assert_allclose(H, sys.energy(sol.omega, sol.Gamma), atol=1e-12)
    np.testing.assert_allclose(H, H[0], atol=1e-9)

    def pend(t, y):
        q, v = y[:n], y[n:]
        return np.concatenate([v, -(Bn / m) * (gamma - (gamma @ q) * q) - (v @ v) * q])

    ref = solve_ref(pend, np.concatenate([q[0], v[0]]), te)
    np.testing.assert_allclose(q, ref[:, :n], atol=1e-8)
    np.testing.assert_allclose(v, ref[:, n:], atol=1e-8)


def test_to_spherical_pendulum_batch_shapes():
    rng = np.random.default_rng(110)
    n = 4
    g = np.stack([np.stack([rand_rot(rng, n) for _ in range(3)]) for _ in range(2)])
    x = rng.standard_normal((2, 3, 6))
    Om = ref_hat(x, n)
    q, v = ls.to_spherical_pendulum(g, Om)
    assert q.shape == (2, 3, n) and v.shape == (2, 3, n)
    np.testing.assert_allclose(q, g[..., :, n - 1], atol=0)
    np.testing.assert_allclose(v, np.einsum("...ij,...j->...i", g, Om[..., :, n - 1]), atol=1e-14)


# ======================================================================================== (e) Fedorov-Kozlov, V = 0


def test_fedorov_kozlov_closed_form():
    """K_D = kappa Id, b = (I_in) != 0: u stays in span(u0, b), angle a to b with tan(a/2) = tan(a0/2) e^{k t}.

    Derived from (2.2): K_D u' = (b.u) u - |u|^2 b, K_D = I' + I_nn Id, I' the (n-1) block of I.
    """
    n = 5
    rng = np.random.default_rng(120)
    b = rng.standard_normal(n - 1) * 0.3
    I = np.eye(n) * 1.5
    I[: n - 1, n - 1] = I[n - 1, : n - 1] = b
    kappa = 3.0
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I))
    u0 = rng.standard_normal(n - 1)
    R = np.linalg.norm(u0)
    e1 = b / np.linalg.norm(b)
    w = u0 - (u0 @ e1) * e1
    e2 = w / np.linalg.norm(w)
    a0 = np.arctan2(u0 @ e2, u0 @ e1)
    k = R * np.linalg.norm(b) / kappa
    te = np.linspace(0.0, 5.0, 11)
    a = 2 * np.arctan(np.tan(a0 / 2) * np.exp(k * te))
    u = R * (np.cos(a)[:, None] * e1 + np.sin(a)[:, None] * e2)
    sol = ls.integrate(sys, u0 @ fk_rows(n), (0.0, 5.0), method="rkmk45", rtol=1e-11, atol=1e-13, t_eval=te)
    np.testing.assert_allclose(sol.omega, u @ fk_rows(n), atol=1e-8)


@pytest.mark.parametrize("n", [3, 4, 6])
def test_fedorov_kozlov_double_asymptotic(n):
    """General I: energy conserved; u -> -mu b (t -> +inf), +mu b (t -> -inf), b = (I_1n, ..., I_{n-1,n})."""
    rng = np.random.default_rng(130 + n)
    I = rand_spd(rng, n)
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), constraints=ls.suslov_distribution(n), potential=None,
                          gyroscopic=0.0)
    KD = I[: n - 1, : n - 1] + I[n - 1, n - 1] * np.eye(n - 1)
    b = I[: n - 1, n - 1]
    u0 = rng.standard_normal(n - 1)
    h = 0.5 * u0 @ KD @ u0
    te = np.linspace(0.0, 3.0, 7)
    sol = ls.integrate(sys, u0 @ fk_rows(n), (0.0, 3.0), method="rkmk45", rtol=1e-11, atol=1e-13, t_eval=te)
    ref = solve_ref(suslov_ref(I, fk_rows(n)), np.concatenate([u0 @ fk_rows(n), np.eye(n)[n - 1]]), te)
    np.testing.assert_allclose(sol.omega, ref[:, : n * (n - 1) // 2], atol=1e-8)
    np.testing.assert_allclose(sys.energy(sol.omega), h, rtol=1e-10)
    mu = np.sqrt(2 * h / (b @ KD @ b))
    T = 40.0 * np.linalg.eigvalsh(KD)[-1] / (mu * (b @ b))  # 40 e-folds of the slowest transverse rate
    fwd = ls.integrate(sys, u0 @ fk_rows(n), (0.0, T), method="rkmk45", rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(fwd.omega[-1] @ fk_rows(n).T, -mu * b, atol=1e-6)
    back = ls.integrate(sys, u0 @ fk_rows(n), (0.0, -T), method="rkmk45", rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(back.omega[-1] @ fk_rows(n).T, mu * b, atol=1e-6)


# ======================================================================================== general scenes vs (2.2)


def test_general_so4_scene_vs_multiplier_reference():
    """Non-diagonal I, a random 4-D D (not symmetric), QuadraticPotential (n, n): the library against (2.2)."""
    rng = np.random.default_rng(140)
    n = 4
    I = rand_spd(rng, n)
    S = rng.standard_normal((n, n))
    S = S + S.T
    A = rng.standard_normal((2, 6))
    D = ls.Subspace.annihilator(ls.so(n), A)
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), constraints=D, potential=ls.QuadraticPotential(S))
    rows = scipy.linalg.null_space(A).T
    x0 = rng.standard_normal(4) @ rows
    G0 = unit(rng, (), n)
    te = np.linspace(0.0, 2.0, 9)
    ref = solve_ref(suslov_ref(I, rows, grad=lambda G: S @ G), np.concatenate([x0, G0]), te)
    for Om0 in (x0, ref_hat(x0, n)):
        sol = ls.integrate(sys, Om0, (0.0, 2.0), Gamma0=G0, method="rkmk45", rtol=1e-11, atol=1e-13, t_eval=te)
        np.testing.assert_allclose(sol.omega, ref[:, :6], atol=1e-8)
        np.testing.assert_allclose(sol.Gamma, ref[:, 6:], atol=1e-8)
    E = sys.energy(sol.Omega, sol.Gamma)
    np.testing.assert_allclose(E, E[0], atol=1e-9)
    np.testing.assert_allclose(sol.omega @ A.T, 0.0, atol=1e-12)


def test_user_potential_and_diagonal_quadratic_vs_reference():
    rng = np.random.default_rng(141)
    n = 5
    I = np.diag(rng.uniform(1.0, 2.0, n))
    Bq = rng.uniform(-1.0, 1.0, n)
    te = np.linspace(0.0, 2.0, 5)
    x0 = rng.standard_normal(n - 1) @ fk_rows(n)
    G0 = unit(rng, (), n)
    ref = solve_ref(suslov_ref(I, fk_rows(n), grad=lambda G: Bq * G), np.concatenate([x0, G0]), te)
    for pot in (ls.QuadraticPotential(Bq), ls.QuadraticPotential(np.diag(Bq)),
                ls.Potential(lambda G: 0.5 * np.sum(Bq * G ** 2, axis=-1), lambda G: Bq * G)):
        sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), potential=pot)
        sol = ls.integrate(sys, x0, (0.0, 2.0), Gamma0=G0, method="rkmk45", rtol=1e-11, atol=1e-13, t_eval=te)
        np.testing.assert_allclose(sol.omega, ref[:, :10], atol=1e-8)
        np.testing.assert_allclose(sol.Gamma, ref[:, 10:], atol=1e-8)


def test_gyroscopic_3d_vs_reference():
    """eps Gamma x w added to J w' (vector form): against (3.1) with the gyroscopic term; energy conserved."""
    rng = np.random.default_rng(142)
    Jw = np.diag([2.0, 3.0, 4.0])
    I = 0.5 * np.trace(Jw) * np.eye(3) - Jw
    eps = 0.8
    B = np.array([0.6, -0.4, 0.0])
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), potential=ls.LinearPotential(B), gyroscopic=eps)
    w0 = np.array([0.5, 1.2, 0.0])
    G0 = unit(rng, (), 3)
    te = np.linspace(0.0, 4.0, 9)

    def f(t, y):  # Suslov constraint w3 = 0: the first two rows of J w' = ... (J diagonal)
        w, G = y[:3], y[3:]
        tq = np.cross(Jw @ w, w) + np.cross(G, B) + eps * np.cross(G, w)
        wd = np.array([tq[0] / Jw[0, 0], tq[1] / Jw[1, 1], 0.0])
        return np.concatenate([wd, np.cross(G, w)])

    ref = solve_ref(f, np.concatenate([w0, G0]), te)
    sol = ls.integrate(sys, x_of(w0), (0.0, 4.0), Gamma0=G0, method="rkmk45", rtol=1e-11, atol=1e-13, t_eval=te)
    np.testing.assert_allclose(w_of(sol.omega), ref[:, :3], atol=1e-8)
    np.testing.assert_allclose(sol.Gamma, ref[:, 3:], atol=1e-8)
    E = sys.energy(sol.omega, sol.Gamma)
    np.testing.assert_allclose(E, E[0], atol=1e-9)


def test_euler_poincare_suslov_general_algebra():
    """se(3), V = 0: K xi' = d^T ad*_Omega K Omega, (ad*_x m)_j = sum x_i C[i, j, k] m_k (coordinate pairing)."""
    rng = np.random.default_rng(143)
    alg = ls.se(3)
    C = np.asarray(alg.structure_constants)
    K = rand_spd(rng, 6)
    A = rng.standard_normal((2, 6))
    D = ls.Subspace.annihilator(alg, A)
    sys = ls.SuslovSystem(ls.Inertia(alg, K), constraints=D)
    rows = scipy.linalg.null_space(A).T
    KD = rows @ K @ rows.T

    def f(t, x):
        m = K @ x
        return np.linalg.solve(KD, rows @ np.einsum("i,ijk,k->j", x, C, m)) @ rows

    x0 = rng.standard_normal(4) @ rows
    te = np.linspace(0.0, 2.0, 5)
    ref = solve_ref(f, x0, te)
    sol = ls.integrate(sys, x0, (0.0, 2.0), method="rkmk45", rtol=1e-11, atol=1e-13, t_eval=te)
    assert sol.Gamma is None and sol.omega.shape == (5, 6)
    np.testing.assert_allclose(sol.omega, ref, atol=1e-8)
    np.testing.assert_allclose(sys.energy(sol.omega), 0.5 * x0 @ K @ x0, rtol=1e-10)
    # the same system on so(3) given by structure constants agrees with so(3) itself
    so3 = ls.so(3)
    I3 = rand_spd(rng, 3)
    Dso = ls.Subspace.annihilator(so3, [[0.3, 1.0, -0.2]])
    s_so = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I3), constraints=Dso)
    gen = ls.LieAlgebra(so3.structure_constants)
    s_gen = ls.SuslovSystem(ls.Inertia(gen, ref_K(I3)), constraints=ls.Subspace.annihilator(gen, [[0.3, 1.0, -0.2]]))
    y0 = np.asarray(Dso.basis).T @ np.array([0.7, -0.4])
    a = ls.integrate(s_so, y0, (0.0, 2.0), method="rkmk4", h=0.01)
    b = ls.integrate(s_gen, y0, (0.0, 2.0), method="rkmk4", h=0.01)
    np.testing.assert_allclose(a.omega, b.omega, atol=1e-10)


def test_se3_reconstruction_constant_velocity():
    """D = span(x0) on se(3): K_D xi' = xi^2 <x0, ad*_x0 K x0> = xi^2 <[x0, x0], K x0> = 0, so g = expm(t hat(x0))."""
    alg = ls.se(3)
    x0 = np.array([0.3, -0.2, 0.5, 1.0, 0.4, -0.7])
    D = ls.Subspace(alg, x0[None, :])
    sys = ls.SuslovSystem(ls.Inertia(alg, np.eye(6)), constraints=D)
    te = np.linspace(0.0, 2.0, 5)
    sol = ls.integrate(sys, x0, (0.0, 2.0), reconstruct=True, method="rkmk4", h=0.05, t_eval=te)
    np.testing.assert_allclose(sol.omega, np.broadcast_to(x0, (5, 6)), atol=1e-13)
    X = alg.hat(x0)
    np.testing.assert_allclose(sol.g, np.stack([scipy.linalg.expm(t * X) for t in te]), atol=1e-12)


def test_general_K_on_so4_with_potential_vs_reference():
    """ls.Inertia(so(4), K) with a dense SPD K, default Fedorov-Kozlov D and a linear potential: M = K Omega."""
    rng = np.random.default_rng(1200)
    n, d = 4, 6
    K = rand_spd(rng, d)
    Bv = rng.standard_normal(n)
    sys = ls.SuslovSystem(ls.Inertia(ls.so(n), K), potential=ls.LinearPotential(Bv))
    rows = fk_rows(n)
    KD = rows @ K @ rows.T

    def f(t, y):
        x, G, g = y[:d], y[d:d + n], y[d + n:].reshape(n, n)
        X, M = ref_hat(x, n), ref_hat(K @ x, n)
        T = M @ X - X @ M + np.outer(Bv, G) - np.outer(G, Bv)
        return np.concatenate([np.linalg.solve(KD, rows @ ref_vee(T)) @ rows, -X @ G, (g @ X).ravel()])

    x0 = rng.standard_normal(n - 1) @ rows
    G0 = unit(rng, (), n)
    te = np.linspace(0.0, 2.0, 5)
    ref = solve_ref(f, np.concatenate([x0, G0, np.eye(n).ravel()]), te)
    s = ls.integrate(sys, x0, (0.0, 2.0), Gamma0=G0, reconstruct=True, method="rkmk45", rtol=1e-11, atol=1e-13,
                     t_eval=te)
    np.testing.assert_allclose(s.omega, ref[:, :d], atol=1e-8)
    np.testing.assert_allclose(s.Gamma, ref[:, d:d + n], atol=1e-8)
    np.testing.assert_allclose(s.g.reshape(5, -1), ref[:, d + n:], atol=1e-8)
    np.testing.assert_allclose(sys.energy(s.omega, s.Gamma), 0.5 * x0 @ K @ x0 + Bv @ G0, atol=1e-9)


# ======================================================================================== integrable cases: integrals


def test_3d_integrals_kharlamova_klebsh_family():
    rng = np.random.default_rng(150)
    J = np.array([2.0, 3.0, 4.5])
    Jw = np.diag(J)
    I = 0.5 * np.trace(Jw) * np.eye(3) - Jw
    inert = ls.Inertia.from_mass_tensor(I)
    w0 = np.array([0.4, -0.9, 0.0])
    G0 = unit(rng, (), 3)
    te = np.linspace(0.0, 6.0, 13)

    def run(pot):
        sys = ls.SuslovSystem(inert, potential=pot)
        s = ls.integrate(sys, x_of(w0), (0.0, 6.0), Gamma0=G0, method="rkmk45", rtol=1e-11, atol=1e-13, t_eval=te)
        E = sys.energy(s.omega, s.Gamma)
        np.testing.assert_allclose(E, E[0], atol=1e-9)
        return w_of(s.omega), s.Gamma

    # Kharlamova: V = B1 G1 + B2 G2, F = J1 w1 B1 + J2 w2 B2
    B1, B2 = 0.7, -1.1
    w, G = run(ls.LinearPotential([B1, B2, 0.0]))
    F = J[0] * w[:, 0] * B1 + J[1] * w[:, 1] * B2
    np.testing.assert_allclose(F, F[0], atol=1e-9)
    # Klebsh-Tisserand: V = eps/2 <J G, G>, F = 1/2 <J w, J w> - 1/2 <A G, G>, A = eps J^-1 det J
    eps = 0.6
    w, G = run(ls.QuadraticPotential(eps * J))
    A = eps * np.prod(J) / J
    F = 0.5 * np.sum((J * w) ** 2, -1) - 0.5 * np.sum(A * G ** 2, -1)
    np.testing.assert_allclose(F, F[0], atol=1e-9)
    # family: v1(s, r) = s r + s^2, v2(t, q) = 0.5 t q^2; F = 1/2 <J w, J w> + J2 v1 + J1 v2

    def v1(s, r):
        return s * r + s ** 2

    def v2(t, q):
        return 0.5 * t * q ** 2

    def V(G):
        g1, g2, g3 = G[..., 0], G[..., 1], G[..., 2]
        return v1(g1, g2 ** 2 + g3 ** 2) + v2(g2, g1 ** 2 + g3 ** 2)

    def grad(G):
        g1, g2, g3 = G[..., 0], G[..., 1], G[..., 2]
        r, q = g2 ** 2 + g3 ** 2, g1 ** 2 + g3 ** 2
        v1s, v1r = r + 2 * g1, g1
        v2t, v2q = 0.5 * q ** 2, g2 * q
        return np.stack([v1s + 2 * g1 * v2q, 2 * g2 * v1r + v2t, 2 * g3 * (v1r + v2q)], axis=-1)

    w, G = run(ls.Potential(V, grad))
    g1, g2, g3 = G[:, 0], G[:, 1], G[:, 2]
    F = 0.5 * np.sum((J * w) ** 2, -1) + J[1] * v1(g1, g2 ** 2 + g3 ** 2) + J[0] * v2(g2, g1 ** 2 + g3 ** 2)
    np.testing.assert_allclose(F, F[0], atol=1e-9)


def test_nd_integrals_kharlamova_klebsh_tisserand():
    n = 5
    rng = np.random.default_rng(160)
    Id = rng.uniform(1.0, 2.0, n)
    inert = ls.Inertia.from_mass_tensor(np.diag(Id))
    x0 = rng.standard_normal(n - 1) @ fk_rows(n)
    G0 = unit(rng, (), n)
    te = np.linspace(0.0, 5.0, 11)
    # Kharlamova: V = sum_{i<n} B_i G_i, F_ij = (I_i + I_n)/B_i O_in - (I_j + I_n)/B_j O_jn
    B = np.append(rng.uniform(0.5, 1.5, n - 1), 0.0)
    sys = ls.SuslovSystem(inert, potential=ls.LinearPotential(B))
    s = ls.integrate(sys, x0, (0.0, 5.0), Gamma0=G0, method="rkmk45", rtol=1e-11, atol=1e-13, t_eval=te)
    u = s.omega @ fk_rows(n).T
    c = (Id[: n - 1] + Id[n - 1]) / B[: n - 1] * u
    F = c[:, :, None] - c[:, None, :]
    np.testing.assert_allclose(F, np.broadcast_to(F[0], F.shape), atol=1e-9)
    # (4.5): (I_i + I_n) O_in' = B_i Gamma_n  =>  d/dt of c_i equals Gamma_n (check by the difference quotient)
    np.testing.assert_allclose(np.diff(c[:, 0]) / np.diff(te), 0.5 * (s.Gamma[1:, -1] + s.Gamma[:-1, -1]),
                               atol=0.05)
    # Klebsh-Tisserand: V = 1/2 sum B_i G_i^2, B_i > B_n; F_i = (B_i - B_n) G_i^2 + (I_i + I_n) O_in^2
    Bq = np.append(rng.uniform(1.0, 2.0, n - 1), 0.5)
    sys = ls.SuslovSystem(inert, potential=ls.QuadraticPotential(Bq))
    s = ls.integrate(sys, x0, (0.0, 5.0), Gamma0=G0, method="rkmk45", rtol=1e-11, atol=1e-13, t_eval=te)
    u = s.omega @ fk_rows(n).T
    Fi = (Bq[:-1] - Bq[-1]) * s.Gamma[:, :-1] ** 2 + (Id[:-1] + Id[-1]) * u ** 2
    np.testing.assert_allclose(Fi, np.broadcast_to(Fi[0], Fi.shape), atol=1e-9)
    E = sys.energy(s.omega, s.Gamma)
    np.testing.assert_allclose(E, 0.5 * (Fi.sum(-1) + Bq[-1]), atol=1e-9)  # E = (sum F_i + B_n)/2


def test_gamma_equation_by_finite_differences():
    """Gamma' = -Omega Gamma along the returned trajectory (central differences, dense t_eval)."""
    rng, I, B, sys = _heavy4(170)
    x0 = rng.standard_normal(3) @ fk_rows(4)
    G0 = unit(rng, (2, 3), 4)
    x0 = np.broadcast_to(x0, (2, 3, 6))
    te = np.linspace(0.0, 1.0, 401)
    sol = ls.integrate(sys, x0, (0.0, 1.0), Gamma0=G0, method="rkmk4", h=1e-3, t_eval=te)
    dt = te[1] - te[0]
    Gd = (sol.Gamma[2:] - sol.Gamma[:-2]) / (2 * dt)
    want = -np.einsum("t...ij,t...j->t...i", sol.Omega[1:-1], sol.Gamma[1:-1])
    np.testing.assert_allclose(Gd, want, atol=1e-4)
    # and M' = [M, Omega] + dV ∧ Gamma + lambda a, projected on D
    K = ref_K(I)
    Md = (sol.omega[2:] - sol.omega[:-2]) @ K / (2 * dt)
    X = sol.Omega[1:-1]
    M = ref_hat(sol.omega[1:-1] @ K, 4)
    Bv = B
    T = M @ X - X @ M + Bv[:, None] * sol.Gamma[1:-1, ..., None, :] - sol.Gamma[1:-1, ..., :, None] * Bv[None, :]
    P = fk_rows(4)
    np.testing.assert_allclose(Md @ P.T, ref_vee(T) @ P.T, atol=1e-4)


# ============================================================================ orders, tolerances, invariance


@pytest.mark.parametrize("method,chart,order,hs", [("lie-euler", "exp", 1, (0.01, 0.005)),
                                                   ("lie-euler", "cayley", 1, (0.01, 0.005)),
                                                   ("rkmk4", "exp", 4, (0.1, 0.05)),
                                                   ("rkmk4", "cayley", 4, (0.1, 0.05))])
def test_convergence_order_with_reconstruction(method, chart, order, hs):
    """Global error in (Omega, Gamma, g) against the scipy reference halves as 2^-order."""
    rng, I, B, sys = _heavy4(180)
    x0 = rng.standard_normal(3) @ fk_rows(4)
    G0 = unit(rng, (), 4)
    g0 = rand_rot(rng, 4)
    ref = solve_ref(suslov_ref(I, fk_rows(4), grad=lambda g: B, with_g=True),
                    np.concatenate([x0, G0, g0.ravel()]), [0.0, 2.0])[-1]
    errs = []
    for h in hs:
        s = ls.integrate(sys, x0, (0.0, 2.0), Gamma0=G0, g0=g0, reconstruct=True, method=method, chart=chart, h=h)
        errs.append(max(frob(s.omega[-1] - ref[:6]), frob(s.Gamma[-1] - ref[6:10]), frob(s.g[-1].ravel() - ref[10:])))
    slope = np.log2(errs[0] / errs[1])
    assert abs(slope - order) < 0.25, (errs, slope)


def test_adaptive_error_follows_rtol():
    rng, I, B, sys = _heavy4(181)
    x0 = rng.standard_normal(3) @ fk_rows(4)
    G0 = unit(rng, (), 4)
    te = np.linspace(0.0, 3.0, 7)
    ref = solve_ref(suslov_ref(I, fk_rows(4), grad=lambda g: B, with_g=True),
                    np.concatenate([x0, G0, np.eye(4).ravel()]), te)
    for rtol in (1e-5, 1e-8):
        s = ls.integrate(sys, x0, (0.0, 3.0), Gamma0=G0, reconstruct=True, method="rkmk45", rtol=rtol, atol=rtol * 1e-2,
                         t_eval=te)
        err = max(frob(s.omega - ref[:, :6]), frob(s.Gamma - ref[:, 6:10]), frob(s.g.reshape(7, -1) - ref[:, 10:]))
        assert err < 100 * rtol, (rtol, err)


@pytest.mark.parametrize("diag", [True, False])
def test_conjugation_invariance(diag):
    """h in SO(n): (h I h^T, Ad_h D, V(h^T .)) moves as (h Omega h^T, h Gamma, h g h^T)."""
    n = 4
    rng = np.random.default_rng(190 + diag)
    I = np.diag(rng.uniform(1.0, 2.0, n)) if diag else rand_spd(rng, n)
    Bv = rng.standard_normal(n)
    h = rand_rot(rng, n)
    rows2 = ref_vee(h @ ref_hat(fk_rows(n), n) @ h.T)
    s1 = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), potential=ls.LinearPotential(Bv))
    D2 = ls.Subspace.annihilator(ls.so(n), ls.Subspace.annihilator(ls.so(n), rows2).basis)
    s2 = ls.SuslovSystem(ls.Inertia.from_mass_tensor(h @ I @ h.T), constraints=D2, potential=ls.LinearPotential(h @ Bv))
    x0 = rng.standard_normal(n - 1) @ fk_rows(n)
    G0 = unit(rng, (), n)
    g0 = rand_rot(rng, n)
    te = np.linspace(0.0, 2.0, 5)
    a = ls.integrate(s1, x0, (0.0, 2.0), Gamma0=G0, g0=g0, reconstruct=True, method="rkmk45", rtol=1e-11, atol=1e-13,
                     t_eval=te)
    b = ls.integrate(s2, h @ ref_hat(x0, n) @ h.T, (0.0, 2.0), Gamma0=h @ G0, g0=h @ g0 @ h.T, reconstruct=True,
                     method="rkmk45", rtol=1e-11, atol=1e-13, t_eval=te)
    np.testing.assert_allclose(b.Omega, h @ a.Omega @ h.T, atol=1e-8)
    np.testing.assert_allclose(b.Gamma, a.Gamma @ h.T, atol=1e-8)
    np.testing.assert_allclose(b.g, h @ a.g @ h.T, atol=1e-8)


# ============================================================ closed forms: Kharlamova, Klebsh-Tisserand


def test_kharlamova_period_closed_form():
    """(4.5): c_i = (I_i + I_n)/B_i Omega_in has c_i' = Gamma_n; with s = c_i - c_i(0):
    Gamma_i = Gamma_i(0) - beta_i (c_i(0) s + s^2/2), s'^2 = P4(s) = 1 - sum_i Gamma_i(s)^2, beta_i = B_i/(I_i + I_n);
    period T = 2 int ds / sqrt(P4) between the roots adjacent to 0 (derived by hand, no paper coordinates).
    """
    n = 4
    rng = np.random.default_rng(600)
    Id = rng.uniform(1.0, 2.0, n)
    B = np.append(rng.uniform(0.5, 1.5, n - 1), 0.0)
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag(Id)), potential=ls.LinearPotential(B))
    u0 = rng.standard_normal(n - 1) * 0.5
    G0 = unit(rng, (), n)
    beta = B[:-1] / (Id[:-1] + Id[-1])
    c0 = u0 / beta
    P = np.poly1d([1.0])
    for i in range(n - 1):
        q = np.poly1d([-beta[i] / 2, -beta[i] * c0[i], G0[i]])
        P = P - q * q
    r = np.roots(P.coeffs)
    r = np.sort(r[np.abs(r.imag) < 1e-12].real)
    s1, s2 = r[r < 0].max(), r[r > 0].min()
    Q = np.poly1d(np.polydiv(np.polydiv(P.coeffs, [1.0, -s1])[0], [1.0, -s2])[0])  # P = (s - s1)(s - s2) Q

    def integrand(th):
        return 1.0 / np.sqrt(-Q(s1 + (s2 - s1) * (1 - np.cos(th)) / 2))

    T = 2 * scipy.integrate.quad(integrand, 0.0, np.pi, epsabs=1e-14, epsrel=1e-13)[0]
    te = np.linspace(0.0, T, 9)
    sol = ls.integrate(sys, u0 @ fk_rows(n), (0.0, T), Gamma0=G0, method="rkmk45", rtol=1e-12, atol=1e-14, t_eval=te)
    np.testing.assert_allclose(sol.omega[-1], u0 @ fk_rows(n), atol=1e-9)  # periodic with period T
    np.testing.assert_allclose(sol.Gamma[-1], G0, atol=1e-9)
    s = sol.omega @ fk_rows(n).T / beta - c0
    np.testing.assert_allclose(s, np.broadcast_to(s[:, :1], s.shape), atol=1e-10)  # the integrals F_ij
    s = s[:, 0]
    Gi = G0[:-1] - beta * (c0 * s[:, None] + s[:, None] ** 2 / 2)
    np.testing.assert_allclose(sol.Gamma[:, :-1], Gi, atol=1e-9)
    assert s.min() >= s1 - 1e-9 and s.max() <= s2 + 1e-9


def test_klebsh_tisserand_torus_closed_form():
    """(4.3) with V = 1/2 sum B_i Gamma_i^2: in tau (dtau = Gamma_n dt), Gamma_i = A_i cos(nu_i tau + p_i),
    Omega_in = A_i nu_i sin(nu_i tau + p_i), nu_i = sqrt((B_i - B_n)/(I_i + I_n))."""
    n = 4
    rng = np.random.default_rng(700)
    Id = rng.uniform(1.0, 2.0, n)
    Bq = np.append(rng.uniform(1.0, 2.0, n - 1), 0.5)
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag(Id)), potential=ls.QuadraticPotential(Bq))
    u0 = rng.standard_normal(n - 1) * 0.5
    G0 = unit(rng, (), n)
    nu = np.sqrt((Bq[:-1] - Bq[-1]) / (Id[:-1] + Id[-1]))
    A = np.sqrt(G0[:-1] ** 2 + (u0 / nu) ** 2)
    p = np.arctan2(u0 / nu, G0[:-1])
    te = np.linspace(0.0, 3.0, 601)
    sol = ls.integrate(sys, u0 @ fk_rows(n), (0.0, 3.0), Gamma0=G0, method="rkmk45", rtol=1e-12, atol=1e-14,
                       t_eval=te)
    tau = scipy.integrate.cumulative_simpson(sol.Gamma[:, -1], x=te, initial=0.0)
    np.testing.assert_allclose(sol.Gamma[:, :-1], A * np.cos(nu * tau[:, None] + p), atol=1e-8)
    np.testing.assert_allclose(sol.omega @ fk_rows(n).T, A * nu * np.sin(nu * tau[:, None] + p), atol=1e-8)


def test_se3_subalgebras_and_symmetric_pair():
    alg = ls.se(3)
    R = alg.hat(np.eye(6))
    rot = [k for k in range(6) if np.any(R[k][:3, :3])]
    tra = [k for k in range(6) if k not in rot]
    assert len(rot) == 3 and len(tra) == 3
    assert ls.Subspace(alg, np.eye(6)[tra]).is_subalgebra() is True
    assert ls.Subspace(alg, np.eye(6)[rot]).is_subalgebra() is True
    assert ls.Subspace(alg, np.eye(6)[rot[:2]]).is_subalgebra() is False
    assert ls.is_symmetric_pair(ls.Subspace(alg, np.eye(6)[rot]), ls.Subspace(alg, np.eye(6)[tra])) is True


# ============================================================================ discrepancies found by the audit (fixed)


def test_quadratic_potential_nonsymmetric_matrix():
    rng = np.random.default_rng(210)
    Bm = rng.standard_normal((4, 4))
    pot = ls.QuadraticPotential(Bm)
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor([1.0, 2.0, 3.0, 4.0]), potential=pot)
    G = unit(rng, (3,), 4)
    np.testing.assert_allclose(sys.energy(np.zeros((3, 6)), G), 0.5 * np.einsum("bi,ij,bj->b", G, Bm, G))


def test_none_is_a_type_error():
    with pytest.raises(TypeError, match="I"):
        ls.Inertia.from_mass_tensor(None)


def test_method_of_wrong_type_names_argument():
    sys = ls.SuslovSystem(ls.Inertia.from_mass_tensor([1.0, 2.0, 3.0]))
    with pytest.raises(TypeError, match="method"):
        ls.integrate(sys, [0.0, 1.0, 0.5], (0.0, 1.0), h=0.1, method=["rkmk4"])
    with pytest.raises(TypeError, match="reconstruct"):
        ls.integrate(sys, [0.0, 1.0, 0.5], (0.0, 1.0), h=0.1, reconstruct="no")
    with pytest.raises(TypeError, match="h must be"):
        ls.integrate(sys, [0.0, 1.0, 0.5], (0.0, 1.0), h=True)
    with pytest.raises(TypeError, match="h must be a real number, got the string"):  # float("0.1") would read it
        ls.integrate(sys, [0.0, 1.0, 0.5], (0.0, 1.0), h="0.1")
    for span in (("0", "1"), "01"):
        with pytest.raises(TypeError, match="t_span"):
            ls.integrate(sys, [0.0, 1.0, 0.5], span, h=0.1)
    with pytest.raises(ValueError, match="empty"):
        ls.integrate(sys, np.zeros((0, 3)), (0.0, 1.0), h=0.1)


def test_gamma0_on_general_algebra_names_argument():
    alg = ls.se(3)
    sys = ls.SuslovSystem(ls.Inertia(alg, np.eye(6)), constraints=ls.Subspace.annihilator(alg, np.eye(6)[:1]))
    with pytest.raises(ValueError, match="Gamma0"):
        ls.integrate(sys, np.eye(6)[1], (0.0, 1.0), h=0.1, Gamma0=[0.0, 0.0, 1.0])
