"""The compiled (numba) stepper: the same method as the numpy one, to rounding, and its fallbacks.

The first test that runs compiles the kernels once (~20 s on a slow machine; cached on disk after that).
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import liesuslov as ls

pytest.importorskip("numba")

from liesuslov.integrators import compiled  # noqa: E402  (after the skip: it imports numba)
from liesuslov.integrators.charts import make_chart  # noqa: E402
from liesuslov.integrators.rkmk import RKMKStepper  # noqa: E402
from liesuslov.integrators.tableaux import TABLEAUX  # noqa: E402

RTOL = 1e-12  # whole runs: rounding differences amplified by a few hundred steps at most


def kt4():
    return ls.cases.klebsh_tisserand([1.0, 1.3, 1.7, 2.0], [4.0, 3.5, 3.0, 1.0])


SCENES = {
    "klebsh_tisserand4": kt4,
    "lagrange3": lambda: ls.cases.lagrange3(1.0, 1.5, 2.0),
    "kharlamova5": lambda: ls.cases.kharlamova([1.0, 1.5, 2.0, 2.5, 3.0], [1.0, -0.5, 0.7, 0.4]),
    "suslov3": lambda: ls.cases.suslov3([[2.0, 0.0, 0.3], [0.0, 3.0, 0.4], [0.3, 0.4, 4.0]]),
    "gyroscopic3": lambda: ls.cases.gyroscopic3([1.0, 2.0, 2.5], 0.7, ls.QuadraticPotential([1.0, 2.0, 0.5])),
}
METHODS = {"lie-euler": {"h": 0.02}, "rkmk4": {"h": 0.05}, "rkmk45": {"rtol": 1e-8, "atol": 1e-10},
           "rkmk853": {"rtol": 1e-9, "atol": 1e-11}}


def both(system, omega, **kw):
    a = ls.integrate(system, omega, backend="numpy", **kw)
    b = ls.integrate(system, omega, backend="numba", **kw)
    assert a.stats["backend"] == "numpy" and b.stats["backend"] == "numba"
    return a, b


def assert_same(a, b, rtol=RTOL):
    for key in ("steps", "rejected", "nfev"):
        assert a.stats[key] == b.stats[key], key
    assert a.status == b.status == 0
    np.testing.assert_array_equal(b.t, a.t)
    for name in ("xi", "Gamma", "g"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            np.testing.assert_allclose(y, x, rtol=rtol, atol=rtol * max(1.0, np.abs(x).max()), err_msg=name)


@pytest.mark.parametrize("mode", ["g", "gamma"])
@pytest.mark.parametrize("chart", ["exp", "cayley"])
@pytest.mark.parametrize("method", list(METHODS))
@pytest.mark.parametrize("scene", list(SCENES))
def test_integrate_agrees_with_numpy(scene, method, chart, mode):
    case = SCENES[scene]()
    omega, Gamma = case.random_state(3)
    if Gamma is None:  # V = 0: "g" is the attitude alone, "gamma" the vertical carried along
        Gamma = np.array([0.6, 0.0, 0.8])
        if mode == "g":
            Gamma = None
    # Adaptive runs take the same steps, of sizes that agree to ~1e-10 only (the error estimates cancel
    # O(h |K|) terms down to O(rtol)): compare the states at the same times, t_eval.
    kw = dict(t_span=(0.0, 1.5), Gamma0=Gamma, reconstruct=mode == "g", method=method, chart=chart,
              t_eval=[0.0, 0.5, 1.0, 1.5], **METHODS[method])
    a, b = both(case.system, omega, **kw)
    assert_same(a, b)


def test_no_group_part_batch_t_eval_and_backward():
    case = SCENES["suslov3"]()
    omega, _ = case.random_state(0, batch=(2, 3))
    t_eval = np.linspace(0.0, -2.0, 7)
    a, b = both(case.system, omega, t_span=(0.0, -2.0), method="rkmk45", t_eval=t_eval)
    assert a.Gamma is None and b.g is None and b.xi.shape == (7, 2, 3, 2)
    assert_same(a, b)
    np.testing.assert_array_equal(b.t, t_eval)


def test_batch_with_attitude_and_dop853():
    case = kt4()
    omega, Gamma = case.random_state(1, batch=(4,))
    a, b = both(case.system, omega, t_span=(0.0, 3.0), Gamma0=Gamma, reconstruct=True, method="rkmk853",
                chart="cayley", rtol=1e-10, atol=1e-12, t_eval=[0.0, 1.0, 2.5, 3.0])
    assert_same(a, b)


@pytest.mark.parametrize("n", [3, 4, 5])
@pytest.mark.parametrize("chart", ["exp", "cayley"])
def test_every_tableau_step_by_step(n, chart):
    """Single steps of every tableau, both charts, both group modes: states, Theta, estimates, nfev."""
    rng = np.random.default_rng(n)
    if n == 3:
        system = SCENES["gyroscopic3"]().system
    else:
        Q = np.linalg.qr(rng.normal(size=(n, n)))[0]  # a general mass tensor: the quadratic term too
        I = Q @ np.diag(np.linspace(1.0, 2.5, n)) @ Q.T
        S = rng.normal(size=(n, n))
        system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), potential=ls.QuadraticPotential(S + S.T))
    model = system.model(gamma=True)
    B, h = 2, 0.3
    xi = rng.normal(size=(B, model.k))
    g = np.linalg.qr(rng.normal(size=(B, n, n)))[0]
    Gam = rng.normal(size=(B, n))
    Gam /= np.linalg.norm(Gam, axis=1, keepdims=True)
    for mode, G, gamma in (("g", g, Gam), ("gamma", Gam, None)):
        for tab in TABLEAUX.values():
            ch = make_chart(chart, n, skew=True, order=tab.order)
            ref, new = RKMKStepper(model, tab, ch, mode, B), compiled.CompiledStepper(model, tab, ch, mode, B)
            x, Y = xi, G
            for _ in range(3):  # stage-0 reuse (FSAL) on the later steps
                ra, rb = ref.step(h, x, Y, gamma, True), new.step(h, x, Y, gamma, True)
                for u, v in zip(ra[:3], rb[:3], strict=True):
                    np.testing.assert_allclose(v, u, rtol=0, atol=1e-13 * np.abs(u).max())
                # the estimates are differences of O(h |K|) terms; the numpy stepper may store err_Theta
                # in another layout with the same sum of squares |err Theta|_F^2
                scale = max(np.abs(ra[0] - x).max(), np.abs(ra[2]).max())  # ~ h |L|, h |K|
                assert len(ra[3]) == len(rb[3]) == len(tab.error_weights)
                for (ex, eg), (fx, fg) in zip(ra[3], rb[3], strict=True):
                    np.testing.assert_allclose(fx, ex, rtol=0, atol=1e-13 * scale)
                    frob = np.sqrt(np.sum(eg.reshape(B, -1) ** 2, axis=1))
                    np.testing.assert_allclose(np.sqrt(np.sum(fg.reshape(B, -1) ** 2, axis=1)), frob, rtol=0,
                                               atol=1e-13 * scale)
                ref.accept()
                new.accept()
                x, Y = ra[0], ra[1]
            assert ref.nfev == new.nfev, tab.name


def test_error_norm_shortcut_matches_the_controller():
    from liesuslov.integrators.integrate import _Run

    case = kt4()
    model = case.system.model(gamma=True)
    rng = np.random.default_rng(0)
    B = 3
    xi = rng.normal(size=(B, 3))
    g = np.linalg.qr(rng.normal(size=(B, 4, 4)))[0]
    gamma = np.array([[0.0, 0.0, 0.6, 0.8]] * B)
    for name in ("bs3", "dopri5", "dop853"):
        tab = TABLEAUX[name]
        st = compiled.CompiledStepper(model, tab, "exp", "g", B, rtol=1e-7, atol=1e-9)
        xi1, _, _, errs = st.step(0.2, xi, g, gamma, True)
        run = _Run(st, model, "g", xi, g, gamma, 0.0, 1.0, True)
        for rtol, atol in ((1e-7, 1e-9), (1e-4, 1e-6)):  # in-kernel value, then the recomputed one
            want = run._error_norm(errs, xi1, rtol, atol, 0.2)
            assert errs.norm(rtol, atol) == pytest.approx(want, rel=1e-13)


def test_attitude_stays_orthogonal():
    case = kt4()
    omega, Gamma = case.random_state(2)
    sol = ls.integrate(case.system, omega, (0.0, 20.0), Gamma0=Gamma, reconstruct=True, method="rkmk4", h=0.01,
                       backend="numba")
    g = sol.g
    err = np.abs(np.swapaxes(g, -1, -2) @ g - np.eye(4)).max()
    assert err < 1e-13
    np.testing.assert_allclose(np.linalg.norm(sol.Gamma, axis=-1), 1.0, rtol=0, atol=1e-13)
    E = case.evaluate(sol.omega, sol.Gamma)["energy"]
    assert np.ptp(E) < 1e-6


def user_potential_system():
    pot = ls.Potential(lambda G: np.cos(G[..., 2]), lambda G: np.stack([0 * G[..., 0], 0 * G[..., 1],
                                                                         -np.sin(G[..., 2])], -1), n=3)
    return ls.SuslovSystem(ls.Inertia.from_principal_moments([1.0, 2.0, 2.5]), potential=pot)


def test_user_potential_falls_back_to_numpy():
    system = user_potential_system()
    omega = system.constraints.from_coordinates([0.3, -0.2])
    Gamma = np.array([0.0, 0.6, 0.8])
    sol = ls.integrate(system, omega, (0.0, 1.0), Gamma0=Gamma, method="rkmk45")
    assert sol.stats["backend"] == "numpy"
    with pytest.raises(ValueError, match="backend='numba'.*not a built-in polynomial potential"):
        ls.integrate(system, omega, (0.0, 1.0), Gamma0=Gamma, method="rkmk45", backend="numba")
    fam = ls.cases.CASES["family3"].build()
    omega, Gamma = fam.random_state(0)
    assert ls.integrate(fam.system, omega, (0.0, 0.5), Gamma0=Gamma, method="rkmk4", h=0.1).stats["backend"] \
        == "numpy"


def test_probing_rejects_a_field_that_is_not_quadratic():
    model = kt4().system.model(gamma=True)

    class Cubic:  # a model-protocol object whose field has a cubic term
        k, n, has_gamma, algebra = model.k, model.n, True, model.algebra
        omega_matrix = staticmethod(model.omega_matrix)

        @staticmethod
        def xi_dot(xi, G):
            return model.xi_dot(xi, G) + 1e-3 * xi ** 3

    with pytest.raises(compiled.NotCompilable, match="not a polynomial of degree <= 2"):
        compiled.compile_plan(Cubic(), "g", "exp")
    plan = compiled.compile_plan(model, "g", "exp")
    assert plan.field_value.size == model.k  # Klebsh–Tisserand: xi_i' = c_i Gamma_i Gamma_n, one term each
    assert plan.omega_value.size == model.k  # Fedorov–Kozlov: Omega = u ∧ e_n


def test_other_algebras_run_the_group_part_on_numpy():
    alg = ls.se(3)
    D = ls.Subspace.annihilator(alg, np.array([[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]]))
    system = ls.SuslovSystem(ls.Inertia(alg, np.diag([1.0, 2.0, 3.0, 1.5, 2.5, 3.5])), constraints=D)
    omega = D.from_coordinates(np.linspace(0.2, 0.6, D.dim))
    sol = ls.integrate(system, omega, (0.0, 1.0), reconstruct=True, method="rkmk4", h=0.1)
    assert sol.stats["backend"] == "numpy"
    with pytest.raises(ValueError, match="SO\\(n\\) only"):
        ls.integrate(system, omega, (0.0, 1.0), reconstruct=True, method="rkmk4", h=0.1, backend="numba")
    a, b = both(system, omega, t_span=(0.0, 1.0), method="rkmk45", t_eval=[0.0, 1.0])  # no group part
    assert_same(a, b)


def test_backend_argument_and_missing_numba(monkeypatch):
    case = kt4()
    omega, Gamma = case.random_state(0)
    with pytest.raises(ValueError, match="backend must be one of"):
        ls.integrate(case.system, omega, (0.0, 1.0), Gamma0=Gamma, h=0.1, backend="cuda")
    monkeypatch.setattr(compiled, "numba_available", lambda: False)
    sol = ls.integrate(case.system, omega, (0.0, 1.0), Gamma0=Gamma, h=0.1)
    assert sol.stats["backend"] == "numpy"
    with pytest.raises(ValueError, match="numba is not installed"):
        ls.integrate(case.system, omega, (0.0, 1.0), Gamma0=Gamma, h=0.1, backend="numba")


def test_auto_leaves_large_n_to_numpy(monkeypatch):
    monkeypatch.setattr(compiled, "AUTO_MAX_N", 3)
    case = kt4()
    omega, Gamma = case.random_state(0)
    kw = dict(t_span=(0.0, 0.1), Gamma0=Gamma, reconstruct=True, h=0.05)
    assert ls.integrate(case.system, omega, **kw).stats["backend"] == "numpy"
    assert ls.integrate(case.system, omega, backend="numba", **kw).stats["backend"] == "numba"


def test_auto_leaves_large_batches_to_numpy(monkeypatch):
    monkeypatch.setattr(compiled, "AUTO_MAX_BATCH", 2)
    case = kt4()
    omega, Gamma = case.random_state(0, batch=(3,))
    kw = dict(t_span=(0.0, 0.1), Gamma0=Gamma, reconstruct=True, h=0.05)
    a = ls.integrate(case.system, omega, **kw)
    b = ls.integrate(case.system, omega, backend="numba", **kw)
    assert a.stats["backend"] == "numpy" and b.stats["backend"] == "numba"
    assert np.abs(a.g - b.g).max() < 1e-13


def test_importing_liesuslov_does_not_import_numba():
    code = "import sys, liesuslov; assert 'numba' not in sys.modules, 'numba imported'"
    subprocess.run([sys.executable, "-c", code], check=True)
