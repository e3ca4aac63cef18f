"""The integrable cases: integrals along trajectories, the paper's formulas (and its typos), validation."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from liesuslov.algebra import so
from liesuslov.mechanics import (
    CASES,
    LinearPotential,
    Potential,
    QuadraticPotential,
    gyroscopic3,
    kharlamova,
    kharlamova3,
    klebsh_tisserand,
    klebsh_tisserand3,
    lagrange,
    lagrange3,
    suslov3,
    suslov_free,
)

TOL = 1e-9  # first integrals along DOP853 trajectories (rtol = atol = 1e-12), relative to max(1, |F|)


def trajectory(case, T=8.0, seed=0, scale=1.0):
    """Integrate the case's own model; return the coordinates omega(t), Gamma(t) and the model."""
    m = case.system.model()
    omega0, G0 = case.random_state(np.random.default_rng(seed), scale=scale)
    y0 = np.concatenate([m.xi_from_coords(omega0)] + ([G0] if m.has_gamma else []))
    sol = solve_ivp(m.vector_field, (0.0, T), y0, method="DOP853", rtol=1e-12, atol=1e-12)
    assert sol.success
    xi = sol.y[:m.k].T
    G = sol.y[m.k:].T if m.has_gamma else None
    return m.omega_coords(xi), G, m


def assert_conserved(case, omega, G):
    for name, F in case.integrals.items():
        v = np.asarray(F(omega, G))
        drift = float(np.max(np.abs(v - v[0])))
        assert drift <= TOL * max(1.0, float(np.max(np.abs(v)))), f"{case.name}: {name} drifts by {drift:.2e}"


def case_3d():
    return [
        suslov3([[2.0, 0.0, 0.3], [0.0, 3.0, 0.4], [0.3, 0.4, 4.0]]),
        lagrange3(2.0, 1.5, 1.3),
        kharlamova3([1.0, 2.0, 2.5], 1.0, -0.6),
        klebsh_tisserand3([1.0, 2.0, 2.5], 0.8),
        klebsh_tisserand3([1.3, 0.9, 1.7], -0.5),
        CASES["family3"].build(),
        gyroscopic3([1.0, 2.0, 2.5], 0.7),
        gyroscopic3([1.0, 2.0, 2.5], -0.4, LinearPotential([0.8, -0.3, 0.0])),
        gyroscopic3([1.0, 2.0, 2.5], 0.7, QuadraticPotential([1.0, 2.0, 0.5])),
        gyroscopic3([1.4, 0.8, 2.0], 1.3, QuadraticPotential([-0.5, 0.3, 0.9])),
    ]


@pytest.mark.parametrize("case", case_3d(), ids=lambda c: c.name)
def test_3d_integrals_are_conserved(case):
    omega, G, m = trajectory(case, T=10.0, seed=1)
    assert_conserved(case, omega, G)
    assert set(case.integrals) > {"energy"} or case.name == "suslov3"


def case_nd(n):
    rng = np.random.default_rng(n)
    I = rng.uniform(1.0, 3.0, n)
    return [
        lagrange(n, 1.2, 2.1, 0.9),
        kharlamova(I, rng.choice([-1.0, 1.0], n - 1) * rng.uniform(0.5, 1.5, n - 1)),
        klebsh_tisserand(I, np.append(rng.uniform(1.5, 3.0, n - 1), 1.0)),
        klebsh_tisserand(I, rng.normal(size=n), allow_general=True),
        suslov_free(np.diag(I) + 0.2 * np.ones((n, n))),
    ]


@pytest.mark.parametrize("n", [3, 4, 5, 6])
def test_nd_integrals_are_conserved(n):
    for case in case_nd(n):
        omega, G, m = trajectory(case, T=8.0, seed=n)
        assert_conserved(case, omega, G)


@pytest.mark.parametrize("n", [3, 4, 6])
def test_model_selection_of_the_cases(n):
    for case in case_nd(n):
        m = case.system.model()
        if case.name == "suslov_free":
            assert m.form == "reduced" and not m.has_gamma and m.state_dim == n - 1
        else:
            assert m.form == "symmetric" and m.fedorov_kozlov and "O(n)" in m.path
            assert m.has_gamma and m.state_dim == 2 * n - 1
    for case in case_3d():
        want = "reduced" if case.name == "suslov3" else "symmetric"
        assert case.system.model().form == want


# ====================================================================== multipliers, measure
def test_lagrange_multipliers_vanish_identically():
    for case in (lagrange3(2.0, 1.5, 1.3), lagrange(3, 0.75, 1.25, 1.3), lagrange(5, 1.2, 2.1, 0.9)):
        omega, G, _ = trajectory(case, T=5.0)
        assert np.max(np.abs(case.system.multipliers(omega, G))) < 1e-14
        om, G = case.random_state(3, batch=(50,), scale=3.0)  # rounding of |Omega|^2 ~ 100 terms
        assert np.max(np.abs(case.system.multipliers(om, G))) < 1e-14 * np.max(np.sum(om ** 2, axis=-1))


def test_other_fk_cases_have_nonzero_multipliers():
    """With diagonal I, only the Lagrange case keeps lambda ≡ 0 (see docs/mechanics.md)."""
    for case in (kharlamova3([1.0, 2.0, 2.5], 1.0, -0.6), klebsh_tisserand3([1.0, 2.0, 2.5], 0.8),
                 CASES["kharlamova"].build(), CASES["klebsh_tisserand"].build(),
                 gyroscopic3([1.0, 2.0, 2.5], 0.7)):
        om, G = case.random_state(5, batch=(20,))
        assert np.max(np.abs(case.system.multipliers(om, G))) > 1e-2


def test_divergence_zero_for_the_integrable_cases_nonzero_for_suslov():
    for case in case_3d() + case_nd(5):
        om, G = case.random_state(2, batch=(5,))
        div = case.system.divergence(om, G)
        if case.name in ("suslov3", "suslov_free"):
            assert np.all(np.abs(div) > 1e-4)
        else:
            np.testing.assert_allclose(div, 0.0, atol=1e-13)


def test_lagrange3_is_the_nd_lagrange_case_for_n3():
    """J = diag(J1, J1, J3) is the mass tensor I = diag(J3/2, J3/2, J1 - J3/2)."""
    a, b = lagrange3(2.0, 1.5, 1.3), lagrange(3, 0.75, 1.25, 1.3)
    np.testing.assert_allclose(a.system.inertia.matrix, b.system.inertia.matrix)
    om, G = a.random_state(0, batch=(4,))
    np.testing.assert_allclose(b.integrals["N_1_2"](om, G), a.integrals["F"](om, G), atol=1e-14)


# ====================================================================== the paper's formulas
@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(3, 8))
def test_klebsh_tisserand_energy_identity(seed, n):
    """E = 1/2 (B_n + sum F_i) on |Gamma| = 1 (the paper's 1/2 (n B_n + ...) is a typo)."""
    rng = np.random.default_rng(seed)
    case = klebsh_tisserand(rng.uniform(0.5, 2.0, n), np.append(rng.uniform(2.0, 3.0, n - 1), 1.5))
    om, G = case.random_state(rng, batch=(6,))
    vals = case.evaluate(om, G)
    Fsum = sum(vals[f"F_{i}"] for i in range(1, n))
    Bn = case.parameters["B"][-1]
    np.testing.assert_allclose(vals["energy"], 0.5 * (Bn + Fsum), rtol=1e-13)
    assert np.all(np.abs(vals["energy"] - 0.5 * (n * Bn + Fsum)) > 0.1)


def test_klebsh_tisserand_field_and_angles():
    """(4.9) with (B_i - B_n), not (B_1 - B_n); d phi_i/dt = Gamma_n sqrt((B_i - B_n)/(I_i + I_n))."""
    I = np.array([1.0, 1.5, 2.0, 2.5, 3.0])
    B = np.array([5.0, 4.0, 3.5, 2.0, 1.0])
    case = klebsh_tisserand(I, B)
    m = case.system.model()
    om, G = case.random_state(1)
    xi = m.xi_from_coords(om)
    xidot = m.xi_dot(xi, G)
    np.testing.assert_allclose((I[:-1] + I[-1]) * xidot, (B[:-1] - B[-1]) * G[:-1] * G[-1], atol=1e-15)
    Gdot = m.Gamma_dot(xi, G)
    a, b = np.sqrt(B[:-1] - B[-1]), np.sqrt(I[:-1] + I[-1])
    X, Y = a * G[:-1], b * xi  # phi = atan2(Y, X)
    phidot = (X * b * xidot - Y * a * Gdot[:-1]) / (X ** 2 + Y ** 2)
    np.testing.assert_allclose(phidot, G[-1] * a / b, rtol=1e-12)


def test_kharlamova_coordinates_4_6_give_4_7():
    rng = np.random.default_rng(8)
    n = 5
    I = rng.uniform(1.0, 2.0, n)
    B = rng.uniform(0.5, 1.5, n - 1) * rng.choice([-1.0, 1.0], n - 1)
    case = kharlamova(I, B)
    m = case.system.model()
    om, G = case.random_state(rng)
    xi = m.xi_from_coords(om)
    xid, Gd = m.xi_dot(xi, G), m.Gamma_dot(xi, G)
    c = (I[:-1] + I[-1]) / B
    w = np.concatenate([[c[0] * xi[0]], c[1:] * xi[1:] - c[0] * xi[0]])
    g = np.concatenate([[-c[0] * G[0]], -c[1:] * G[1:-1] + c[0] * G[0], [G[-1]]])
    wd = np.concatenate([[c[0] * xid[0]], c[1:] * xid[1:] - c[0] * xid[0]])
    gd = np.concatenate([[-c[0] * Gd[0]], -c[1:] * Gd[1:-1] + c[0] * Gd[0], [Gd[-1]]])
    np.testing.assert_allclose(wd, np.concatenate([[g[-1]], np.zeros(n - 2)]), atol=1e-14)
    np.testing.assert_allclose(gd[:-1], g[-1] * np.concatenate([[w[0]], w[1:]]), atol=1e-14)
    k = (1.0 / c) ** 2
    want = -k[0] * g[0] * w[0] - np.sum(k[1:] * (g[0] + g[1:-1]) * (w[0] + w[1:]))
    np.testing.assert_allclose(gd[-1], want, atol=1e-14)
    # the quartic: gamma_n^2 = 1 - k_1 gamma_1^2 - sum k_i (gamma_1 + gamma_i)^2 on |Gamma| = 1
    np.testing.assert_allclose(g[-1] ** 2, 1 - k[0] * g[0] ** 2 - np.sum(k[1:] * (g[0] + g[1:-1]) ** 2),
                               atol=1e-14)


def test_3d_integrals_agree_with_their_nd_forms():
    kt = klebsh_tisserand3([1.0, 2.0, 2.5], 0.8)
    om, G = kt.random_state(0, batch=(5,))
    v = kt.evaluate(om, G)
    J1, J2, eps = 1.0, 2.0, 0.8
    np.testing.assert_allclose(2 * v["F"], J2 * v["F_1"] + J1 * v["F_2"] - eps * J1 * J2, atol=1e-13)
    kh = kharlamova3([1.0, 2.0, 2.5], 1.0, -0.6)
    om, G = kh.random_state(0, batch=(5,))
    v = kh.evaluate(om, G)
    np.testing.assert_allclose(v["energy"], v["E_1"] + v["E_2"], atol=1e-14)


def test_lagrange_nd_integrals_form_a_conserved_bivector():
    case = lagrange(5, 1.2, 2.1, 0.9)
    omega, G, _ = trajectory(case, T=6.0, seed=3)
    assert len([k for k in case.integrals if k.startswith("N_")]) == 6
    # |N|^2 = (I1 + In)^2 (|xi|^2 (1 - Gamma_n^2) - (xi . Gamma')^2): the pendulum's momentum ⊥ gamma
    xi = omega[:, [so(5).index(i, 4) for i in range(4)]]
    N2 = sum(case.integrals[k](omega, G) ** 2 for k in case.integrals if k.startswith("N_"))
    want = (1.2 + 2.1) ** 2 * (np.sum(xi ** 2, -1) * (1 - G[:, -1] ** 2) - np.sum(xi * G[:, :-1], -1) ** 2)
    np.testing.assert_allclose(N2, want, atol=1e-12)


# ====================================================================== validation
def test_bad_parameters_are_rejected():
    with pytest.raises(ValueError, match="J1 = J2"):
        lagrange3([2.0, 2.5], 1.5, 1.0)
    with pytest.raises(ValueError, match="I_1 = I_2"):
        lagrange(4, [1.0, 1.5, 1.0], 2.0, 1.0)
    with pytest.raises(ValueError, match="n must be an integer >= 3"):
        lagrange(2, 1.0, 2.0, 1.0)
    with pytest.raises(ValueError, match="B_2 = 0.5 <= B_n = 1.0"):
        klebsh_tisserand([1.0, 2.0, 3.0, 4.0], [2.0, 0.5, 3.0, 1.0])
    klebsh_tisserand([1.0, 2.0, 3.0, 4.0], [2.0, 0.5, 3.0, 1.0], allow_general=True)
    with pytest.raises(ValueError, match="B must have shape \\(4,\\)"):
        klebsh_tisserand([1.0, 2.0, 3.0, 4.0], [2.0, 3.0, 1.0])
    with pytest.raises(ValueError, match="all must be nonzero"):
        kharlamova([1.0, 2.0, 3.0, 4.0], [1.0, 0.0, 2.0])
    with pytest.raises(ValueError, match="B must have shape \\(3,\\)"):
        kharlamova([1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0, 4.0])
    with pytest.raises(ValueError, match="diagonal"):
        kharlamova(np.eye(4), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="symmetric"):
        suslov_free([[1.0, 0.2, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]])
    with pytest.raises(ValueError, match="eigenvector"):
        suslov3(np.diag([1.0, 2.0, 3.0]))
    with pytest.raises(ValueError, match="principal moments"):
        kharlamova3([[1.0, 0.0, 0.0]] * 3, 1.0, 1.0)
    with pytest.raises(ValueError, match="positive"):
        klebsh_tisserand3([1.0, -2.0, 2.5], 0.8)
    with pytest.raises(ValueError, match="finite"):
        klebsh_tisserand3([1.0, 2.0, 2.5], np.inf)
    with pytest.raises(ValueError, match="J1 != J2"):
        CASES["family3"].build(J=[2.0, 2.0, 1.0])
    with pytest.raises(ValueError, match="grad disagrees"):
        CASES["family3"].build(dv1=lambda s, r: (s, r))
    with pytest.raises(ValueError, match="B = \\(B1, B2, 0\\)"):
        gyroscopic3([1.0, 2.0, 2.5], 0.7, LinearPotential([1.0, 0.0, 1.0]))
    with pytest.raises(ValueError, match="integrable for V = 0"):
        gyroscopic3([1.0, 2.0, 2.5], 0.7, Potential(lambda G: G[..., 0], lambda G: 0 * G + [1.0, 0, 0], n=3))


def test_registry():
    assert set(CASES) == {"suslov3", "lagrange3", "kharlamova3", "klebsh_tisserand3", "family3",
                          "gyroscopic3", "suslov_free", "lagrange", "kharlamova", "klebsh_tisserand"}
    for name, entry in CASES.items():
        assert entry.name == name and "\n" not in entry.description and len(entry.description) < 110
        case = entry.build()
        assert case.name == name and "energy" in case.integrals and case.description
        om, G = case.random_state(0, batch=(2,))
        assert all(v.shape == (2,) for v in case.evaluate(om, G).values())


@pytest.mark.parametrize("name", sorted(CASES))
def test_cases_pickle_with_their_integrals(name):
    # ensembles send cases to workers: a case pickles as its recipe and its integrals give the same numbers
    import pickle

    case = CASES[name].build()
    again = pickle.loads(pickle.dumps(case))
    omega, Gamma = case.random_state(3, 4)
    want, got = case.evaluate(omega, Gamma), again.evaluate(omega, Gamma)
    assert want.keys() == got.keys()
    for key in want:
        np.testing.assert_array_equal(got[key], want[key])
    assert again.parameters.keys() == case.parameters.keys()


def test_random_state_names_its_bad_arguments():
    from liesuslov.mechanics import cases

    case = cases.klebsh_tisserand([1.0, 1.5, 2.0, 0.5], [4.0, 3.0, 2.5, 1.0])
    for kw, exc, says in ((dict(scale=np.nan), ValueError, "scale"), (dict(scale="x"), TypeError, "scale"),
                          (dict(batch=(2.7,)), TypeError, "batch"), (dict(rng=-1), ValueError, "rng"),
                          (dict(rng="seed"), TypeError, "rng")):
        with pytest.raises(exc, match=says):
            case.random_state(**kw)
    assert case.random_state(0, batch=(2, 3))[0].shape == (2, 3, 6)
