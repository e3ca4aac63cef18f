"""The compiled solve (:mod:`liesuslov.integrators.kernel`): the method of the numpy stepper to rounding, per
trajectory, with dense output, events, failures and exact structure.

The first test compiles the kernel (cached on disk after that).
"""

from __future__ import annotations

import os

import numpy as np
import pytest

import liesuslov as ls

pytest.importorskip("numba")

from liesuslov.integrators import kernel  # noqa: E402
from liesuslov.integrators.integrate import METHODS  # noqa: E402
from liesuslov.integrators.plan import make_plan  # noqa: E402
from liesuslov.integrators.problem import Problem  # noqa: E402
from liesuslov.integrators.tableaux import get_tableau  # noqa: E402

EPS = np.finfo(float).eps
# one step of every tableau: the fixed-step methods, and the adaptive ones with a loose tolerance
STEP_METHODS = ["lie-euler", "rkmk2", "rkmk-heun", "rkmk3", "rkmk4", "rkmk5", "rkmk8", "rkmk23", "rkmk45",
                "rkmk853"]


def make_problem(model, xi0, *, G0=None, gamma=None, mode="none", chart="exp", kind=None, method="rkmk4", h=0.0,
                 t_span=(0.0, 1.0), rtol=1e-8, atol=1e-10, t_eval=None, max_steps=10**7, reproject=True,
                 event_coef=None, event_offset=None, event_terminal=None, event_direction=None, tableau=None):
    """A Problem as the front door builds it (batch flattened)."""
    meth = METHODS[method]
    plan = make_plan(get_tableau(tableau or meth.tableau))
    xi0 = np.atleast_2d(np.asarray(xi0, float))
    B, k = xi0.shape
    m = 0 if mode == "none" else int(model.n)
    q = {"none": 0, "gamma": m, "g": m * m}[mode]
    G0 = np.zeros((B, 0)) if G0 is None else np.asarray(G0, float).reshape(B, q)
    gamma = np.zeros((B, 0)) if gamma is None else np.asarray(gamma, float).reshape(B, -1)
    if kind is None:
        kind = kernel.kind_for(model, mode, chart)
    skew = model.algebra.name.startswith("so(")
    E = 0 if event_coef is None else event_coef.shape[1]
    linear = [(np.ascontiguousarray(event_coef[:, e]), np.ascontiguousarray(event_offset[:, e])) for e in range(E)]
    if E:
        event_terminal = np.zeros(E, np.int64) if event_terminal is None else np.asarray(event_terminal, np.int64)
        event_direction = np.zeros(E, np.int64) if event_direction is None else np.asarray(event_direction, np.int64)
    return Problem(model=model, mode=mode, chart=chart if mode != "none" else None, kind=kind, skew=skew, plan=plan,
                   k=k, m=m, q=q, B=B, xi0=np.ascontiguousarray(xi0), G0=np.ascontiguousarray(G0),
                   gamma=np.ascontiguousarray(gamma), t0=float(t_span[0]), t1=float(t_span[1]),
                   adaptive=meth.adaptive, h=float(h), rtol=rtol, atol=atol, max_steps=max_steps,
                   t_eval=None if t_eval is None else np.asarray(t_eval, float), events=[None] * E, event_linear=linear,
                   event_terminal=event_terminal,
                   event_direction=event_direction, reproject=reproject)


def rotations(rng, B, n):
    Q = np.linalg.qr(rng.normal(size=(B, n, n)))[0]
    Q[:, :, 0] *= np.sign(np.linalg.det(Q))[:, None]
    return Q


def unit(rng, B, n):
    v = rng.normal(size=(B, n))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def general_system(n, rng, potential=True):
    Q = np.linalg.qr(rng.normal(size=(n, n)))[0]
    I = Q @ np.diag(np.linspace(1.0, 2.5, n)) @ Q.T
    S = rng.normal(size=(n, n))
    pot = ls.QuadraticPotential(S + S.T) if potential else None
    return ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), potential=pot)


def fk_system(n, rng):
    A = rng.normal(size=(n, n)) * 0.2
    I = np.diag(np.linspace(1.0, 2.0, n)) + A @ A.T
    return ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), constraints="fedorov_kozlov")


def scenes():
    """(name, model, kind) for every kind: so3, dense n = 4 and 5, lowrank n = 8, so4 (the dense4 model)."""
    rng = np.random.default_rng(1)
    out = [("so3", ls.cases.gyroscopic3([1.0, 2.0, 2.5], 0.7, ls.QuadraticPotential([1.0, 2.0, 0.5])).system
            .model(gamma=True), "so3")]
    for n in (4, 5):
        out.append((f"dense{n}", general_system(n, rng).model(gamma=True), "dense"))
    out.append(("lowrank8", fk_system(8, rng).model(gamma=False), "lowrank"))
    out.append(("so4", out[1][1], "so4"))
    return out


SCENES = scenes()


def numpy_solve(problem):
    from liesuslov.integrators import solve_numpy

    return solve_numpy.solve(problem)


def assert_same_run(a, b, atol=1e-12):
    """The compiled run ``a`` against the numpy run ``b``: counts equal, states to rounding."""
    for key in ("status", "failure", "nfev", "steps", "rejected"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key), err_msg=key)
    np.testing.assert_allclose(a.t_stop, b.t_stop, rtol=1e-12)
    np.testing.assert_allclose(a.xi, b.xi, rtol=0, atol=atol * max(1.0, np.nanmax(np.abs(b.xi))))
    np.testing.assert_allclose(a.G, b.G, rtol=0, atol=atol)


@pytest.mark.parametrize("mode", ["g", "gamma"])
@pytest.mark.parametrize("chart", ["exp", "cayley"])
@pytest.mark.parametrize("scene", range(len(SCENES)), ids=[s[0] for s in SCENES])
def test_every_tableau_agrees_with_the_numpy_solver(scene, chart, mode):
    name, model, kind = SCENES[scene]
    if mode == "gamma" and not model.has_gamma:
        pytest.skip("no vertical in this model")
    rng = np.random.default_rng(scene)
    B, n = 2, model.n
    xi = rng.normal(size=(B, model.k))
    gamma = unit(rng, B, n) if model.has_gamma else None
    G = rotations(rng, B, n).reshape(B, -1) if mode == "g" else unit(rng, B, n)
    rtol = 1e-7
    for method in STEP_METHODS:
        adaptive = METHODS[method].adaptive
        p = make_problem(model, xi, G0=G, gamma=gamma if mode == "g" else None, mode=mode, chart=chart, kind=kind,
                         method=method, h=0.0 if adaptive else 0.1, t_span=(0.0, 0.55),
                         t_eval=[0.0, 0.13, 0.4, 0.55], rtol=rtol, atol=1e-9)
        res = kernel.solve(p)
        assert res.backend == "numba" and np.all(res.status == 0), method
        # Adaptive runs: a step's error estimate can be at the rounding level (the first step of rkmk853 on the
        # low-rank scene: nrm ~ 6e-8, so the next h is set by rounding noise; the two paths' next steps then differ
        # by ~2e-6 relative, and the end states by ~rtol * that ~ 1e-12, measured). States to rounding plus that.
        assert_same_run(res, numpy_solve(p), atol=1e-12 + (1e-4 * rtol if adaptive else 0.0))


def test_kinds_and_check():
    rng = np.random.default_rng(0)
    so3 = SCENES[0][1]
    assert kernel.kind_for(so3, "g", "exp") == "so3"
    assert kernel.kind_for(so3, "none", None) is None
    assert kernel.kind_for(SCENES[1][1], "g", "exp") == "so4"
    assert kernel.kind_for(SCENES[2][1], "g", "exp") == "dense"
    with pytest.raises(kernel.NotCompilable, match="4×4"):
        kernel.check(make_problem(SCENES[2][1], np.zeros((1, SCENES[2][1].k)), G0=np.eye(5).ravel(), mode="g",
                                  kind="so4"))
    fk = fk_system(16, rng).model(gamma=False)
    assert kernel.kind_for(fk, "g", "cayley") == "lowrank"
    p = make_problem(so3, np.zeros((1, so3.k)), G0=np.eye(3).ravel(), mode="g", event_coef=np.zeros((1, 1, 11)),
                     event_offset=np.zeros((1, 1)))
    p.event_linear = [None]  # a user callable: no linear form
    with pytest.raises(kernel.NotCompilable, match="callable"):
        kernel.check(p)
    assert issubclass(kernel.NotCompilable, ValueError)
    user = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0])),
                           potential=ls.Potential(lambda G: np.sum(G ** 4, axis=-1),
                                                  lambda G: 4 * G ** 3)).model(gamma=True)
    with pytest.raises(kernel.NotCompilable, match="polynomial"):
        kernel.check(make_problem(user, np.zeros((1, user.k)), G0=[0.0, 0.0, 1.0], mode="gamma"))


def test_first_calls_in_several_threads_compile_or_load_one_at_a_time(monkeypatch):
    """numba's loading from its cache is not thread-safe: first calls of a process in 8 threads at once failed
    in 1 process of 5 ("generator already executing", an audit). The first use of a family is serialised;
    checked here by making that first use slow and counting the threads inside it."""
    import threading
    import time

    from liesuslov.integrators.kernel import wrapper

    inside, most, guard = [0], [0], threading.Lock()
    real = wrapper._compile_apart

    def slow_first_use(family, sig):
        with guard:
            inside[0] += 1
            most[0] = max(most[0], inside[0])
        time.sleep(0.05)
        real(family, sig)
        with guard:
            inside[0] -= 1

    monkeypatch.setattr(wrapper, "_LOOPS", {})  # every family's first use again (loaded from the cache)
    monkeypatch.setattr(wrapper, "_compile_apart", slow_first_use)
    monkeypatch.setattr(wrapper._solve_one, "overloads", {})
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0])),
                             potential=ls.LinearPotential([0.2, 0.0, 1.0]))
    Omega0 = system.constraints.basis[0] * 0.5
    barrier, out = threading.Barrier(4), []

    def call():
        barrier.wait()
        out.append(ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=[0.0, 0.6, 0.8], h=0.01, backend="numba"))

    threads = [threading.Thread(target=call) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(out) == 4 and most[0] == 1
    assert all(np.array_equal(sol.omega, out[0].omega) for sol in out)


def test_a_model_the_kernel_refuses_is_not_kept_alive():
    """The refusal was cached with its traceback, whose frames (the caller's too) held the model, the weak key of
    the cache: a new system per call (a parameter sweep) kept every caller's data alive (an audit: +190 MB per
    call of a function holding 200 MB)."""
    import gc
    import weakref

    class Data:  # the caller's own data, unrelated to the solve
        pass

    def user_step():
        data = Data()
        system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0])),
                                 potential=ls.Potential(lambda G: np.sum(G ** 4, axis=-1), lambda G: 4 * G ** 3))
        sol = ls.integrate(system, [0.0, 0.3, 0.2], (0.0, 0.1), Gamma0=[0.0, 0.0, 1.0], h=0.05)
        assert "polynomial" in sol.stats["backend_reason"]
        return weakref.ref(data), weakref.ref(system)

    refs = [user_step() for _ in range(2)]
    gc.collect()
    assert all(r() is None for pair in refs for r in pair)


def test_batch_equals_alone_bitwise():
    rng = np.random.default_rng(5)
    model = ls.cases.klebsh_tisserand([1.0, 1.3, 1.7, 2.0], [4.0, 3.5, 3.0, 1.0]).system.model(gamma=True)
    B = 6
    xi = rng.normal(size=(B, model.k)) * np.array([0.3, 1.0, 3.0, 0.5, 2.0, 1.0])[:, None]
    g = rotations(rng, B, 4).reshape(B, -1)
    gamma = unit(rng, B, 4)
    for method, chart in (("rkmk45", "exp"), ("rkmk853", "cayley")):
        kw = dict(mode="g", chart=chart, method=method, t_span=(0.0, 3.0), t_eval=np.linspace(0.0, 3.0, 7),
                  rtol=1e-9, atol=1e-11)
        full = kernel.solve(make_problem(model, xi, G0=g, gamma=gamma, **kw))
        assert np.all(full.status == 0)
        assert len(set(full.steps.tolist())) > 1  # trajectories take their own steps
        for b in (0, 3, 5):
            one = kernel.solve(make_problem(model, xi[b:b + 1], G0=g[b:b + 1], gamma=gamma[b:b + 1], **kw))
            np.testing.assert_array_equal(one.xi[:, 0], full.xi[:, b])
            np.testing.assert_array_equal(one.G[:, 0], full.G[:, b])
            for key in ("nfev", "steps", "rejected", "t_stop"):
                assert getattr(one, key)[0] == getattr(full, key)[b], key


def test_failure_is_isolated():
    rng = np.random.default_rng(2)
    model = SCENES[1][1]
    B = 4
    xi = rng.normal(size=(B, model.k))
    xi[2, 0] = np.nan
    g = rotations(rng, B, 4).reshape(B, -1)
    gamma = unit(rng, B, 4)
    kw = dict(mode="g", method="rkmk45", t_span=(0.0, 1.0), t_eval=[0.0, 0.5, 1.0])
    res = kernel.solve(make_problem(model, xi, G0=g, gamma=gamma, **kw))
    assert res.status.tolist() == [0, 0, -1, 0]
    assert res.failure[2] == 1 and res.t_stop[2] == 0.0
    assert np.all(np.isnan(res.xi[1:, 2])) and np.all(np.isnan(res.G[1:, 2]))
    one = kernel.solve(make_problem(model, xi[3:], G0=g[3:], gamma=gamma[3:], **kw))
    np.testing.assert_array_equal(one.xi[:, 0], res.xi[:, 3])
    # max_steps: code 3, the time it stopped, never a hang
    res = kernel.solve(make_problem(model, xi[:1], G0=g[:1], gamma=gamma[:1], max_steps=5, **kw))
    assert res.status[0] == -1 and res.failure[0] == 3 and 0.0 < res.t_stop[0] < 1.0
    assert res.steps[0] + res.rejected[0] == 5


def euler_top():
    """A free symmetric top in so(3) (no constraint): in the algebra's coordinates omega_0 (the symmetry axis)
    is constant and omega_1 = cos(lam t) from (w3, 1, 0)."""
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag([1.0, 1.0, 2.0])), constraints="none")
    return system.model(gamma=False)


def test_events_against_a_closed_form():
    model = euler_top()
    x = np.array([[6.0, 1.0, 0.0]])
    xi = model.xi_from_coords(x)
    Bm = model.omega_coords(np.eye(model.k))  # omega = xi @ Bm
    coef = np.zeros((1, 2, model.k))
    coef[0, 0] = Bm[:, 1]  # omega_1 = 0, both directions
    coef[0, 1] = Bm[:, 1]  # omega_1 = 0 upward, terminal when asked
    kw = dict(mode="none", method="rkmk853", t_span=(0.0, 20.0), t_eval=np.linspace(0, 20, 5), rtol=1e-10,
              atol=1e-12, event_coef=coef, event_offset=np.zeros((1, 2)), event_direction=[0, 1])
    p = make_problem(model, xi, event_terminal=[0, 0], **kw)
    res = kernel.solve(p)
    ref = numpy_solve(p)
    for e in range(2):
        np.testing.assert_allclose(res.event_t[e], ref.event_t[e], rtol=0, atol=1e-12)
        np.testing.assert_allclose(res.event_xi[e], ref.event_xi[e], rtol=0, atol=1e-12)
    assert_same_run(res, ref)
    t = res.event_t[0]
    assert len(t) >= 6
    # omega_1 = cos(lam t): roots at (pi/2 + n pi) / lam, equally spaced
    lam = np.pi / np.diff(t).mean()
    np.testing.assert_allclose(t, (np.pi / 2 + np.pi * np.arange(len(t))) / lam, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.event_t[1], t[1::2], rtol=0, atol=1e-12)  # the upward ones
    np.testing.assert_allclose((res.event_xi[0] @ Bm)[:, 1], 0.0, atol=1e-10)
    # terminal: stops at the first upward crossing, later outputs NaN
    res = kernel.solve(make_problem(model, xi, event_terminal=[0, 1], **kw))
    assert res.status[0] == 1 and res.t_stop[0] == res.event_t[1][0] == pytest.approx(t[1], abs=1e-12)
    assert len(res.event_t[0]) == 2 and len(res.event_t[1]) == 1
    stopped = res.t > res.t_stop[0]
    assert np.isnan(res.xi[stopped]).all() and not np.isnan(res.xi[~stopped]).any()
    # the same events over a batch, indices sorted
    p = make_problem(model, np.repeat(xi, 3, axis=0) * np.array([[1.0], [0.5], [2.0]]), mode="none",
                     method="rkmk45", t_span=(0.0, 10.0), t_eval=[0.0, 10.0], rtol=1e-9, atol=1e-11,
                     event_coef=np.repeat(coef[:, :1], 3, axis=0), event_offset=np.zeros((3, 1)))
    res = kernel.solve(p)
    assert np.all(np.diff(res.event_index[0]) >= 0)
    assert np.bincount(res.event_index[0]).tolist()[0] == len(t[t < 10.0])


def test_many_crossings_grow_the_storage():
    model = euler_top()
    xi = model.xi_from_coords(np.array([[40.0, 1.0, 0.0]]))
    Bm = model.omega_coords(np.eye(model.k))
    coef = Bm[:, 1].reshape(1, 1, -1).copy()
    res = kernel.solve(make_problem(model, xi, mode="none", method="rkmk45", t_span=(0.0, 10.0),
                                    t_eval=[0.0, 10.0], event_coef=coef, event_offset=np.zeros((1, 1))))
    assert len(res.event_t[0]) > kernel.EVENT_CAP
    assert np.all(np.diff(res.event_t[0]) > 0)


@pytest.mark.parametrize("method", ["rkmk23", "rkmk45", "rkmk853"])
def test_dense_output_order(method):
    name, model, kind = SCENES[1]
    rng = np.random.default_rng(3)
    xi = rng.normal(size=(1, model.k))
    g = rotations(rng, 1, 4).reshape(1, -1)
    gamma = unit(rng, 1, 4)
    plan = make_plan(get_tableau(METHODS[method].tableau))
    # the local error of the extension at theta = 0.37 of one step, against a tight run that ends at that time
    # (its own steps, no extension involved): h^(q+1) for an extension of order q, fitted on three step sizes
    # (measured slopes 3.83, 5.28, 7.90); test_solve.py's dense-order test checks against scipy instead
    hs = {"rkmk23": 0.1, "rkmk45": 0.2, "rkmk853": 0.4}[method] / np.array([1.0, 2.0, 4.0])
    errs = []
    for h in hs:
        te = 0.37 * h
        p = make_problem(model, xi, G0=g, gamma=gamma, mode="g", method=method, h=h, t_span=(0.0, h),
                         t_eval=[te], rtol=1e3, atol=1e3)
        res = kernel.solve(p)
        assert res.steps[0] == 1
        ref = kernel.solve(make_problem(model, xi, G0=g, gamma=gamma, mode="g", method="rkmk853",
                                        t_span=(0.0, te), t_eval=[te], rtol=1e-13, atol=1e-15))
        errs.append(max(np.abs(res.xi[0] - ref.xi[0]).max(), np.abs(res.G[0] - ref.G[0]).max()))
        Gt = res.G[0, 0].reshape(4, 4)
        assert np.abs(Gt.T @ Gt - np.eye(4)).max() < 10 * EPS  # exact structure at interpolated times
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert abs(slope - (plan.dense_order + 1)) < 0.5, (errs, slope)


@pytest.mark.parametrize("scene", range(len(SCENES)), ids=[s[0] for s in SCENES])
@pytest.mark.parametrize("chart", ["exp", "cayley"])
def test_one_step_structure(scene, chart):
    name, model, kind = SCENES[scene]
    rng = np.random.default_rng(scene)
    n = model.n
    xi = rng.normal(size=(4, model.k))
    Om = model.omega_matrix(xi)
    xi *= 4.0 / np.sqrt(0.5 * np.sum(Om ** 2, axis=(1, 2)))[:, None]  # |h Omega| = 2 rad
    gamma = unit(rng, 4, n) if model.has_gamma else None
    p = make_problem(model, xi, G0=np.tile(np.eye(n).ravel(), (4, 1)), gamma=gamma, mode="g", chart=chart,
                     kind=kind, method="rkmk4", h=0.5, t_span=(0.0, 0.5), t_eval=[0.5], reproject=False)
    res = kernel.solve(p)
    assert np.all(res.status == 0)
    R = res.G[0].reshape(4, n, n)
    assert np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(n)).max() <= 10 * EPS
    if model.has_gamma:
        p = make_problem(model, xi, G0=gamma, mode="gamma", chart=chart, kind=kind, method="rkmk4", h=0.5,
                         t_span=(0.0, 0.5), t_eval=[0.5], reproject=False)
        res = kernel.solve(p)
        assert np.abs(np.linalg.norm(res.G[0], axis=1) - 1.0).max() <= 10 * EPS


@pytest.mark.parametrize("kind", ["so3", "dense", "lowrank", "so4"])
def test_structure_without_reprojection(kind):
    rng = np.random.default_rng(4)
    model = {"so3": SCENES[0][1], "dense": SCENES[1][1], "lowrank": SCENES[3][1], "so4": SCENES[4][1]}[kind]
    n = model.n
    N = 10_000
    xi = rng.normal(size=(1, model.k))
    gamma = unit(rng, 1, n) if model.has_gamma else None
    p = make_problem(model, xi, G0=np.eye(n).ravel(), gamma=gamma, mode="g", method="rkmk4", h=0.01,
                     t_span=(0.0, N * 0.01), t_eval=[N * 0.01], reproject=False, kind=kind)
    res = kernel.solve(p)
    assert res.steps[0] == N
    R = res.G[0, 0].reshape(n, n)
    assert np.abs(R.T @ R - np.eye(n)).max() <= 2 * N * EPS
    if model.has_gamma:
        p = make_problem(model, xi, G0=gamma, mode="gamma", method="rkmk4", h=0.01, t_span=(0.0, N * 0.01),
                         t_eval=[N * 0.01], reproject=False, kind=kind)
        res = kernel.solve(p)
        assert abs(np.linalg.norm(res.G[0, 0]) - 1.0) <= 2 * N * EPS


def test_chart_domain():
    model = euler_top()
    so3 = SCENES[0][1]
    xi = np.array([[0.0, 0.0]])
    xi[0, 0] = 1.0
    # fixed step with |h Omega| = 2 pi: fails with code 4, at the start
    Om = so3.omega_matrix(xi)[0]
    w = np.sqrt(0.5 * np.sum(Om ** 2))
    h = 2 * np.pi / w
    base = dict(G0=np.eye(3).ravel(), gamma=np.array([0.0, 0.0, 1.0]), mode="g", t_span=(0.0, 3 * h),
                t_eval=[0.0, 3 * h])
    res = kernel.solve(make_problem(so3, xi, method="rkmk4", h=h, **base))
    assert res.status[0] == -1 and res.failure[0] == 4 and res.t_stop[0] == 0.0
    # adaptive from the same first step: rejected, then it finishes
    res = kernel.solve(make_problem(so3, xi, method="rkmk45", h=h, **base))
    assert res.status[0] == 0 and res.rejected[0] >= 1
    ref = kernel.solve(make_problem(so3, xi, method="rkmk45", **base))
    np.testing.assert_allclose(res.G[-1], ref.G[-1], atol=1e-6)
    del model


def klebsh_tisserand():
    """The Klebsh–Tisserand body in SO(4) (Fedorov–Kozlov constraints), the benchmark's scene."""
    return ls.cases.klebsh_tisserand(np.array([1.0, 1.5, 2.0, 0.5]), np.array([4.0, 3.0, 2.5, 1.0])).system.model(
        gamma=True)


@pytest.mark.parametrize("mode", ["g", "gamma"])
@pytest.mark.parametrize("chart", ["exp", "cayley"])
@pytest.mark.parametrize("method", ["rkmk4", "rkmk45", "rkmk853"])
def test_so4_agrees_with_the_numpy_solver(method, chart, mode):
    """The so4 kind (closed forms on the pair (p, q)) runs the numpy solver's so(4) kernel to rounding, and the
    dense kind's matrix algorithms (the same truncated dexp⁻¹ series) to rounding too."""
    model = klebsh_tisserand()
    assert kernel.kind_for(model, mode, chart) == "so4"
    rng = np.random.default_rng(12)
    B = 2
    xi = rng.normal(size=(B, model.k))
    gamma = unit(rng, B, 4)
    G = rotations(rng, B, 4).reshape(B, -1) if mode == "g" else gamma
    adaptive = METHODS[method].adaptive
    kw = dict(G0=G, gamma=gamma if mode == "g" else None, mode=mode, chart=chart, method=method,
              h=0.0 if adaptive else 0.01, t_span=(0.0, 3.0), t_eval=[0.0, 0.7, 2.2, 3.0], rtol=1e-10, atol=1e-12)
    p = make_problem(model, xi, kind="so4", **kw)
    res = kernel.solve(p)
    assert np.all(res.status == 0) and res.steps.min() >= 10
    assert_same_run(res, numpy_solve(p), atol=1e-13)
    assert_same_run(res, kernel.solve(make_problem(model, xi, kind="dense", **kw)), atol=1e-13)


def test_so4_chart_domain_agrees_with_numpy():
    """A step with |h Omega|_F / sqrt 2 = 2 pi: the fixed step fails with code 4 at the start, the adaptive one
    is rejected and finishes — with the numpy solver's counts."""
    model = klebsh_tisserand()
    xi = np.array([[0.3, -0.2, 0.25]])
    w = np.sqrt(0.5 * np.sum(model.omega_matrix(xi)[0] ** 2))
    h = 2 * np.pi / w
    base = dict(G0=np.eye(4).ravel(), gamma=np.array([0.2, -0.4, 0.4, 0.8]), mode="g", kind="so4",
                t_span=(0.0, 3 * h), t_eval=[0.0, 3 * h])
    p = make_problem(model, xi, method="rkmk4", h=h, **base)
    res = kernel.solve(p)
    assert res.status[0] == -1 and res.failure[0] == 4 and res.t_stop[0] == 0.0
    assert_same_run(res, numpy_solve(p))
    p = make_problem(model, xi, method="rkmk45", h=h, **base)
    res = kernel.solve(p)
    assert res.status[0] == 0 and res.rejected[0] >= 1
    assert_same_run(res, numpy_solve(p), atol=1e-13)


def test_record_every_step_and_backward():
    name, model, kind = SCENES[0]
    rng = np.random.default_rng(8)
    xi = rng.normal(size=(1, model.k))
    gamma = unit(rng, 1, 3)
    p = make_problem(model, xi, G0=np.eye(3).ravel(), gamma=gamma, mode="g", method="rkmk45",
                     t_span=(0.0, -2.0), t_eval=None)
    res = kernel.solve(p)
    assert res.t[0] == 0.0 and res.t[-1] == -2.0 and np.all(np.diff(res.t) < 0)
    assert res.xi.shape == (len(res.t), 1, model.k) and len(res.t) == res.steps[0] + 1
    q = make_problem(model, xi, G0=np.eye(3).ravel(), gamma=gamma, mode="g", method="rkmk45",
                     t_span=(0.0, -2.0), t_eval=res.t)
    out = kernel.solve(q)
    np.testing.assert_array_equal(out.xi, res.xi)
    np.testing.assert_array_equal(out.steps, res.steps)


@pytest.mark.parametrize("n", [8, 64])
def test_lowrank_agrees_with_dense(n):
    rng = np.random.default_rng(n)
    model = fk_system(n, rng).model(gamma=False)
    xi = rng.normal(size=(2, model.k)) / np.sqrt(n)
    g = rotations(rng, 2, n).reshape(2, -1)
    for chart in ("exp", "cayley"):
        kw = dict(G0=g, mode="g", chart=chart, method="rkmk45", t_span=(0.0, 1.0), t_eval=[0.0, 0.5, 1.0],
                  rtol=1e-9, atol=1e-11)
        lo = kernel.solve(make_problem(model, xi, kind="lowrank", **kw))
        de = kernel.solve(make_problem(model, xi, kind="dense", **kw))
        assert np.all(lo.status == 0) and np.all(lo.steps == de.steps) and np.all(lo.nfev == de.nfev)
        np.testing.assert_allclose(lo.xi, de.xi, atol=1e-12)
        np.testing.assert_allclose(lo.G, de.G, atol=1e-12)


@pytest.mark.slow
def test_lowrank_n256():
    """Fedorov–Kozlov in SO(256) with reconstruction (diagonal I: a sparse field; probing a general I's dense
    quadratic field at n = 256 would take minutes)."""
    model = ls.cases.suslov_free(np.diag(np.linspace(1.0, 2.0, 256))).system.model(gamma=False)
    rng = np.random.default_rng(256)
    xi = rng.normal(size=(1, model.k)) / 16
    res = kernel.solve(make_problem(model, xi, G0=np.eye(256).ravel(), mode="g", method="rkmk4", h=0.05,
                                    t_span=(0.0, 1.0), t_eval=[1.0], reproject=False))
    R = res.G[0, 0].reshape(256, 256)
    assert res.status[0] == 0 and np.abs(R.T @ R - np.eye(256)).max() < 1e-13
    Om = model.omega_matrix(xi)[0]  # xi' = 0 here: g(t) = exp(t Omega)
    from scipy.linalg import expm

    assert np.abs(R - expm(Om)).max() < 1e-10


@pytest.mark.parametrize("chart", ["exp", "cayley"])
def test_general_matrix_algebra_se3(chart):
    """se(3) (not skew): full brackets, Padé with the 1-norm, Cayley by LU — the numpy solver's numbers."""
    alg = ls.se(3)
    D = ls.Subspace.annihilator(alg, np.array([[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]]))
    system = ls.SuslovSystem(ls.Inertia(alg, np.diag([1.0, 2.0, 3.0, 1.5, 2.5, 3.5])), constraints=D)
    model = system.model(gamma=False)
    rng = np.random.default_rng(9)
    xi = rng.normal(size=(2, model.k)) * 0.5
    g0 = np.tile(np.eye(4).ravel(), (2, 1))
    assert kernel.kind_for(model, "g", chart) == "dense"
    for method in ("rkmk4", "rkmk45"):
        p = make_problem(model, xi, G0=g0, mode="g", chart=chart, method=method, h=0.1, t_span=(0.0, 1.0),
                         t_eval=[0.0, 0.35, 1.0], rtol=1e-8, atol=1e-10)
        assert not p.skew
        res = kernel.solve(p)
        assert np.all(res.status == 0)
        assert_same_run(res, numpy_solve(p))
        assert np.all(res.G[:, :, 12:15] == 0.0) and np.all(res.G[:, :, 15] == 1.0)  # the last row stays (0, 1)


def test_warm_compiles_every_kind_and_rejects_unknown_ones():
    """Each kind's scene runs on the compiled kernel (its family's loop); a kind that does not exist is refused
    before any process starts."""
    from liesuslov.integrators.kernel import warm

    for kind in warm.KIND_SCENES:
        assert warm.run_kind(kind) == "numba", kind
    with pytest.raises(ValueError, match="kinds"):
        warm.compile_kinds(["so5"])
    with pytest.raises(ValueError, match="kind"):
        warm.run_kind("so5")
    assert set(warm.compile_kinds(["so3"], processes=1)) == {"so3"}


def test_the_cache_is_stamped_with_every_kernel_source(tmp_path):
    """numba stamps a cached function with its own file only; the kernel's functions embed code of other files
    (groups/, control.py), so their stamp hashes all of them: a change in any one makes the cache stale."""
    from liesuslov.integrators.kernel import common, loop

    names = {(p.parent.name, p.name) for p in common.KERNEL_SOURCES}
    assert {("kernel", "loop.py"), ("kernel", "group.py"), ("groups", "so3.py"), ("groups", "so4.py"),
            ("integrators", "control.py")} <= names
    assert not names & {("kernel", "wrapper.py"), ("kernel", "warm.py")}  # Python only: no compiled code
    import numba

    for name in ("wrapper", "warm"):  # (so leaving them out cannot serve a stale compiled function)
        mod = __import__(f"liesuslov.integrators.kernel.{name}", fromlist=[name])
        assert not [v for v in vars(mod).values() if isinstance(v, numba.core.dispatcher.Dispatcher)
                    and v.py_func.__module__ == mod.__name__]
    for fn in (loop._solve_one, common._accept_factor):
        assert fn._cache._cache_file._source_stamp == common.sources_stamp(common.KERNEL_SOURCES)
    a, b = tmp_path / "a.py", tmp_path / "b.py"
    a.write_text("x = 1\n")
    b.write_text("y = 2\n")
    before = common.sources_stamp([a, b])
    b.write_text("y = 3\n")  # the second file alone changes
    assert common.sources_stamp([a, b]) != before


def test_the_precompiled_kernel_is_read_first_and_written_only_while_precompiling(tmp_path, monkeypatch):
    """_KernelCacheFile: a function's compiled code is looked up in the installation's precompiled directory,
    then in numba's own cache; a compilation goes to numba's own cache, or only to the precompiled directory
    while the build precompiles (LIESUSLOV_PRECOMPILED=write, where numba's own cache is not read either);
    LIESUSLOV_PRECOMPILED=off reads numba's own cache alone; an entry stamped with other kernel sources is not
    read (stale)."""
    from liesuslov.integrators.kernel import common

    pre, own = tmp_path / "precompiled", tmp_path / "own"
    own.mkdir()
    monkeypatch.setattr(common, "PRECOMPILED_DIR", pre)
    key = ("sig", ("triple", "cpu", "features"), ("code", ""))

    def files(setting, stamp=b"kernel sources"):
        if setting is None:
            monkeypatch.delenv(common.PRECOMPILED_ENV, raising=False)
        else:
            monkeypatch.setenv(common.PRECOMPILED_ENV, setting)
        return common._KernelCacheFile(str(own), "f-1.py311", stamp)

    files(None).save(key, "compiled here")
    assert not pre.exists() and files(None).load(key) == "compiled here"
    assert files("write").load(key) is None  # precompiling reads the precompiled directory alone
    files("write").save(key, "compiled by the build")  # (creates the directory)
    assert files(None).load(key) == "compiled by the build"  # read first
    assert files("off").load(key) == "compiled here"
    assert files(None, stamp=b"changed sources").load(key) is None  # both stale
    (own / "f-1.py311.nbi").unlink()
    assert files(None).load(key) == "compiled by the build"
    assert files("off").load(key) is None
    with pytest.raises(ValueError, match="LIESUSLOV_PRECOMPILED must be 'write', 'off' or unset, got '0'"):
        files("0")


@pytest.mark.slow
def test_a_precompiled_kernel_is_loaded_where_the_package_is_installed(tmp_path):
    """The build's precompile step (warm with LIESUSLOV_PRECOMPILED=write) on a copy of the package, then a first
    call from that copy in a fresh process with an empty numba cache: the loop is loaded from the precompiled
    directory (a cache hit, no compilation), which is found beside the package wherever it lies."""
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    import liesuslov
    from liesuslov.integrators.kernel import common

    built = tmp_path / "built"
    shutil.copytree(Path(liesuslov.__file__).parent, built / "liesuslov",
                    ignore=shutil.ignore_patterns("__pycache__", "_precompiled"))
    env = {k: v for k, v in os.environ.items() if k != "LIESUSLOV_KERNEL_COMPILE_HERE"}

    def run(code, root, numba_cache, **extra):  # a fresh process with its own (empty) numba cache
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=900,
                              check=False, cwd=tmp_path, env={**env, "PYTHONPATH": str(root),
                                                              "NUMBA_CACHE_DIR": str(tmp_path / numba_cache), **extra})

    res = run("from liesuslov.integrators.kernel.warm import compile_kinds; compile_kinds(['none'])", built,
              "numba-build", LIESUSLOV_PRECOMPILED="write")
    assert res.returncode == 0, res.stderr[-2000:]
    precompiled = built / "liesuslov" / common.PRECOMPILED_DIR.relative_to(Path(liesuslov.__file__).parent)
    assert any(precompiled.glob("loop._solve_one-*.nbi"))
    moved = tmp_path / "installed"
    shutil.move(built, moved)  # the package elsewhere, as a wheel's files are
    probe = ("from liesuslov.integrators.kernel.warm import run_kind; from liesuslov.integrators.kernel import loop; "
             "b = run_kind('none'); s = loop._solve_one.stats; print(b, len(s.cache_hits), len(s.cache_misses), "
             "loop.__file__)")
    res = run(probe, moved, "numba-first")
    backend, hits, misses, where = res.stdout.split()
    assert res.returncode == 0 and (backend, hits, misses) == ("numba", "1", "0"), res.stderr[-2000:]
    assert where.startswith(str(moved))
    compiled_into = lambda name: any((tmp_path / name).rglob("loop._solve_one-*.nbi"))  # noqa: E731
    assert not compiled_into("numba-build") and not compiled_into("numba-first")
    res = run(probe, moved, "numba-off", LIESUSLOV_PRECOMPILED="off")  # the compilation itself, not the directory
    assert res.returncode == 0 and res.stdout.split()[:3] == ["numba", "1", "0"], res.stderr[-2000:]
    assert compiled_into("numba-off")


@pytest.mark.slow
def test_the_first_compilation_prints_no_numba_warning(tmp_path):
    """The closed-form family's first compilation printed numba's NumbaIRAssumptionWarning ("variable ... is not
    in scope", asking the user to report it to numba) once per inlined so(4) Omega (six scalars summed in branches).
    A first call of the so(4) kind, on an empty cache, in a process where numba's warnings are errors."""
    import os
    import subprocess
    import sys

    from liesuslov.integrators.kernel.warm import COMPILE_HERE_ENV

    script = ("import warnings, numba.core.errors as e; warnings.simplefilter('error', e.NumbaWarning); "
              "from liesuslov.integrators.kernel.warm import run_kind; print(run_kind('so4'))")
    # compiled in this very process (where the warnings are errors), not in a child of it
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path), COMPILE_HERE_ENV: "1"}
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=900,
                         check=False)
    assert res.returncode == 0 and res.stdout.strip() == "numba", res.stderr[-2000:]


def test_a_family_missing_from_the_cache_is_compiled_in_a_child_process(monkeypatch):
    """_compiled compiles a family that numba's cache lacks in a child (compile_kinds, whose children get
    COMPILE_HERE_ENV and this package's root on PYTHONPATH), not when the cache has it, never from inside such
    a child (no recursion), and leaves it to this process when the child fails."""
    import subprocess
    from pathlib import Path

    from liesuslov.integrators.kernel import common, warm, wrapper

    calls = []
    compile_kinds = warm.compile_kinds  # (the wrapper imports it from warm when it needs it: patched there)
    monkeypatch.setattr(warm, "compile_kinds", lambda kinds, processes=None: calls.append((kinds, processes)))
    monkeypatch.setattr(wrapper._solve_one._cache, "load_overload", lambda sig, ctx: None)  # a cache miss
    monkeypatch.delenv(warm.COMPILE_HERE_ENV, raising=False)
    wrapper._compile_apart(2, ())
    wrapper._compile_apart(0, ())
    assert calls == [(["dense"], 1), (["none"], 1)]
    monkeypatch.setenv(warm.COMPILE_HERE_ENV, "1")  # inside a child: compile here
    wrapper._compile_apart(1, ())
    monkeypatch.setattr(wrapper._solve_one._cache, "load_overload", lambda sig, ctx: object())  # a cache hit
    monkeypatch.delenv(warm.COMPILE_HERE_ENV)
    wrapper._compile_apart(1, ())
    assert len(calls) == 2

    def failing(kinds, processes=None):
        raise RuntimeError("compiling kind 'so3' failed: no space left")
    monkeypatch.setattr(warm, "compile_kinds", failing)
    monkeypatch.setattr(wrapper._solve_one._cache, "load_overload", lambda sig, ctx: None)
    wrapper._compile_apart(1, ())  # no exception: the caller compiles

    seen = {}

    class Done:
        returncode = 0

        def __init__(self, cmd, **kw):
            seen.update(kw["env"])

        def poll(self):
            return 0

    monkeypatch.setattr(subprocess, "Popen", Done)
    monkeypatch.setenv("PYTHONPATH", "/elsewhere")
    compile_kinds(["none"], processes=1)
    root = str(Path(warm.__file__).resolve().parents[3])
    assert seen[warm.COMPILE_HERE_ENV] == "1" and seen["PYTHONPATH"].split(os.pathsep) == [root, "/elsewhere"]
    assert set(warm.FAMILY_KIND.values()) == set(warm.FAMILY_KINDS)
    for family, kind in warm.FAMILY_KIND.items():  # each family compiled by a kind of that family
        assert common.FAMILIES[common.KINDS[None if kind == "none" else kind]] == family


@pytest.mark.slow
def test_a_first_call_loads_its_family_compiled_apart(tmp_path):
    """On an empty cache a first call compiles its family in a child and loads it: the calling process's loop
    is a cache hit, not a compilation of its own."""
    import subprocess
    import sys

    script = ("from liesuslov.integrators.kernel.warm import run_kind; from liesuslov.integrators.kernel import loop; "
              "b = run_kind('none'); s = loop._solve_one.stats; print(b, len(s.cache_hits), len(s.cache_misses))")
    env = {k: v for k, v in os.environ.items() if k != "LIESUSLOV_KERNEL_COMPILE_HERE"}
    env["NUMBA_CACHE_DIR"] = str(tmp_path)
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=900,
                         check=False)
    assert res.returncode == 0 and res.stdout.split() == ["numba", "1", "0"], (res.stdout, res.stderr[-2000:])


def test_per_model_caches_follow_every_setting():
    """The kernel keeps its judgement of a model and the integer head per (model, setting): calls on one model
    that differ only in max_steps, adaptivity (one tableau, fixed then adaptive), chart or group part must
    each run as asked (a stale head would run the previous call's settings; each of max_steps and adaptivity
    left out of the key fails here). A stale record flag would only record steps for nothing: not visible in
    the result."""
    case = ls.cases.klebsh_tisserand(np.array([1.0, 2.0, 3.0, 4.0]), np.array([2.0, 2.5, 3.0, 1.5]))
    rng = np.random.default_rng(5)
    Om0 = case.system.constraints.project(rng.standard_normal(6))
    G0 = np.array([0.5, 0.5, 0.5, 0.5])
    run = lambda **kw: ls.integrate(case.system, Om0, (0.0, 2.0), Gamma0=G0, backend="numba", **kw)  # noqa: E731
    full = run(method="rkmk4", h=0.01)
    assert full.success and full.stats["steps"] == 200
    short = run(method="rkmk4", h=0.01, max_steps=7)
    assert short.status == -1 and "max_steps" in short.message and short.stats["steps"] == 7
    again = run(method="rkmk4", h=0.01)
    assert again.success and np.array_equal(again.Omega, full.Omega)
    assert run(method="rkmk5", h=0.01).stats["steps"] == 200  # the same tableau as rkmk45, fixed step
    adaptive = run(method="rkmk45", rtol=1e-6)
    assert adaptive.success and adaptive.stats["steps"] < 100
    dense = run(method="rkmk4", h=0.01, t_eval=[0.5, 1.0, 2.0])
    assert dense.t.shape == (3,) and np.allclose(dense.Omega[-1], full.Omega[-1], rtol=0, atol=1e-14)
    cay = run(method="rkmk4", h=0.01, chart="cayley")
    assert cay.stats["chart"] == "cayley" and 0 < np.abs(cay.Omega[-1] - full.Omega[-1]).max() < 1e-6
    recon = run(method="rkmk4", h=0.01, reconstruct=True)
    assert recon.g is not None and np.abs(recon.Omega[-1] - full.Omega[-1]).max() < 1e-12


def test_borrowed_views_are_the_owners_memory():
    """common._view: the entries arr.flat[offset : offset + prod(shape)] in C order, for a 1-D or 2-D owner and
    an int or tuple shape, written through to the owner (the group operations of the matrix kinds compute in
    such views of the kernel's flat scratch)."""
    from numba import njit

    from liesuslov.integrators.kernel.common import _borrow, _view

    @njit
    def views(flat, grid):
        A = _view(flat, 3, (2, 4))
        W = _view(flat, 1, (2, 2, 3))
        v = _view(grid, grid.shape[1], 5)  # row 1 of grid and on
        B = _borrow(grid)
        B[2, 1] = -7.0  # written into the owner
        A[1, 0] = -1.0
        return A.copy(), W.copy(), v.copy(), B.shape

    flat = np.arange(20.0)
    grid = np.arange(12.0).reshape(3, 4)
    A, W, v, shape = views(flat, grid)
    expect = np.arange(20.0)
    expect[7] = -1.0  # A[1, 0], written before the copies
    np.testing.assert_array_equal(W, expect[1:13].reshape(2, 2, 3))
    np.testing.assert_array_equal(A, expect[3:11].reshape(2, 4))
    np.testing.assert_array_equal(flat, expect)
    np.testing.assert_array_equal(v, np.arange(4.0, 9.0))
    assert shape == (3, 4) and grid[2, 1] == -7.0


def test_borrowed_scratch_keeps_its_owners():
    """The loop borrows its scratch (no reference counting in the step): every array it allocates before the loop
    and then borrows must be held in ``owners``, handed to ``_keepalive`` at the end of the call — numba releases
    a variable after its last use, so an owner left out would be freed under its view (silently wrong numbers)."""
    import ast
    import inspect
    import textwrap

    from liesuslov.integrators.kernel import loop

    fn = ast.parse(textwrap.dedent(inspect.getsource(loop._solve_one.py_func))).body[0]
    allocated, borrowed, owners = set(), set(), None
    for node in fn.body:  # the function's top level: the scratch, before the per-trajectory loop
        if not isinstance(node, ast.Assign):
            continue
        if isinstance(node.targets[0], ast.Name) and node.targets[0].id == "owners":
            owners = {e.id for e in node.value.elts}
            continue
        targets = node.targets[0].elts if isinstance(node.targets[0], ast.Tuple) else node.targets
        values = node.value.elts if isinstance(node.value, ast.Tuple) else [node.value]
        for target, value in zip(targets, values, strict=False):
            if not isinstance(target, ast.Name):
                continue
            call = ast.unparse(value)
            if call.startswith("np.zeros("):
                allocated.add(target.id)
            elif call == f"_borrow({target.id})":
                borrowed.add(target.id)
    params = {a.arg for a in fn.args.args}
    record = {"t_rec", "xi_rec", "G_rec"}  # the step record: reallocated as it grows, so never borrowed
    assert allocated and borrowed and owners is not None and record <= allocated
    assert not record & borrowed
    allocated -= record
    assert borrowed - params == allocated, "every scratch array is borrowed"
    assert allocated <= owners, f"scratch borrowed without its owner kept: {sorted(allocated - owners)}"
    tail = [ast.unparse(s) for s in fn.body[-2:]]
    assert tail[0] == "_keepalive(owners)" and tail[1].startswith("return"), tail


def test_batch_threads_are_kept_shared_and_made_again_after_a_fork():
    """The batch's threads (wrapper._batch_pool) are made once per process and kept; calls from several user
    threads share them, each getting its own numbers bit for bit; a forked child, which inherits the pool
    object but not its threads, makes its own (the old one would take the chunks and never run them)."""
    import warnings
    from concurrent.futures import ThreadPoolExecutor

    from liesuslov.integrators.kernel import wrapper

    name, model, kind = SCENES[0]
    rng = np.random.default_rng(7)
    B = 24
    xi = rng.normal(size=(B, model.k))
    G = rotations(rng, B, model.n).reshape(B, -1)
    p = make_problem(model, xi, G0=G, gamma=unit(rng, B, model.n), mode="g", kind=kind, method="rkmk45",
                     t_span=(0.0, 2.0), t_eval=[0.5, 2.0], rtol=1e-9, atol=1e-11)
    ref = kernel.solve(p)
    pool = wrapper._batch_pool()
    assert wrapper._batch_pool() is pool
    with ThreadPoolExecutor(4) as users:
        outs = list(users.map(lambda _: kernel.solve(p), range(8)))
    for out in outs:
        np.testing.assert_array_equal(out.xi, ref.xi)
        np.testing.assert_array_equal(out.G, ref.G)
        np.testing.assert_array_equal(out.nfev, ref.nfev)
    assert wrapper._batch_pool() is pool
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # (fork with threads running, Python >= 3.12)
        pid = os.fork()
    if pid == 0:  # the child: a new pool first (else solve would wait forever on the inherited one)
        ok = False
        try:
            ok = wrapper._batch_pool() is not pool and bool(np.array_equal(kernel.solve(p).xi, ref.xi))
        finally:
            os._exit(0 if ok else 1)
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0
