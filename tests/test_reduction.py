"""The SO(n−1) reduction of the Lagrange case to the spherical pendulum (liesuslov.reduction)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import liesuslov as ls
from liesuslov import reduction as red

NS = list(range(3, 9))


def _unit(x):
    x = np.asarray(x, dtype=float)
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def _random_rotation(rng, n, batch=()):
    A = rng.standard_normal(tuple(batch) + (n, n))
    Q, Rr = np.linalg.qr(A)
    Q = Q * np.sign(np.diagonal(Rr, axis1=-2, axis2=-1))[..., None, :]
    det = np.linalg.det(Q)
    Q[..., :, 0] *= det[..., None]
    return Q


def _lagrange_state(rng, n, batch=(), scale=0.8):
    case = ls.cases.lagrange(n, 1.0, 2.0, 1.5)
    x0 = (scale * rng.standard_normal(tuple(batch) + (n - 1,))) @ case.system.constraints.basis
    G0 = _unit(rng.standard_normal(tuple(batch) + (n,)))
    return case, x0, G0


def test_top_level_exports():
    """The public names are importable from the package (API.md: ls.to_spherical_pendulum)."""
    for name in ("to_spherical_pendulum", "pendulum_energy", "momentum_map", "SphericalPendulum",
                 "integrate_pendulum", "lift", "check_lagrange_reduction", "lagrange_parameters"):
        assert getattr(ls, name) is getattr(red, name), name


# ============================================================================ the map, Φ, energy
@pytest.mark.parametrize("n", NS)
def test_map_definition_and_shapes(n):
    rng = np.random.default_rng(n)
    g = _random_rotation(rng, n, (2, 3))
    alg = ls.so(n)
    x = rng.standard_normal((2, 3, alg.dim))
    q, v = red.to_spherical_pendulum(g, alg.hat(x))
    assert q.shape == v.shape == (2, 3, n)
    np.testing.assert_allclose(q, g[..., :, -1], atol=1e-15)
    np.testing.assert_allclose(v, np.einsum("...ij,...j->...i", g, alg.hat(x)[..., :, -1]), atol=1e-14)
    # coordinates are accepted too, and batch axes broadcast
    q2, v2 = red.to_spherical_pendulum(g, x)
    np.testing.assert_array_equal(q, q2)
    np.testing.assert_allclose(v, v2, atol=1e-15)
    q3, v3 = red.to_spherical_pendulum(g[0, 0], alg.hat(x))
    assert q3.shape == v3.shape == (2, 3, n)
    np.testing.assert_allclose(np.sum(q * v, axis=-1), 0.0, atol=1e-13)  # v is tangent for any Omega


def test_map_validation():
    g = np.eye(4)
    with pytest.raises(ValueError, match="g must be in SO"):
        red.to_spherical_pendulum(2 * g, np.zeros(6))
    with pytest.raises(ValueError, match="det = -1"):
        red.to_spherical_pendulum(np.diag([1.0, 1, 1, -1]), np.zeros(6))
    with pytest.raises(ValueError, match="Omega.*skew"):
        red.to_spherical_pendulum(g, np.ones((4, 4)))
    with pytest.raises(ValueError, match="Omega must be"):
        red.to_spherical_pendulum(g, np.zeros(5))
    with pytest.raises(ValueError, match="g must be square"):
        red.to_spherical_pendulum(np.eye(4)[:3], np.zeros(6))
    with pytest.raises(ValueError, match="do not broadcast"):
        red.to_spherical_pendulum(np.broadcast_to(g, (2, 4, 4)), np.zeros((3, 6)))
    with pytest.raises(ValueError, match="NaN"):
        red.to_spherical_pendulum(g, np.full(6, np.nan))


@pytest.mark.parametrize("n", [3, 4, 6])
def test_momentum_map(n):
    rng = np.random.default_rng(10 + n)
    alg = ls.so(n)
    I = np.array([1.3] * (n - 1) + [0.7])
    J = ls.Inertia.from_mass_tensor(I)
    # on D with a diagonal mass tensor: Phi = 0 exactly
    xD = rng.standard_normal((5, n - 1)) @ ls.suslov_distribution(n).basis
    np.testing.assert_array_equal(red.momentum_map(xD, J), 0.0)
    assert red.momentum_map(xD, J).shape == (5, (n - 1) * (n - 2) // 2)
    # in general: the so(n-1) block of M = I Omega + Omega I
    X = alg.hat(rng.standard_normal((5, alg.dim)))
    M = np.diag(I) @ X + X @ np.diag(I)
    np.testing.assert_allclose(red.momentum_map(X, I, as_matrix=True), M[:, : n - 1, : n - 1], atol=1e-14)
    np.testing.assert_allclose(red.momentum_map(X, J), ls.so(n - 1).vee(M[:, : n - 1, : n - 1]), atol=1e-14)
    # a non-diagonal mass tensor does not annihilate D: Phi is a real condition
    In = np.diag(I)
    In[0, n - 1] = In[n - 1, 0] = 0.2
    assert np.max(np.abs(red.momentum_map(xD, In))) > 1e-3


def test_momentum_map_validation():
    with pytest.raises(ValueError, match="so\\(n\\) with n >= 3"):
        red.momentum_map(np.zeros(1), ls.Inertia.from_mass_tensor([1.0, 2.0]))
    with pytest.raises(ValueError, match="Omega"):
        red.momentum_map(np.zeros(5), [1.0, 1.0, 1.0, 2.0])


@pytest.mark.parametrize("n", NS)
def test_energy_identity(n):
    """E(Omega, Gamma) = 1/2 m |v|^2 + Bn <gamma, q> at any Suslov state (no integration)."""
    rng = np.random.default_rng(20 + n)
    case, x0, G0 = _lagrange_state(rng, n, (7,))
    g = _random_rotation(rng, n, (7,))
    gamma = np.einsum("bij,bj->bi", g, G0)
    q, v = red.to_spherical_pendulum(g, x0)
    E = case.system.energy(x0, G0)
    H = red.pendulum_energy(q, v, 3.0, 1.5, gamma)
    np.testing.assert_allclose(E, H, rtol=0, atol=1e-14)
    np.testing.assert_allclose(red.pendulum_momentum(v, 3.0), 3.0 * v)
    # p = m v is the image of the body momentum: g M e_n
    M = ls.so(n).hat(case.system.inertia(x0))
    np.testing.assert_allclose(np.einsum("bij,bj->bi", g, M[..., :, -1]), 3.0 * v, atol=1e-14)


@pytest.mark.parametrize("n", [3, 6])
def test_momentum_about_vertical_is_the_bivector_integral(n):
    """|P (m q ∧ v) P| (pendulum) = |N| (cases.lagrange: N_ij = m (Omega_in Gamma_j - Omega_jn Gamma_i))."""
    rng = np.random.default_rng(25 + n)
    case, x0, G0 = _lagrange_state(rng, n, (4,))
    g = _random_rotation(rng, n, (4,))
    q, v = red.to_spherical_pendulum(g, x0)
    P = red.SphericalPendulum(n, 3.0, 1.5, np.einsum("bij,bj->bi", g, G0))
    L = ls.so(n).vee(P.momentum_about_vertical(q, v))
    ev = case.evaluate(x0, G0)
    N = np.stack([ev[k] for k in ev if k.startswith("N_")], -1)
    np.testing.assert_allclose(np.linalg.norm(L, axis=-1), np.linalg.norm(N, axis=-1), rtol=1e-13)


# ============================================================================ the lift
@pytest.mark.parametrize("n", NS)
def test_lift_projection_round_trip(n):
    rng = np.random.default_rng(30 + n)
    q = _unit(rng.standard_normal((6, n)))
    q[0] = np.eye(n)[-1]
    q[1] = -np.eye(n)[-1]
    q[2] = _unit(np.eye(n)[0] - 1e-17 * np.eye(n)[-1])
    v = rng.standard_normal((6, n))
    v -= np.sum(v * q, -1, keepdims=True) * q
    g, Om = red.lift(q, v)
    np.testing.assert_allclose(np.swapaxes(g, -1, -2) @ g, np.broadcast_to(np.eye(n), g.shape), atol=1e-14)
    assert np.all(np.linalg.det(g) > 0)
    np.testing.assert_array_equal(g[0], np.eye(n))  # identity at the north pole
    D = ls.suslov_distribution(n)
    assert np.all(D.contains(ls.so(n).vee(Om), 1e-15))
    q2, v2 = red.to_spherical_pendulum(g, Om)
    np.testing.assert_allclose(q2, q, atol=1e-15)
    np.testing.assert_allclose(v2, v, atol=1e-14)
    # any point of the fibre projects to the same (q, v)
    R = _random_rotation(rng, n - 1, (6,))
    gR, OmR = red.lift(q, v, fibre=R)
    np.testing.assert_allclose(gR[..., :, :n - 1], g[..., :, :n - 1] @ R, atol=1e-14)
    assert not np.allclose(gR, g)
    q3, v3 = red.to_spherical_pendulum(gR, OmR)
    np.testing.assert_allclose(q3, q, atol=1e-15)
    np.testing.assert_allclose(v3, v, atol=1e-14)


@pytest.mark.parametrize("n", [3, 5])
def test_lift_recovers_a_suslov_state_with_its_fibre(n):
    """lift(pi(g, Omega), fibre=R) = (g, Omega) for R = the SO(n-1) block of g_q^T g."""
    rng = np.random.default_rng(40 + n)
    g = _random_rotation(rng, n, (4,))
    x = rng.standard_normal((4, n - 1)) @ ls.suslov_distribution(n).basis
    Om = ls.so(n).hat(x)
    q, v = red.to_spherical_pendulum(g, Om)
    gq, _ = red.lift(q, v)
    rel = np.swapaxes(gq, -1, -2) @ g  # in SO(n-1) x {1}
    np.testing.assert_allclose(rel[:, -1, :], np.broadcast_to(np.eye(n)[-1], (4, n)), atol=1e-14)
    g2, Om2 = red.lift(q, v, fibre=rel[:, : n - 1, : n - 1])
    np.testing.assert_allclose(g2, g, atol=1e-14)
    np.testing.assert_allclose(Om2, Om, atol=1e-14)


def test_lift_validation():
    q = np.array([0.0, 0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="q must be a unit vector"):
        red.lift(2 * q, np.zeros(4))
    with pytest.raises(ValueError, match="v must be tangent"):
        red.lift(q, q)
    with pytest.raises(ValueError, match="fibre must be in SO\\(3\\)"):
        red.lift(q, np.zeros(4), fibre=2 * np.eye(3))
    with pytest.raises(ValueError, match="fibre must have shape"):
        red.lift(q, np.zeros(4), fibre=np.eye(4))
    with pytest.raises(ValueError, match="det = -1"):
        red.lift(q, np.zeros(4), fibre=np.diag([1.0, 1.0, -1.0]))


# ============================================================================ the pendulum system
@pytest.mark.parametrize("n", [3, 4, 7])
def test_pendulum_model_field_is_the_pendulum(n):
    """With W = v ∧ q: d/dt (W q) = W' q + W q' equals the pendulum's v' (the derivation)."""
    rng = np.random.default_rng(50 + n)
    P = red.SphericalPendulum(n, 2.5, -1.3, _unit(rng.standard_normal(n)))
    q = _unit(rng.standard_normal((5, n)))
    v = rng.standard_normal((5, n))
    v -= np.sum(v * q, -1, keepdims=True) * q
    model = P.model((5,))
    W = ls.so(n).hat(P.state(q, v))
    np.testing.assert_allclose(np.einsum("bij,bj->bi", W, q), v, atol=1e-14)
    xi = P.state(q, v)
    Wdot = ls.so(n).hat(model.xi_dot(xi, q))
    qdot = model.Gamma_dot(xi, q)
    np.testing.assert_allclose(qdot, v, atol=1e-14)
    np.testing.assert_allclose(-model.omega_matrix(xi), W, atol=0)
    np.testing.assert_allclose(model.omega_coords(model.xi_from_coords(xi)), xi)
    vdot = np.einsum("bij,bj->bi", Wdot, q) + np.einsum("bij,bj->bi", W, qdot)
    np.testing.assert_allclose(vdot, P.rhs(q, v)[1], atol=1e-13)
    assert model.state_dim == model.k + n and model.form == "spherical-pendulum"
    assert "spherical-pendulum" in model.description()


@pytest.mark.parametrize("n", [2, 3, 5, 8])
def test_pendulum_invariants_exact_and_energy(n):
    """|q| = 1 and <q, v> = 0 to rounding at any tolerance; energy and P L P conserved at tight ones."""
    rng = np.random.default_rng(60 + n)
    gamma = _unit(rng.standard_normal(n))
    P = red.SphericalPendulum(n, 3.0, 2.0, gamma)
    q0 = _unit(rng.standard_normal((3, n)))
    v0 = rng.standard_normal((3, n))
    v0 -= np.sum(v0 * q0, -1, keepdims=True) * q0
    loose = red.integrate_pendulum(P, q0, v0, (0, 30), method="rkmk45", rtol=1e-5, atol=1e-7)
    assert loose.success
    for sol in (loose, P.integrate(q0, v0, (0, 10), method="rkmk853", rtol=1e-13, atol=1e-13)):
        assert np.max(np.abs(np.linalg.norm(sol.q, axis=-1) - 1)) < 1e-14
        assert np.max(np.abs(np.sum(sol.q * sol.v, axis=-1))) < 1e-14 * max(1.0, np.abs(sol.v).max())
    assert sol.q.shape == sol.v.shape == (sol.t.size, 3, n) and sol.energy.shape == (sol.t.size, 3)
    np.testing.assert_array_equal(sol.p, 3.0 * sol.v)
    assert np.max(np.abs(sol.energy - sol.energy[0])) < 1e-10
    L = P.momentum_about_vertical(sol.q, sol.v)
    assert np.max(np.abs(L - L[0])) < 1e-10


@pytest.mark.parametrize("n", [3, 6])
def test_pendulum_against_scipy(n):
    """The so(n) x S^(n-1) integration agrees with scipy's DOP853 on the (q, v) equations."""
    rng = np.random.default_rng(70 + n)
    P = red.SphericalPendulum(n, 1.7, 2.3, _unit(rng.standard_normal(n)))
    q0 = _unit(rng.standard_normal(n))
    v0 = rng.standard_normal(n)
    v0 -= (v0 @ q0) * q0
    t = np.linspace(0, 6, 31)
    sol = P.integrate(q0, v0, (0, 6), method="rkmk853", rtol=1e-12, atol=1e-12, t_eval=t)

    def f(_, y):
        qd, vd = P.rhs(y[:n], y[n:])
        return np.concatenate([qd, vd])
    ref = solve_ivp(f, (0, 6), np.concatenate([q0, v0]), method="DOP853", rtol=1e-13, atol=1e-13, t_eval=t)
    np.testing.assert_allclose(sol.t, t)
    np.testing.assert_allclose(sol.q, ref.y[:n].T, atol=1e-9)
    np.testing.assert_allclose(sol.v, ref.y[n:].T, atol=1e-9)


def test_pendulum_batched_gamma_and_validation():
    rng = np.random.default_rng(80)
    n = 4
    gam = _unit(rng.standard_normal((3, n)))
    P = red.SphericalPendulum(n, 2.0, 1.0, gam)
    q0 = _unit(rng.standard_normal(n))
    v0 = np.zeros(n)
    sol = P.integrate(q0, v0, (0, 2), method="rkmk853", rtol=1e-12, t_eval=[0.0, 1.0, 2.0])
    assert sol.q.shape == (3, 3, n)
    for b in range(3):  # each trajectory uses its own gamma
        one = red.SphericalPendulum(n, 2.0, 1.0, gam[b]).integrate(q0, v0, (0, 2), method="rkmk853",
                                                                   rtol=1e-12, t_eval=[0.0, 1.0, 2.0])
        np.testing.assert_allclose(sol.q[:, b], one.q, atol=1e-10)
    with pytest.raises(ValueError, match="gamma must be a unit vector"):
        red.SphericalPendulum(n, 2.0, 1.0, 2 * gam)
    with pytest.raises(ValueError, match="m must be a finite positive"):
        red.SphericalPendulum(n, -1.0, 1.0)
    with pytest.raises(ValueError, match="n must be >= 2"):
        red.SphericalPendulum(1, 1.0, 1.0)
    P1 = red.SphericalPendulum(n, 2.0, 1.0)
    with pytest.raises(ValueError, match="q0 must be a unit vector"):
        P1.integrate(2 * q0, v0, (0, 1))
    with pytest.raises(ValueError, match="v0 must be tangent"):
        P1.integrate(q0, q0, (0, 1))
    with pytest.raises(ValueError, match="v0 must have shape"):
        P1.integrate(q0, np.zeros(3), (0, 1))
    with pytest.raises(TypeError, match="Gamma0"):
        P1.integrate(q0, v0, (0, 1), Gamma0=q0)
    with pytest.raises(TypeError, match="SphericalPendulum"):
        red.integrate_pendulum("pendulum", q0, v0, (0, 1))


# ============================================================================ the reduction, integrated
@pytest.mark.parametrize("n", NS)
def test_reduction_matches_pendulum(n):
    """The mapped Suslov trajectory = the independent pendulum, q stays in span{gamma, q0, v0}, Phi = 0."""
    rng = np.random.default_rng(90 + n)
    case, x0, G0 = _lagrange_state(rng, n, (2,))
    g0 = _random_rotation(rng, n, (2,))
    r = red.check_lagrange_reduction(case, x0, G0, (0.0, 8.0), g0=g0, method="rkmk853", rtol=1e-12,
                                     atol=1e-12)
    assert r.q_suslov.shape == r.q_pendulum.shape == (r.t.size, 2, n)
    assert r.max_dq < 1e-8 and r.max_dv < 1e-8
    assert r.energy_mismatch < 1e-13  # the energy identity, to rounding, at each time
    assert r.energy_drift_pendulum < 1e-10 and r.energy_drift_suslov < 1e-9
    assert r.max_phi == 0.0
    assert r.in_plane_defect < 1e-12
    assert r.ok(1e-8)
    np.testing.assert_allclose(r.gamma, np.einsum("bij,bj->bi", g0, G0), atol=1e-15)
    # the motion is not trivial: q moves far and (for n > 3) the plane test has content
    assert np.max(np.linalg.norm(r.q_suslov - r.q_suslov[0], axis=-1)) > 0.3
    text = str(r)
    assert "max |q_suslov - q_pendulum|" in text and f"SO({n})" in text


@pytest.mark.parametrize("n", [3, 6])
def test_reduction_fixed_step_rkmk8(n):
    rng = np.random.default_rng(100 + n)
    case, x0, G0 = _lagrange_state(rng, n)
    r = red.check_lagrange_reduction(case, x0, G0, (0.0, 5.0), method="rkmk8", h=0.02,
                                    t_eval=np.linspace(0, 5, 11))
    np.testing.assert_allclose(r.t, np.linspace(0, 5, 11))
    assert r.max_dq < 1e-12 and r.max_dv < 1e-12
    assert r.energy_drift_pendulum < 1e-12 and r.energy_drift_suslov < 1e-12


def test_reduction_lagrange3_case_cayley_and_backward():
    """The 3-D case given by the paper's J (J1 = J2), the Cayley chart, backward in time."""
    case = ls.cases.lagrange3(2.0, 1.5, 1.0)
    x0 = np.array([0.0, 0.4, -0.3])
    G0 = _unit([0.2, 0.5, 0.8])
    p = red.lagrange_parameters(case)
    assert p.n == 3 and p.I1 == pytest.approx(0.75) and p.m == pytest.approx(2.0)
    r = red.check_lagrange_reduction(case, x0, G0, (0.0, -6.0), chart="cayley", rtol=1e-12, atol=1e-12)
    assert r.t[-1] == -6.0
    assert r.ok(1e-8)


def test_reduction_free_motion_is_a_great_circle():
    """Bn = 0 (V = 0, Gamma0 may be omitted): q(t) = cos(|v| t) q0 + sin(|v| t) v0 / |v0|."""
    n = 5
    case = ls.cases.lagrange(n, 1.0, 2.0, 0.0)
    x0 = np.array([0.3, -0.2, 0.1, 0.5]) @ case.system.constraints.basis
    t = np.linspace(0, 4, 9)
    r = red.check_lagrange_reduction(case, x0, None, (0, 4), t_eval=t)
    q0, v0 = r.q_suslov[0], r.v_suslov[0]
    w = np.linalg.norm(v0)
    exact = np.cos(w * t)[:, None] * q0 + np.sin(w * t)[:, None] * v0 / w
    np.testing.assert_allclose(r.q_suslov, exact, atol=1e-10)
    np.testing.assert_allclose(r.q_pendulum, exact, atol=1e-10)


def test_reduction_accepts_an_equivalent_system():
    """A SuslovSystem built by hand (inertia from K only, explicit constraints) is recognised."""
    n = 4
    K = ls.Inertia.from_mass_tensor([1.0, 1.0, 1.0, 3.0]).matrix
    sysm = ls.SuslovSystem(ls.Inertia(ls.so(n), K), ls.suslov_distribution(n),
                           ls.LinearPotential([0.0, 0.0, 0.0, -2.0]))
    p = red.lagrange_parameters(sysm)
    assert (p.n, p.I1, p.In, p.Bn) == (4, pytest.approx(1.0), pytest.approx(3.0), -2.0)


def _system(I, B=None, D=None, **kw):
    n = len(I)
    B = np.eye(n)[-1] if B is None else B
    pot = ls.QuadraticPotential(B) if kw.pop("quadratic", False) else ls.LinearPotential(B)
    return ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), D, pot, **kw)


@pytest.mark.parametrize("scene, match", [
    (lambda: ls.cases.kharlamova([1.0, 1.0, 1.0, 2.0], [1.0, 0.5, 0.2]), "B_1 = 1 != 0"),
    (lambda: ls.cases.klebsh_tisserand([1.0, 1.0, 1.0, 2.0], [4.0, 3.0, 2.0, 1.0]), "quadratic potential"),
    (lambda: _system([1.0, 1.5, 1.0, 2.0]), "I_2 = 1.5 != I_1 = 1"),
    (lambda: _system(np.diag([1.0, 1, 1, 2]) + 0.1 * (np.eye(4)[[1]].T @ np.eye(4)[[0]] +
                                                     np.eye(4)[[0]].T @ np.eye(4)[[1]])), "must be diagonal"),
    (lambda: _system([1.0, 1.0, 1.0, 2.0], D=ls.Subspace(ls.so(4), np.eye(6)[[0, 1, 2]])), "Fedorov–Kozlov"),
    (lambda: _system([1.0, 1.0, 2.0], gyroscopic=0.3), "gyroscopic"),
    (lambda: ls.cases.suslov_free(np.diag([1.0, 2.0, 3.0, 4.0])), "I_2 = 2 != I_1 = 1"),
    (lambda: ls.cases.kharlamova3([1.0, 1.0, 2.0], 1.0, 0.5), "B_1 = 1 != 0"),
])
def test_harness_rejects_non_lagrange_scenes(scene, match):
    sysm = scene()
    with pytest.raises(ValueError, match=match):
        red.lagrange_parameters(sysm)
    n = (sysm.system if isinstance(sysm, ls.Case) else sysm).n
    Om = np.zeros((n, n))
    with pytest.raises(ValueError, match="not the Lagrange case"):
        red.check_lagrange_reduction(sysm, Om, np.eye(n)[-1], (0, 1))


def test_harness_rejects_other_inputs():
    case = ls.cases.lagrange(4, 1.0, 2.0, 1.0)
    with pytest.raises(TypeError, match="SuslovSystem or a Case"):
        red.lagrange_parameters("lagrange")
    with pytest.raises(ValueError, match="SO\\(n\\)"):
        red.lagrange_parameters(ls.SuslovSystem(ls.Inertia(ls.se(3), np.eye(6)),
                                               ls.Subspace(ls.se(3), np.eye(6)[:3])))
    with pytest.raises(ValueError, match="Omega0 is not in the constraint subspace"):
        red.check_lagrange_reduction(case, np.ones(6), np.eye(4)[-1], (0, 1))
    with pytest.raises(ValueError, match="Gamma0 must be a unit vector"):
        red.check_lagrange_reduction(case, np.zeros(6), np.ones(4), (0, 1))
    with pytest.raises(ValueError, match="Gamma0 is required"):
        red.check_lagrange_reduction(case, np.zeros(6), None, (0, 1))
    with pytest.raises(ValueError, match="g0 must be in SO"):
        red.check_lagrange_reduction(case, np.zeros(6), np.eye(4)[-1], (0, 1), g0=2 * np.eye(4))


# ============================================================================ closed form
@pytest.mark.parametrize("n", [3, 5])
def test_planar_swing_against_elliptic_closed_form(n):
    """Released from rest at angle theta0 from the bottom -gamma: sin(theta/2) = k sn(K - w t, k),
    k = sin(theta0/2), w^2 = Bn/m, through the whole chain lift -> Suslov -> map and the pendulum."""
    from scipy.special import ellipj, ellipk

    rng = np.random.default_rng(110 + n)
    I1, In, Bn = 0.8, 1.7, 2.0
    w = np.sqrt(Bn / (I1 + In))  # m = I1 + In
    gamma = _unit(rng.standard_normal(n))
    e = rng.standard_normal(n)
    e = _unit(e - (e @ gamma) * gamma)
    theta0 = 2.5  # a large swing (elliptic modulus k^2 = 0.9)
    q0 = -np.cos(theta0) * gamma + np.sin(theta0) * e
    g0, Om0 = red.lift(q0, np.zeros(n), fibre=_random_rotation(rng, n - 1))
    case = ls.cases.lagrange(n, I1, In, Bn)
    t = np.linspace(0.0, 12.0, 25)
    r = red.check_lagrange_reduction(case, Om0, g0.T @ gamma, (0.0, 12.0), g0=g0, t_eval=t)
    k2 = np.sin(theta0 / 2) ** 2
    sn = ellipj(ellipk(k2) - w * t, k2)[0]
    theta = 2 * np.arcsin(np.sqrt(k2) * sn)
    exact = -np.cos(theta)[:, None] * gamma + np.sin(theta)[:, None] * e
    np.testing.assert_allclose(r.q_suslov, exact, atol=1e-9)
    np.testing.assert_allclose(r.q_pendulum, exact, atol=1e-9)
    np.testing.assert_allclose(r.energy_pendulum, -Bn * np.cos(theta0), atol=1e-10)
