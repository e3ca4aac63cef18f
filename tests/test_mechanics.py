"""Potentials, SuslovSystem (reference form, diagnostics, validation) and the models of each form."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import liesuslov as ls
from liesuslov.algebra import Inertia, Subspace, se, so, suslov_distribution
from liesuslov.mechanics import (
    FamilyPotential,
    LinearPotential,
    ModelProtocol,
    Potential,
    QuadraticPotential,
    SuslovSystem,
    ZeroPotential,
    check_gradient,
)
from liesuslov.mechanics import models as models_module
from liesuslov.mechanics.system import gyroscopic_torque

RTOL = 1e-12  # forms against the reference: rounding level, relative to the size of the field

seeds = st.integers(0, 2**32 - 1)


def unit(rng, shape, n):
    G = rng.standard_normal(tuple(shape) + (n,))
    return G / np.linalg.norm(G, axis=-1, keepdims=True)


def random_spd(rng, n, lo=1.0):
    A = rng.standard_normal((n, n))
    return A @ A.T / n + lo * np.eye(n)


def cubic_potential(n):
    """A general (non-polynomial-structured) potential with its exact gradient."""
    c = np.linspace(0.5, 1.5, n)

    def V(G):
        return np.sin(G @ c) + 0.5 * G[..., 0] ** 3

    def grad(G):
        g = np.cos(G @ c)[..., None] * c
        g[..., 0] += 1.5 * G[..., 0] ** 2
        return g
    return Potential(V, grad, n=n)


def family_potential():
    return FamilyPotential(lambda s, r: s ** 3 + s * r, lambda s, r: (3 * s ** 2 + r, s),
                           lambda t, q: np.cos(t) * q, lambda t, q: (-np.sin(t) * q, np.cos(t)))


# ====================================================================== potentials
def test_linear_and_quadratic_values_batched():
    rng = np.random.default_rng(0)
    G = unit(rng, (4, 2), 3)
    B = np.array([1.0, -2.0, 0.5])
    P = LinearPotential(B)
    assert P.kind == "linear" and P.n == 3
    np.testing.assert_allclose(P.V(G), G @ B)
    np.testing.assert_allclose(P.grad(G), np.broadcast_to(B, G.shape))
    Q = QuadraticPotential(B)
    assert Q.diagonal is not None
    np.testing.assert_allclose(Q.V(G), 0.5 * np.sum(B * G ** 2, axis=-1))
    np.testing.assert_allclose(Q.grad(G), B * G)
    S = random_spd(rng, 3)
    Qm = QuadraticPotential(S)
    assert Qm.diagonal is None
    np.testing.assert_allclose(Qm.V(G), 0.5 * np.einsum("...i,ij,...j->...", G, S, G))
    assert QuadraticPotential(np.diag(B)).diagonal is not None
    Z = ZeroPotential()
    assert Z.is_zero and Z.V(G).shape == (4, 2) and not Z.grad(G).any()


@settings(max_examples=25, deadline=None)
@given(seeds, st.integers(2, 7))
def test_builtin_gradients_pass_the_checker(seed, n):
    rng = np.random.default_rng(seed)
    for P in (LinearPotential(rng.standard_normal(n)), QuadraticPotential(rng.standard_normal(n)),
              QuadraticPotential(random_spd(rng, n)), cubic_potential(n)):
        assert check_gradient(P, seed=seed).ok


def test_family_potential_gradient():
    assert check_gradient(family_potential()).max_error < 1e-7


def test_gradient_checker_finds_a_wrong_gradient():
    wrong = Potential(lambda G: G[..., 0] ** 2 * G[..., 1], lambda G: np.stack(
        [2 * G[..., 0] * G[..., 1], 2 * G[..., 0] ** 2, 0 * G[..., 2]], -1), n=3)  # d/dG_1 is G_0^2
    report = check_gradient(wrong)
    assert not report.ok and report.max_error > 0.1
    worst = report.worst_point
    np.testing.assert_allclose(report.finite_difference[1], worst[0] ** 2, atol=1e-8)
    assert "WRONG" in str(report)
    with pytest.raises(ValueError, match="grad disagrees"):
        check_gradient(wrong, raise_error=True)
    with pytest.raises(ValueError, match="grad disagrees"):
        wrong.check_gradient(np.array([[0.6, 0.8, 0.0]]), raise_error=True)


def test_potential_validation():
    with pytest.raises(TypeError, match="V must be a callable"):
        Potential(1.0, lambda G: G)
    with pytest.raises(TypeError, match="grad must be a callable"):
        Potential(lambda G: G[..., 0], None)
    assert np.array_equal(QuadraticPotential([[1.0, 2.0], [0.0, 1.0]]).matrix, [[1.0, 1.0], [1.0, 1.0]])
    with pytest.raises(ValueError, match="B must have shape"):
        QuadraticPotential(np.ones((2, 3)))
    with pytest.raises(ValueError, match="B must be a vector"):
        LinearPotential(np.ones((2, 2)))
    with pytest.raises(ValueError, match="n is required"):
        check_gradient(Potential(lambda G: G[..., 0], lambda G: G))


# ====================================================================== systems: validation
def fk_system(I, potential=None, gyroscopic=0.0, constraints=None):
    return SuslovSystem(Inertia.from_mass_tensor(I), constraints=constraints, potential=potential,
                        gyroscopic=gyroscopic)


def sleigh(I=1.0, m=2.0, a=0.5):
    """Chaplygin-sleigh-like EPS system on se(2): (omega, v_x, v_y), no sideways slip v_y = 0."""
    alg = se(2)
    K = np.array([[I + m * a * a, 0.0, m * a], [0.0, m, 0.0], [m * a, 0.0, m]])
    return SuslovSystem(Inertia(alg, K), constraints=Subspace.annihilator(alg, [[0.0, 0.0, 1.0]]))


def test_system_rejects_bad_input():
    J = Inertia.from_mass_tensor([1.0, 2.0, 3.0, 4.0])
    with pytest.raises(TypeError, match="inertia"):
        SuslovSystem(np.eye(6))
    with pytest.raises(ValueError, match="symmetric"):
        Inertia.from_mass_tensor([[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match="gyroscopic"):
        SuslovSystem(J, gyroscopic=0.5)
    with pytest.raises(ValueError, match="potential acts on Gamma of dimension 3"):
        SuslovSystem(J, potential=LinearPotential([1.0, 0.0, 0.0]))
    with pytest.raises(TypeError, match="potential must be a Potential"):
        SuslovSystem(J, potential=np.ones(4))
    with pytest.raises(ValueError, match="potential.grad must map"):
        SuslovSystem(J, potential=Potential(lambda G: G[..., 0], lambda G: G[..., :2]))
    with pytest.raises(TypeError, match="constraints must be a Subspace"):
        SuslovSystem(J, constraints=np.eye(6)[:3])
    with pytest.raises(ValueError, match="constraints live in"):
        SuslovSystem(J, constraints=suslov_distribution(3))
    alg = se(2)
    K = np.diag([1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="constraints are required"):
        SuslovSystem(Inertia(alg, K))
    D = Subspace.annihilator(alg, [[0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match="potential must be None on se"):
        SuslovSystem(Inertia(alg, K), D, potential=LinearPotential([1.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="gyroscopic must be 0 on se"):
        SuslovSystem(Inertia(alg, K), D, gyroscopic=1.0)
    SuslovSystem(Inertia(alg, K), D, potential=ZeroPotential())  # V = 0 is fine


def test_methods_validate_omega_and_gamma():
    s = fk_system([1.0, 2.0, 3.0, 4.0], QuadraticPotential([4.0, 3.0, 2.0, 1.0]))
    G = np.array([0.0, 0.0, 0.6, 0.8])
    with pytest.raises(ValueError, match="Omega must be"):
        s.energy(np.ones(5), G)
    with pytest.raises(ValueError, match="Omega as \\(4, 4\\) matrices must be skew-symmetric"):
        s.energy(np.ones((4, 4)), G)
    with pytest.raises(ValueError, match="Gamma is required"):
        s.energy(np.zeros(6))
    with pytest.raises(ValueError, match="Gamma must have shape"):
        s.rhs(np.zeros(6), np.ones(3))
    with pytest.raises(ValueError, match="NaN"):
        s.multipliers(np.full(6, np.nan), G)
    with pytest.raises(ValueError, match="Omega is not in D"):
        s.divergence(np.ones(6), G)
    with pytest.raises(ValueError, match="gamma=False is impossible"):
        s.model(gamma=False)
    with pytest.raises(TypeError, match="gamma must be"):
        s.model(gamma="yes")
    with pytest.raises(ValueError, match="form must be one of"):
        s.model(form="fast")
    free = fk_system(random_spd(np.random.default_rng(1), 4))
    with pytest.raises(ValueError, match="form='symmetric' does not hold.*not an invariant subspace"):
        free.model(form="symmetric")
    with pytest.raises(ValueError, match="form='eigenspace' does not hold"):
        free.model(form="eigenspace")
    with pytest.raises(ValueError, match="gamma=True needs a body in SO"):
        sleigh().model(gamma=True)


def test_omega_as_matrices_or_coordinates():
    s = fk_system([1.0, 2.0, 3.0], LinearPotential([0.0, 0.0, 1.0]))
    alg = so(3)
    x = np.array([[0.0, 0.3, -0.2], [0.0, -0.1, 0.5]])
    G = unit(np.random.default_rng(0), (2,), 3)
    np.testing.assert_allclose(s.energy(alg.hat(x), G), s.energy(x, G))
    np.testing.assert_allclose(s.rhs(alg.hat(x), G)[0], s.rhs(x, G)[0])


# ====================================================================== the equations
def test_gyroscopic_torque_is_the_vector_form():
    rng = np.random.default_rng(3)
    x, G = rng.standard_normal((2, 5, 3))
    w = so(3).to_vector3(x)
    want = so(3).from_vector3(0.7 * np.cross(G, w))
    np.testing.assert_allclose(gyroscopic_torque(x, G, 0.7), want, atol=1e-15)


@settings(max_examples=20, deadline=None)
@given(seeds)
def test_reference_form_is_the_papers_vector_form(seed):
    """(3.1): J w' = J w x w + Gamma x dV/dGamma + eps Gamma x w + lambda a,  Gamma' = Gamma x w, w3 = 0."""
    rng = np.random.default_rng(seed)
    Jw = random_spd(rng, 3)  # a full symmetric J: a = e3 is not an eigenvector
    eps = rng.normal()
    s = SuslovSystem(Inertia.from_principal_moments(Jw), potential=cubic_potential(3), gyroscopic=eps)
    w = np.array([rng.normal(), rng.normal(), 0.0])
    G = unit(rng, (), 3)
    f = np.cross(Jw @ w, w) + np.cross(G, s.potential.grad(G)) + eps * np.cross(G, w)
    e3 = np.array([0.0, 0.0, 1.0])
    Jinv = np.linalg.inv(Jw)
    lam = -(e3 @ Jinv @ f) / (e3 @ Jinv @ e3)
    wdot = Jinv @ (f + lam * e3)
    xdot, Gdot = s.rhs(so(3).from_vector3(w), G)
    np.testing.assert_allclose(so(3).to_vector3(xdot), wdot, atol=1e-12 * (1 + np.abs(wdot).max()))
    np.testing.assert_allclose(Gdot, np.cross(G, w), atol=1e-14)
    np.testing.assert_allclose(s.multipliers(so(3).from_vector3(w), G), [-lam], rtol=1e-10, atol=1e-12)


@settings(max_examples=20, deadline=None)
@given(seeds, st.integers(3, 5), st.integers(1, 4))
def test_energy_is_conserved_by_the_reference_field_for_any_D(seed, n, r):
    """dE/dt = <J Omega, Omega'> + <dV, Gamma'> = 0 for random constraints, mass tensor and potential."""
    rng = np.random.default_rng(seed)
    alg = so(n)
    r = min(r, alg.dim - 1)
    D = Subspace.annihilator(alg, rng.standard_normal((r, alg.dim)))
    s = fk_system(random_spd(rng, n), cubic_potential(n), constraints=D)
    x = rng.standard_normal((3, D.dim)) @ D.basis
    G = unit(rng, (3,), n)
    xdot, Gdot = s.rhs(x, G)
    dE = np.sum(s.inertia(x) * xdot, axis=-1) + np.sum(s.potential.grad(G) * Gdot, axis=-1)
    np.testing.assert_allclose(dE, 0.0, atol=1e-11 * (1 + np.abs(xdot).max()))
    assert np.all(D.contains(xdot, 1e-10))  # the constraints hold at first order


def _rows_alone_equal(f, *arrays) -> bool:
    """Every row of ``f(*arrays)`` (arrays batch-first) equals, bit for bit, ``f`` on that row alone."""
    full = f(*arrays)
    full = full if isinstance(full, tuple) else (full,)
    for b in range(arrays[0].shape[0]):
        one = f(*(a[b:b + 1] for a in arrays))
        one = one if isinstance(one, tuple) else (one,)
        if not all(x is None or np.array_equal(x[b:b + 1], y) for x, y in zip(full, one, strict=True)):
            return False
    return True


def test_reference_form_gives_a_row_the_same_bits_alone_or_in_a_batch():
    """A dense D, a full mass tensor and a full quadratic potential (so(5)), and se(3) with a full K: the
    reference form's products of a batch with matrices went through BLAS (matmul, einsum with optimize),
    which sums a row differently by its position in the batch (most of 200 rows differed from themselves
    alone); the research tools evaluate it on batches."""
    rng = np.random.default_rng(5)
    D = Subspace.annihilator(so(5), rng.normal(size=(3, 10)))
    S = rng.normal(size=(5, 5))
    s = SuslovSystem(Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0, 4.0, 5.0]) + 0.1), constraints=D,
                        potential=QuadraticPotential(S + S.T))
    x = 0.3 * rng.normal(size=(200, D.dim)) @ D.basis
    G = unit(rng, (200,), 5)
    for method in (s.rhs, s.energy, s.multipliers, s.divergence):
        assert _rows_alone_equal(method, x, G), method.__name__
    K = rng.normal(size=(6, 6))
    D6 = Subspace.annihilator(se(3), rng.normal(size=(2, 6)))
    s6 = SuslovSystem(Inertia(se(3), K @ K.T + 6 * np.eye(6)), constraints=D6)
    x6 = rng.normal(size=(200, D6.dim)) @ D6.basis
    for method in (s6.rhs, s6.multipliers, s6.divergence):
        assert _rows_alone_equal(method, x6), method.__name__


# ====================================================================== the forms
def coordinate_subspace(n, pairs):
    alg = so(n)
    return Subspace(alg, np.eye(alg.dim)[[alg.index(i, j) for i, j in pairs]])


def scene_list():
    """(label, system, expected auto form) covering every path of the models."""
    rng = np.random.default_rng(7)
    I4 = np.array([1.0, 2.0, 3.0, 4.0])
    block = np.diag([1.0, 2.0, 3.0, 4.0])
    block[0, 1] = block[1, 0] = 0.4  # I' non-diagonal, I_in = 0: D still J-invariant, K_D not diagonal
    permuted_fk = Subspace(so(4), suslov_distribution(4).basis[[2, 0, 1]])
    grassmann = coordinate_subspace(4, [(0, 2), (0, 3), (1, 2), (1, 3)])  # p of (so(4), so(2) + so(2))
    eigen_only = coordinate_subspace(4, [(0, 1), (0, 2), (2, 3)])
    random_D = Subspace.annihilator(so(5), rng.standard_normal((4, 10)))
    S4 = random_spd(rng, 4)
    return [
        ("fk zero", fk_system(I4), "symmetric"),
        ("fk linear", fk_system(I4, LinearPotential([0.3, -0.2, 0.5, 0.7])), "symmetric"),
        ("fk kharlamova", fk_system(I4, LinearPotential([0.3, -0.2, 0.5, 0.0])), "symmetric"),
        ("fk lagrange", fk_system([1.0, 1.0, 1.0, 2.0], LinearPotential([0.0, 0.0, 0.0, 0.7])), "symmetric"),
        ("fk quadratic diag", fk_system(I4, QuadraticPotential([4.0, 3.0, 2.0, 1.0])), "symmetric"),
        ("fk quadratic matrix", fk_system(I4, QuadraticPotential(S4)), "symmetric"),
        ("fk general", fk_system(I4, cubic_potential(4)), "symmetric"),
        ("fk family", fk_system([1.0, 2.0, 3.0], family_potential()), "symmetric"),
        ("fk gyro V=0", fk_system([1.0, 2.0, 3.0], gyroscopic=0.7), "symmetric"),
        ("fk gyro quad", fk_system([1.0, 2.0, 3.0], QuadraticPotential([1.0, 2.0, 0.5]), 0.7), "symmetric"),
        ("fk block I", fk_system(block, QuadraticPotential([4.0, 3.0, 2.0, 1.0])), "symmetric"),
        ("fk block I gyro", fk_system([[1.0, 0.3, 0.0], [0.3, 2.0, 0.0], [0.0, 0.0, 3.0]],
                                      cubic_potential(3), 0.4), "symmetric"),
        ("permuted fk basis", fk_system(I4, QuadraticPotential(S4), constraints=permuted_fk), "symmetric"),
        ("grassmannian", fk_system(I4, cubic_potential(4), constraints=grassmann), "symmetric"),
        ("eigenspace only", fk_system(I4, LinearPotential([0.3, -0.2, 0.5, 0.7]), constraints=eigen_only),
         "eigenspace"),
        ("suslov free", fk_system(random_spd(rng, 4)), "reduced"),
        ("reduced + V + gyro", fk_system(random_spd(rng, 3), QuadraticPotential([1.0, 2.0, 0.5]), 0.9),
         "reduced"),
        ("random D so(5)", fk_system(random_spd(rng, 5), cubic_potential(5), constraints=random_D),
         "reduced"),
        ("sleigh se(2)", sleigh(), "reduced"),
        ("se(3)", SuslovSystem(Inertia(se(3), random_spd(rng, 6)),
                               Subspace.annihilator(se(3), rng.standard_normal((2, 6)))), "reduced"),
    ]


SCENES = scene_list()


def check_against_reference(s, form, seed=0, gamma=None):
    rng = np.random.default_rng(seed)
    m = s.model(gamma=gamma, form=form)
    ref = s.model(gamma=gamma, form="multiplier")
    xi = rng.standard_normal((4, m.k))
    G = unit(rng, (4,), s.n) if m.has_gamma else None
    x = m.omega_coords(xi)
    want, Gwant = s.rhs(x, G)
    got = m.omega_coords(m.xi_dot(xi, G))
    scale = 1.0 + np.abs(want).max()
    np.testing.assert_allclose(got, want, rtol=0, atol=RTOL * scale)
    np.testing.assert_allclose(ref.xi_dot(x, G), want, rtol=0, atol=RTOL * scale)
    np.testing.assert_allclose(m.xi_from_coords(x), xi, atol=1e-14)
    if m.n is not None:
        np.testing.assert_allclose(m.omega_matrix(xi), s.algebra.hat(x), atol=1e-14)
    if m.has_gamma:
        np.testing.assert_allclose(m.Gamma_dot(xi, G), Gwant, atol=1e-14)
        np.testing.assert_allclose(m.Gamma_dot(xi, G), -(s.algebra.hat(x) @ G[..., None])[..., 0], atol=1e-14)


@pytest.mark.parametrize("label,system,auto", SCENES, ids=[s[0] for s in SCENES])
def test_every_form_agrees_with_the_reference(label, system, auto):
    assert system.model().form == auto
    forms = system.available_forms()
    assert forms[0] == auto and forms[-2:] == ["reduced", "multiplier"]
    for form in forms:
        check_against_reference(system, form)
        if system.is_so and not system.needs_gamma:
            check_against_reference(system, form, gamma=True)


@settings(max_examples=15, deadline=None)
@given(seeds, st.integers(3, 7))
def test_fk_symmetric_form_agrees_for_random_diagonal_bodies(seed, n):
    rng = np.random.default_rng(seed)
    I = rng.uniform(0.5, 3.0, n)
    for pot in (QuadraticPotential(rng.normal(size=n)), LinearPotential(rng.normal(size=n)),
                cubic_potential(n)):
        s = fk_system(I, pot)
        m = s.model()
        assert m.form == "symmetric" and m.fedorov_kozlov and "O(n)" in m.path
        check_against_reference(s, "symmetric", seed)


def test_quadratic_term_by_commutators(monkeypatch):
    """The large-k path (matrix commutators instead of the k^3 tensor) agrees with the reference."""
    monkeypatch.setattr(models_module, "_TENSOR_MAX_K", 0)
    rng = np.random.default_rng(5)
    for s in (fk_system(random_spd(rng, 5), cubic_potential(5)),
              fk_system(random_spd(rng, 4), QuadraticPotential(random_spd(rng, 4)),
                        constraints=Subspace.annihilator(so(4), rng.standard_normal((2, 6))))):
        m = s.model(form="reduced")
        assert "commutators" in m.path
        check_against_reference(s, "reduced")


def test_fk_xi_dot_closed_form():
    """(4.3): (I_i + I_n) xi_i' = dV_i Gamma_n - Gamma_i dV_n."""
    rng = np.random.default_rng(11)
    I = np.array([1.0, 1.5, 2.5, 3.0, 4.0])
    pot = cubic_potential(5)
    m = fk_system(I, pot).model()
    xi = rng.normal(size=(3, 4))
    G = unit(rng, (3,), 5)
    g = pot.grad(G)
    want = (g[:, :4] * G[:, 4:] - G[:, :4] * g[:, 4:]) / (I[:4] + I[4])
    np.testing.assert_allclose(m.xi_dot(xi, G), want, atol=1e-15)


# ====================================================================== the model object
def test_model_attributes_and_gamma_selection():
    I4 = [1.0, 2.0, 3.0, 4.0]
    m = fk_system(I4, QuadraticPotential([4.0, 3.0, 2.0, 1.0])).model()
    summary = (m.form, m.k, m.n, m.has_gamma, m.state_dim, m.fedorov_kozlov)
    assert summary == ("symmetric", 3, 4, True, 7, True)
    assert m.algebra is so(4) and m.subspace.dim == 3 and m.system.model() is m
    assert "symmetric" in m.description() and "7" in m.description()
    free = fk_system(I4)
    m0 = free.model()
    assert not m0.has_gamma and m0.state_dim == 3 and "Gamma (V = 0)" in m0.description()
    assert free.model(gamma=True).state_dim == 7
    np.testing.assert_array_equal(m0.xi_dot(np.ones(3), None), 0.0)  # J(D) ⊂ D, V = 0: Omega constant
    mult = free.model(form="multiplier")
    assert mult.k == 6 and not mult.fedorov_kozlov and mult.subspace.dim == 6
    permuted = Subspace(so(4), suslov_distribution(4).basis[[1, 0, 2]])
    assert not fk_system(I4, constraints=permuted).model().fedorov_kozlov
    gyro = fk_system([1.0, 2.0, 3.0], gyroscopic=0.3).model()
    assert gyro.has_gamma and gyro.state_dim == 5  # the gyroscopic term needs Gamma even with V = 0
    sl = sleigh().model()
    summary = (sl.form, sl.has_gamma, sl.n, sl.k, sl.state_dim, sl.fedorov_kozlov)
    assert summary == ("reduced", False, 3, 2, 2, False)


def test_model_batches_and_broadcasts():
    s = fk_system([1.0, 2.0, 3.0, 4.0], QuadraticPotential(random_spd(np.random.default_rng(0), 4)))
    rng = np.random.default_rng(1)
    xi = rng.normal(size=(2, 5, 3))
    G = unit(rng, (2, 5), 4)
    for form in s.available_forms():
        m = s.model(form=form)
        xk = xi if form != "multiplier" else m.xi_from_coords(s.model().omega_coords(xi))
        assert m.xi_dot(xk, G).shape == (2, 5, m.k)
        assert m.xi_dot(xk[0, 0], G).shape == (2, 5, m.k)  # one Omega, many Gamma
        assert m.omega_matrix(xk).shape == (2, 5, 4, 4)
        assert m.Gamma_dot(xk, G).shape == (2, 5, 4)
        y = np.concatenate([xk[0, 0], G[0, 0]])
        assert m.vector_field(0.0, y).shape == (m.state_dim,)


def test_fk_model_at_n64_is_linear_in_n():
    n = 64
    I = np.linspace(1.0, 2.0, n)
    B = np.linspace(3.0, 1.0, n)
    m = fk_system(I, QuadraticPotential(B)).model()
    rng = np.random.default_rng(0)
    xi = rng.normal(size=n - 1)
    G = unit(rng, (), n)
    want = (B[:-1] - B[-1]) * G[:-1] * G[-1] / (I[:-1] + I[-1])
    np.testing.assert_allclose(m.xi_dot(xi, G), want, rtol=1e-14)
    Om = m.omega_matrix(xi)
    np.testing.assert_array_equal(Om[:-1, :-1], 0.0)
    np.testing.assert_allclose(m.Gamma_dot(xi, G), -Om @ G, atol=1e-14)


# ====================================================================== divergence and multipliers
def fd_divergence(m, xi, G, h=1e-6):
    tot = 0.0
    for a in range(m.k):
        e = np.zeros(m.k)
        e[a] = h
        tot += (m.xi_dot(xi + e, G)[a] - m.xi_dot(xi - e, G)[a]) / (2 * h)
    if m.has_gamma:
        for j in range(m.n):
            e = np.zeros(m.n)
            e[j] = h
            tot += (m.Gamma_dot(xi, G + e)[j] - m.Gamma_dot(xi, G - e)[j]) / (2 * h)
    return tot


@pytest.mark.parametrize("label,system,auto", SCENES, ids=[s[0] for s in SCENES])
def test_divergence_is_the_trace_of_the_jacobian(label, system, auto):
    rng = np.random.default_rng(2)
    m = system.model(form="reduced")
    xi = rng.normal(size=m.k)
    G = unit(rng, (), system.n) if m.has_gamma else None
    div = system.divergence(m.omega_coords(xi), G)
    np.testing.assert_allclose(div, fd_divergence(m, xi, G), atol=1e-7)
    if auto in ("symmetric", "eigenspace"):
        assert abs(div) < 1e-13  # J(D) ⊂ D on so(n): the measure d Omega d Gamma is invariant
    if label in ("suslov free", "random D so(5)"):
        assert abs(div) > 1e-3


def test_sleigh_has_no_invariant_measure_and_conserves_energy():
    from scipy.integrate import solve_ivp

    s = sleigh()
    m = s.model()
    sol = solve_ivp(m.vector_field, (0.0, 40.0), [1.0, 0.2], method="DOP853", rtol=1e-12, atol=1e-12)
    x = m.omega_coords(sol.y.T)
    E = s.energy(x)
    assert np.max(np.abs(E - E[0])) < 1e-10
    assert abs(x[-1, 0]) < 1e-3 * abs(x[0, 0])  # the rotation dies out: v_x carries the energy
    assert abs(s.divergence(x[0])) > 1e-3


def test_multipliers_of_the_fk_symmetric_form():
    """lambda_ij = (I_i - I_j) Omega_in Omega_jn - (dV_i Gamma_j - Gamma_i dV_j), i < j < n."""
    rng = np.random.default_rng(4)
    n = 5
    I = rng.uniform(1.0, 3.0, n)
    pot = cubic_potential(n)
    s = fk_system(I, pot)
    m = s.model()
    xi = rng.normal(size=(2, n - 1))
    G = unit(rng, (2,), n)
    g = pot.grad(G)
    r, c = np.triu_indices(n - 1, 1)
    want = (I[r] - I[c]) * xi[:, r] * xi[:, c] - (g[:, r] * G[:, c] - G[:, r] * g[:, c])
    np.testing.assert_allclose(s.multipliers(m.omega_coords(xi), G), want, atol=1e-12)


# ====================================================================== lazy inertia
def _dense_K(I):
    """K[a, b] = <E_a, I E_b + E_b I> from the basis matrices (the definition, O(d n^3))."""
    E = so(I.shape[0]).representation
    JE = I @ E + E @ I
    return np.einsum("aij,bij->ab", E, JE) / 2.0  # <A, B> = -1/2 tr(AB) = 1/2 sum A_ij B_ij for skew A


@pytest.mark.parametrize("n", [2, 3, 4, 5, 7])
@pytest.mark.parametrize("diagonal", [True, False])
def test_lazy_inertia_equals_the_dense_matrix(n, diagonal, monkeypatch):
    """Inertia.from_mass_tensor keeps I, builds K only on access, and every action (through K for small
    dimensions, through I Omega + Omega I and the Sylvester solution above) equals the dense matrix."""
    from liesuslov.algebra import inertia as inertia_module

    rng = np.random.default_rng(10 * n + diagonal)
    I = np.diag(rng.uniform(0.5, 2.0, n)) if diagonal else random_spd(rng, n)
    J = Inertia.from_mass_tensor(I)
    assert "matrix" not in J.__dict__
    K = _dense_K(I)
    x = rng.standard_normal((2, 3, J.dim))
    D = suslov_distribution(n) if n >= 3 else Subspace(so(2), np.eye(1))
    S = Subspace(so(n), rng.standard_normal((max(1, J.dim // 2), J.dim)))
    for limit in (64, 0):  # the K path, then the mass-tensor path (I Omega + Omega I, Sylvester)
        monkeypatch.setattr(inertia_module, "_DENSE_ACTION_MAX_DIM", limit)
        np.testing.assert_allclose(J(x), x @ K, rtol=0, atol=1e-14 * np.abs(K).max())
        np.testing.assert_allclose(J.inverse(J(x)), x, rtol=0, atol=1e-13 * np.linalg.cond(K))
        np.testing.assert_allclose(J.kinetic_energy(x), 0.5 * np.sum((x @ K) * x, -1), rtol=1e-14)
        for sub in (D, S):
            np.testing.assert_allclose(J.restrict(sub), sub.basis @ K @ sub.basis.T, rtol=0, atol=1e-14 * n)
    assert J.is_invariant(D) == (diagonal or n == 2)
    assert J._max_abs_entry() == pytest.approx(np.abs(K).max(), rel=1e-15)
    np.testing.assert_allclose(J.matrix, K, rtol=0, atol=1e-15 * np.abs(K).max())
    np.testing.assert_allclose(J.inverse_matrix, np.linalg.inv(K), rtol=0, atol=1e-13 * np.linalg.cond(K))
    assert not J.matrix.flags.writeable and not J.inverse_matrix.flags.writeable


def test_lazy_inertia_sparse_restriction_and_invariance():
    """Diagonal mass tensor, coordinate subspaces: restriction and J-invariance by sparse products, equal
    to the dense formulas; a subspace mixing eigenspaces is not invariant."""
    rng = np.random.default_rng(3)
    n = 6
    I = rng.uniform(0.5, 2.0, n)
    J = Inertia.from_mass_tensor(I)
    K = _dense_K(np.diag(I))
    D = suslov_distribution(n)
    assert J._sparse_basis(D.basis) is not None
    np.testing.assert_allclose(J.restrict(D), np.diag(I[:-1] + I[-1]), rtol=1e-15)
    assert J.is_invariant(D) and J.is_invariant(D.complement())
    mixed = Subspace(so(n), D.basis[0] + D.basis[1])  # E_1n + E_2n: eigenvalues I_1 + I_n != I_2 + I_n
    np.testing.assert_allclose(J.restrict(mixed), mixed.basis @ K @ mixed.basis.T, rtol=1e-15)
    assert not J.is_invariant(mixed)
    assert "matrix" not in J.__dict__


def test_fedorov_kozlov_model_never_builds_K():
    """The O(n) symmetric model at n = 64 (d = 2016) comes from the mass tensor alone."""
    n = 64
    J = Inertia.from_mass_tensor(np.linspace(1.0, 2.0, n))
    s = SuslovSystem(J, potential=QuadraticPotential(np.linspace(3.0, 1.0, n)))
    m = s.model()
    assert m.form == "symmetric" and "O(n)" in m.path
    np.testing.assert_allclose(m.reduced_inertia, np.diag(J.mass_tensor.diagonal()[:-1] + J.mass_tensor[-1, -1]))
    assert "matrix" not in J.__dict__ and "inverse_matrix" not in J.__dict__



@pytest.mark.parametrize("n", [3, 6, 40])
def test_fedorov_kozlov_coordinate_maps_are_the_plane_rotations_e_in(n):
    """omega_coords puts xi_i at the coordinate of E_in and exact zeros elsewhere, for any batch axes;
    xi_from_coords reads them back (the two maps of the Fedorov–Kozlov model, against the algebra's index)."""
    s = SuslovSystem(Inertia.from_mass_tensor(np.linspace(1.0, 2.0, n)), constraints="fedorov_kozlov")
    m = s.model()
    alg = s.algebra
    k = n - 1
    xi = np.random.default_rng(n).standard_normal((2, 3, k))
    x = m.omega_coords(xi)
    want = np.zeros((2, 3, alg.dim))
    for i in range(k):
        want[..., alg.index(i, n - 1)] = xi[..., i]
    np.testing.assert_array_equal(x, want)
    ref = np.zeros((2, 3, n, n))  # Omega = u e_n^T - e_n u^T, built here from the definition
    ref[..., :k, n - 1] = xi
    ref[..., n - 1, :k] = -xi
    np.testing.assert_array_equal(alg.hat(x), ref)
    np.testing.assert_array_equal(m.xi_from_coords(x), xi)
    np.testing.assert_array_equal(m.omega_coords(xi[0, 0]), want[0, 0])  # one vector
    np.testing.assert_array_equal(m.xi_from_coords(list(want[0, 0])), xi[0, 0])  # array_like

# ---------------------------------------------------------------------- pickling (issue 12)
def _cube_V(G):
    return G[..., 0] ** 3


def _cube_grad(G):
    out = np.zeros_like(G)
    out[..., 0] = 3.0 * G[..., 0] ** 2
    return out


def _integrate_case(system, case, method="rkmk4"):
    omega0, Gamma0 = case.random_state(7, 3, scale=0.5)
    return ls.integrate(system, omega0, (0.0, 0.5), Gamma0=Gamma0, method=method, h=0.05, backend="numpy")


@pytest.mark.parametrize("name", sorted(ls.CASES))
def test_systems_models_and_solutions_pickle_also_after_integrate(name):
    import pickle

    case = ls.CASES[name].build()
    system = case.system
    before = pickle.loads(pickle.dumps(system))  # before any model exists
    sol = _integrate_case(system, case)  # caches models built from closures in the system
    assert system.model() is not None
    after = pickle.loads(pickle.dumps(system))
    model = pickle.loads(pickle.dumps(system.model()))
    assert isinstance(model, ModelProtocol)
    assert (model.form, model.k, model.has_gamma, model.path) == (system.model().form, system.model().k,
                                                                   system.model().has_gamma, system.model().path)
    # the unpickled systems integrate to the same numbers, bit for bit (same arrays, same operations)
    for copy in (before, after, model.system):
        again = _integrate_case(copy, case)
        np.testing.assert_array_equal(again.omega, sol.omega)
        if sol.Gamma is not None:
            np.testing.assert_array_equal(again.Gamma, sol.Gamma)
    sol2 = pickle.loads(pickle.dumps(sol))
    np.testing.assert_array_equal(sol2.omega, sol.omega)
    assert sol2.stats["steps"] == sol.stats["steps"]


def test_multiplier_model_pickles():
    import pickle

    case = ls.CASES["suslov_free"].build()
    m = case.system.model(form="multiplier")
    m2 = pickle.loads(pickle.dumps(m))
    x = case.random_state(1, 4)[0]
    np.testing.assert_array_equal(m2.xi_dot(x, None), m.xi_dot(x, None))


def test_potentials_from_module_level_callables_pickle_and_lambdas_do_not():
    import pickle

    P = ls.Potential(_cube_V, _cube_grad, n=3)
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor([1.0, 2.0, 3.0]), potential=P)
    G = np.array([[0.6, 0.0, 0.8], [0.0, 1.0, 0.0]])
    s2 = pickle.loads(pickle.dumps(system))
    np.testing.assert_array_equal(s2.potential.grad(G), P.grad(G))
    F = ls.CASES["family3"].build().system.potential  # module-level example functions
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(F)).V(G), F.V(G))
    L = ls.Potential(lambda G: G[..., 0], lambda G: np.ones_like(G), n=3)
    with pytest.raises((pickle.PicklingError, AttributeError, TypeError), match="lambda"):
        pickle.dumps(L)


def test_pendulum_model_implements_the_protocol_and_pickles():
    import pickle

    P = ls.SphericalPendulum(3, m=2.0, B=1.0)
    m = P.model()
    assert isinstance(m, ModelProtocol)
    m2 = pickle.loads(pickle.dumps(m))
    xi, q = np.array([0.1, -0.2, 0.3]), np.array([0.0, 0.6, 0.8])
    np.testing.assert_array_equal(m2.xi_dot(xi, q), m.xi_dot(xi, q))
    np.testing.assert_array_equal(m2.omega_matrix(xi), m.omega_matrix(xi))


def test_every_model_implements_the_protocol_with_the_documented_shapes():
    for name, entry in ls.CASES.items():
        system = entry.build().system
        assert not isinstance(system, ModelProtocol)  # integrate tells a system from a model this way
        for form in system.available_forms():
            m = system.model(form=form)
            assert isinstance(m, ModelProtocol), (name, form)
            xi = np.ones((2, m.k)) * 0.1
            G = np.tile(np.eye(m.n)[-1], (2, 1)) if m.has_gamma else None
            assert m.xi_dot(xi, G).shape == (2, m.k)
            assert m.omega_matrix(xi).shape == (2, m.n, m.n)
            x = m.omega_coords(xi)
            assert x.shape == (2, m.algebra.dim)
            np.testing.assert_allclose(m.xi_from_coords(x), xi, atol=1e-15)
            assert m.state_dim == m.k + (m.n if m.has_gamma else 0)


def test_mechanics_modules_import_no_cycle():
    # system builds models; models need only the lower modules (forces, protocol) at run time
    import ast
    from pathlib import Path

    src = Path(ls.mechanics.__file__).parent / "models.py"
    tree = ast.parse(src.read_text(encoding="utf-8"))
    top_level = [n for n in tree.body if isinstance(n, ast.ImportFrom)]
    assert not any(n.module == "system" for n in top_level)


# ---------------------------------------------------------------------- small frictions (issue 13)
def test_constraints_none_means_the_whole_algebra():
    J = ls.Inertia.from_mass_tensor([1.0, 2.0, 3.0, 4.0])
    free = ls.SuslovSystem(J, constraints="none")
    assert free.constraints.dim == 6
    assert ls.SuslovSystem(J).constraints.dim == 3  # the default stays Fedorov–Kozlov
    assert ls.SuslovSystem(J, constraints="fedorov_kozlov").is_fedorov_kozlov
    x0 = np.array([0.3, -0.2, 0.1, 0.4, 0.2, -0.1])
    sol = ls.integrate(free, x0, (0.0, 1.0), method="rkmk45", rtol=1e-11, atol=1e-13, backend="numpy")
    # the free body: the Casimir |M|^2 is conserved (not true under constraints)
    M = J(sol.omega)
    np.testing.assert_allclose(np.sum(M * M, -1), np.sum(M[0] * M[0]), rtol=1e-9)
    se2 = ls.SuslovSystem(ls.Inertia(ls.se(2), np.diag([1.0, 2.0, 3.0])), constraints="none")
    assert se2.constraints.dim == 3
    with pytest.raises(ValueError, match='constraints must be a Subspace, "none"'):
        ls.SuslovSystem(J, constraints="free")
    with pytest.raises(ValueError, match="fedorov_kozlov.*is for so\\(n\\)"):
        ls.SuslovSystem(ls.Inertia(ls.se(2), np.eye(3)), constraints="fedorov_kozlov")


def test_random_state_takes_an_int_batch_size():
    case = ls.CASES["kharlamova"].build()
    omega, Gamma = case.random_state(0, 1000)
    assert omega.shape == (1000, 6) and Gamma.shape == (1000, 4)
    np.testing.assert_array_equal(case.random_state(0, (1000,))[0], omega)
    with pytest.raises(TypeError, match="batch must be an int or a tuple of ints"):
        case.random_state(0, "many")


@pytest.mark.parametrize("where", ["Omega0", "Gamma0", "mass tensor", "potential"])
def test_complex_input_is_a_type_error_not_a_dropped_imaginary_part(where):
    I = [1.0, 2.0, 3.0, 4.0]
    Omega0 = np.array([0.0, 0.0, 0.3, 0.0, -0.2, 0.5])
    Gamma0 = np.array([0.0, 0.6, 0.0, 0.8])
    with pytest.raises(TypeError, match="must be real, got complex values"):
        if where == "mass tensor":
            ls.Inertia.from_mass_tensor(np.array(I) + 1e-3j)
        elif where == "potential":
            ls.LinearPotential([0.0, 0.0, 0.0, 1.0 + 1j])
        else:
            system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), potential=ls.LinearPotential([0, 0, 0, 1.0]))
            kw = {"Omega0": Omega0 + 1e-3j if where == "Omega0" else Omega0,
                  "Gamma0": Gamma0 + 1e-3j if where == "Gamma0" else Gamma0}
            ls.integrate(system, kw["Omega0"], (0.0, 0.1), Gamma0=kw["Gamma0"], method="rkmk4", h=0.05)


def test_a_potential_returning_a_stacked_array_for_a_pair_is_caught():
    """FamilyPotential's derivatives return a pair; one returning np.stack(..., -1) passed the probe on a batch
    of 2 (unpacking its rows) and mixed the trajectories of every batch of 2."""
    p = FamilyPotential(lambda s, r: s * r, lambda s, r: np.stack([r, s], -1), lambda t, q: t * q,
                        lambda t, q: np.stack([q, t], -1))
    with pytest.raises(ValueError, match="potential could not be evaluated"):
        SuslovSystem(Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0])), potential=p)


def test_a_potential_returning_complex_numbers_is_a_type_error():
    """numpy casts a complex gradient to float with a ComplexWarning, dropping its imaginary part: refused at
    construction instead, naming which callable."""
    J = Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0]))
    complex_grad = Potential(lambda G: G[..., 2], lambda G: (1 + 1j) * G)
    with pytest.raises(TypeError, match=r"potential\.grad must return real numbers"):
        SuslovSystem(J, potential=complex_grad)
    complex_V = Potential(lambda G: 1j * G[..., 2], lambda G: G)
    with pytest.raises(TypeError, match=r"potential\.V must return real numbers"):
        SuslovSystem(J, potential=complex_V)
    SuslovSystem(J, potential=Potential(lambda G: G[..., 2] > 0, lambda G: 0 * G))  # booleans are numbers


def test_user_callables_cannot_write_into_the_integrated_state():
    """A gradient that assigned into its argument zeroed the integrator's Gamma and the run reported success with
    |Gamma| = 0 (an audit); user callables get the state read-only — potentials (caught at construction, with
    the fix) and events (which received views of the solver's Gamma and g)."""
    J = Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0]))

    def grad(G):
        G[...] = 0.0
        return np.zeros_like(G)

    with pytest.raises(ValueError, match="read-only: compute on a copy"):
        SuslovSystem(J, potential=Potential(lambda G: G[..., 0], grad))
    system = SuslovSystem(J, potential=ls.LinearPotential([0.0, 0.0, 1.0]))

    def meddling(t, Omega, Gamma, g):
        Gamma[..., 0] = 0.0
        return Gamma[..., 2] - 0.5

    with pytest.raises(ValueError, match=r"events\[0\] raised ValueError: assignment destination is read-only"):
        ls.integrate(system, [0.0, 0.6, -0.4], (0.0, 5.0), Gamma0=[0.0, 0.6, 0.8], method="rkmk45", events=meddling)


def test_mismatched_shapes_are_named():
    """numpy's broadcast errors named neither array (an audit): the potentials and the system say which."""
    with pytest.raises(ValueError, match=r"Gamma must have shape \(\.\.\., 3\)"):
        ls.LinearPotential([1.0, 2.0, 3.0]).grad(np.ones(4))
    with pytest.raises(ValueError, match=r"Gamma must have shape \(\.\.\., 3\)"):
        ls.QuadraticPotential([1.0, 2.0, 3.0]).V(np.ones((2, 4)))
    system = SuslovSystem(Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0, 4.0])),
                          potential=ls.QuadraticPotential([4.0, 3.0, 2.0, 1.0]))
    with pytest.raises(ValueError, match=r"batch axes of Omega \(2,\) and Gamma \(3,\) do not broadcast"):
        system.energy(np.zeros((2, 6)), np.full((3, 4), 0.5))
    assert system.energy(np.zeros((2, 6)), np.array([0.0, 0.0, 0.6, 0.8])).shape == (2,)


def test_cached_properties_do_not_serialise_instances():
    """On Python < 3.12 functools.cached_property holds one lock per attribute for all instances: a thread inside
    one system's cached property blocked every other system's first read, and a process forked then hung in
    the child (an audit). The package's cached_property holds none."""
    import threading

    from liesuslov._cached import cached_property

    assert isinstance(ls.SuslovSystem.__dict__["_forms"], cached_property)
    entered, release = threading.Event(), threading.Event()

    class Slow:
        def __init__(self, wait):
            self.wait = wait

        @cached_property
        def value(self):
            if self.wait:
                entered.set()
                release.wait(10.0)
            return 1.0

    inside = threading.Thread(target=lambda: Slow(True).value)
    inside.start()
    assert entered.wait(10.0)
    done = []
    other = threading.Thread(target=lambda: done.append(Slow(False).value))
    other.start()
    other.join(2.0)
    blocked = other.is_alive()
    release.set()
    inside.join()
    other.join()
    assert not blocked and done == [1.0]
