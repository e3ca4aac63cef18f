"""The per-trajectory time loop: batch = alone, isolated failures, dense output, events, t_eval, robustness.

References are independent of the library: scipy's solve_ivp on the embedded ODE (xi, g) at tight
tolerance, and the Euler top's closed form in Jacobi elliptic functions (``analytic.EulerTop``, checked
against scipy in its own tests).
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from scipy.optimize import brentq

import liesuslov as ls
from liesuslov.analytic.euler_top import EulerTop
from liesuslov.integrators import LinearEvent, coordinate_plane, gamma_crossing, return_plane

from .references import embedded_reference

BACKENDS = ["numpy", "auto"]

I3 = np.diag([1.0, 2.0, 3.0])
J3 = np.array([5.0, 4.0, 3.0])  # so(3) body moments of the mass tensor I3: J_i = I_j + I_k


def free_body():
    return ls.SuslovSystem(ls.Inertia.from_mass_tensor(I3), constraints="none")


def kt_body():
    J = ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0, 4.0]))
    system = ls.SuslovSystem(J, potential=ls.QuadraticPotential([4.0, 3.0, 2.0, 1.0]))
    Omega0 = np.zeros((4, 4))
    Omega0[:3, 3] = [0.1, 0.2, 0.3]
    Omega0[3, :3] = -Omega0[:3, 3]
    return system, Omega0, np.array([0.0, 0.0, 0.6, 0.8])


# ---------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("method,kw", [("rkmk45", {"rtol": 1e-8}), ("rkmk853", {"rtol": 1e-9}),
                                       ("rkmk4", {"h": 0.05})])
def test_batch_equals_alone_bitwise(backend, method, kw):
    system, Omega0, Gamma0 = kt_body()
    scales = np.array([1.0, 3.0, 0.2, 7.0])
    O = Omega0 * scales[:, None, None]
    t_eval = np.linspace(0.0, 6.0, 7)
    batch = ls.integrate(system, O, (0.0, 6.0), Gamma0=Gamma0, reconstruct=True, method=method, t_eval=t_eval,
                         backend=backend, **kw)
    assert batch.success
    steps = batch.stats["trajectory_steps"]
    if method != "rkmk4":
        assert len(set(steps.tolist())) > 1  # the trajectories really took their own steps
    for b in (3, 0, 2):
        alone = ls.integrate(system, O[b], (0.0, 6.0), Gamma0=Gamma0, reconstruct=True, method=method,
                             t_eval=t_eval, backend=backend, **kw)
        assert np.array_equal(alone.g, batch.g[:, b])
        assert np.array_equal(alone.omega, batch.omega[:, b])
        assert alone.stats["steps"] == steps[b]
    chunk = ls.integrate(system, O[1:3], (0.0, 6.0), Gamma0=Gamma0, reconstruct=True, method=method, t_eval=t_eval,
                         backend=backend, **kw)
    assert np.array_equal(chunk.g, batch.g[:, 1:3])


@pytest.mark.parametrize("backend", BACKENDS)
def test_batch_equals_alone_bitwise_for_any_constraint_subspace(backend):
    """A random D (a dense basis) and a mass tensor that is not diagonal: the maps xi <-> omega and the
    numpy field take products of a batch with matrices, which BLAS sums differently by a row's position in
    the batch (every trajectory differed from itself alone in the last bits); they are row-wise now."""
    rng = np.random.default_rng(5)
    alg = ls.so(5)
    D = ls.Subspace.annihilator(alg, rng.normal(size=(3, alg.dim)))
    I5 = np.diag([1.0, 2.0, 3.0, 4.0, 5.0]) + 0.1
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I5), constraints=D,
                             potential=ls.LinearPotential([0.3, 0.1, 1.0, 0.0, 0.2]))
    B = 200
    O = 0.3 * rng.normal(size=(B, D.dim)) @ D.basis
    G = rng.normal(size=(B, 5))
    G /= np.linalg.norm(G, axis=1, keepdims=True)
    kw = {"method": "rkmk45", "reconstruct": True, "backend": backend}
    batch = ls.integrate(system, O, (0.0, 2.0), Gamma0=G, **kw)
    for b in (0, 37, 101, 199):
        alone = ls.integrate(system, O[b], (0.0, 2.0), Gamma0=G[b], t_eval=[0.0, 2.0], **kw)
        assert np.array_equal(alone.omega, batch.omega[:, b]) and np.array_equal(alone.g, batch.g[:, b])


@pytest.mark.parametrize("backend", BACKENDS)
def test_failing_trajectory_is_isolated(backend):
    """A step beyond the exponential's domain (|h Omega| > pi) fails that trajectory only, with its time."""
    system = free_body()
    w = np.array([[0.3, 1.0, 0.4], [300.0, 1000.0, 400.0], [0.1, 0.2, -0.3]])
    sol = ls.integrate(system, w, (0.0, 2.0), reconstruct=True, method="rkmk4", h=0.01,
                       t_eval=np.linspace(0, 2, 5), backend=backend)
    assert sol.status.tolist() == [0, -1, 0]
    assert not sol.success
    assert sol.stats["t_stop"][1] == 0.0
    assert np.all(np.isnan(sol.g[1:, 1])) and np.all(np.isfinite(sol.g[:, [0, 2]]))
    for b in (0, 2):
        alone = ls.integrate(system, w[b], (0.0, 2.0), reconstruct=True, method="rkmk4", h=0.01,
                             t_eval=np.linspace(0, 2, 5), backend=backend)
        assert np.array_equal(alone.g, sol.g[:, b])
    assert "t = 0" in sol.message


def test_nonfinite_field_at_t0_fails_at_once():
    pot = ls.Potential(lambda G: np.full(G.shape[:-1], np.nan), lambda G: np.full(G.shape, np.nan))
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I3), potential=pot)
    sol = ls.integrate(system, [0.0, 0.0, 0.5], (0.0, 1.0), Gamma0=[0.0, 0.0, 1.0], method="rkmk45")
    assert sol.status == -1 and sol.stats["t_stop"] == 0.0 and sol.stats["steps"] == 0
    assert "non-finite" in sol.message
    # the initial state is reported (NaN only after the failure time): one trajectory, and a batch with t_eval
    assert sol.t.tolist() == [0.0] and sol.omega[0].tolist() == [0.0, 0.0, 0.5]
    batch = ls.integrate(system, [[0.0, 0.0, 0.5], [0.0, 0.0, 0.7]], (0.0, 1.0), Gamma0=[0.0, 0.0, 1.0],
                         method="rkmk45", t_eval=[0.0, 0.5, 1.0])
    assert batch.status.tolist() == [-1, -1] and np.all(np.isfinite(batch.omega[0]))
    assert np.all(np.isnan(batch.omega[1:]))


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_fixed_step_below_the_resolution_of_t_fails_at_once(backend):
    """h below ten ulps of t in t_span: the grid t0 + i h cannot be represented (the compiled loop took one step
    over the whole span for h = 1e-19 — ceil(span / h) overflowed — and reported success); both backends fail at
    t0 with the reason, at once (numpy ran 10^7 steps for h = 1e-300)."""
    system = free_body()
    for span, h in (((0.0, 3.0), 1e-19), ((0.0, 2.0), 5e-324), ((1e16, 1e16 + 8.0), 0.05), ((0.0, 1e300), 0.05)):
        sol = ls.integrate(system, [0.3, -0.5, 0.7], span, method="rkmk4", h=h, reconstruct=True, backend=backend)
        assert sol.status == -1 and sol.stats["t_stop"] == span[0] and sol.stats["steps"] == 0
        assert "ten ulps" in sol.message
    # a huge max_steps is no limit (the compiled loop counts in int64)
    sol = ls.integrate(system, [0.3, -0.5, 0.7], (0.0, 2.0), method="rkmk4", h=0.1, max_steps=2**70, backend=backend)
    assert sol.success and sol.stats["steps"] == 20


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_first_step_whose_norms_overflow_fails_at_once(backend):
    """A field far beyond atol (|f| / atol overflows the norms of the starting step): the estimate was NaN, which
    numpy rejected ~10^7 times (a hang) and the kernel called a non-finite state; now a step of 0, failed at once
    by the step-size floor, on both backends."""
    system, Omega0, Gamma0 = kt_body()
    sol = ls.integrate(system, Omega0, (0.0, 2.0), Gamma0=Gamma0, method="rkmk45", atol=1e-300, backend=backend)
    assert sol.status == -1 and sol.stats["t_stop"] == 0.0 and sol.stats["rejected"] == 0
    assert "underflow" in sol.message
    ok = ls.integrate(system, Omega0, (0.0, 2.0), Gamma0=Gamma0, method="rkmk45", atol=1e-300, first_step=1e-3,
                      backend=backend)
    assert ok.success


def test_bad_initial_data_is_named():
    system = free_body()
    with pytest.raises(ValueError, match="Omega0 must be a rectangular array"):
        ls.integrate(system, [[0.1, 0.2, 0.3], [0.3]], (0.0, 1.0), method="rkmk45")
    with pytest.raises(TypeError, match="Omega0 must be a real numeric array, got strings"):
        ls.integrate(system, ["0.3", "-0.5", "0.7"], (0.0, 1.0), method="rkmk45")
    with pytest.raises(TypeError, match="Omega0 must be a real numeric array, got booleans"):
        ls.integrate(system, np.array([True, False, True]), (0.0, 1.0), method="rkmk45")
    # hidden by numpy in a float array ([True, 1.0] is float64) or an object one: found in what was given
    for mixed, what in (([True, 1.0, 0.4], "booleans"), ([[0.1, 0.2, 0.3], [0.3, np.True_, 0.1]], "booleans"),
                        (np.array([0.1, "0.3", 0.2], dtype=object), "strings"), ([0.1, 0.2, 0.3 + 0j], "complex")):
        with pytest.raises(TypeError, match=f"Omega0 must be .*{what}"):
            ls.integrate(system, mixed, (0.0, 1.0), method="rkmk45")
    with pytest.raises(TypeError, match="Gamma0 must be a real numeric array, got booleans"):
        ls.integrate(ls.SuslovSystem(ls.Inertia.from_principal_moments([1.0, 2.0, 3.0]),
                                     potential=ls.LinearPotential([0.0, 0.0, 1.0]), constraints="none"),
                     [0.1, 0.2, 0.0], (0.0, 1.0), Gamma0=[0.0, False, 1.0], method="rkmk45")
    se3 = ls.SuslovSystem(ls.Inertia(ls.se(3), np.eye(6)), constraints="none")
    g0 = np.eye(4)
    g0[:3, 3] = [1.0, 2.0, 3.0]
    assert ls.integrate(se3, 0.1 * np.ones(6), (0.0, 1.0), method="rkmk4", h=0.1, reconstruct=True, g0=g0).success
    for bad in (2.0 * np.eye(4), np.diag([1.0, 1.0, -1.0, 1.0]), np.zeros((4, 4))):
        with pytest.raises(ValueError, match=r"g0.* must be in S[EO]\(3\)"):
            ls.integrate(se3, 0.1 * np.ones(6), (0.0, 1.0), method="rkmk4", h=0.1, reconstruct=True, g0=bad)


def test_batch_without_t_eval_reports_the_two_ends():
    system, Omega0, Gamma0 = kt_body()
    sol = ls.integrate(system, np.stack([Omega0, 2 * Omega0]), (0.0, 3.0), Gamma0=Gamma0, method="rkmk45")
    assert sol.t.tolist() == [0.0, 3.0] and sol.Gamma.shape == (2, 2, 4)
    one = ls.integrate(system, Omega0, (0.0, 3.0), Gamma0=Gamma0, method="rkmk45")
    assert one.t.size == one.stats["steps"] + 1  # a single trajectory reports every step


@pytest.mark.parametrize("backend", BACKENDS)
def test_t_eval_does_not_change_the_steps(backend):
    system, Omega0, Gamma0 = kt_body()
    kw = dict(Gamma0=Gamma0, reconstruct=True, method="rkmk45", rtol=1e-8, backend=backend)
    end = ls.integrate(system, Omega0, (0.0, 20.0), t_eval=[20.0], **kw)
    many = ls.integrate(system, Omega0, (0.0, 20.0), t_eval=np.linspace(0.0, 20.0, 501), **kw)
    assert many.stats["steps"] == end.stats["steps"]
    assert many.stats["nfev"] <= 1.2 * end.stats["nfev"]  # dopri5's extension is free (FSAL)
    assert np.array_equal(many.g[-1], end.g[-1])
    om_ref, g_ref = embedded_reference(system, ls.so(4).vee(Omega0), 20.0, many.t, Gamma0)
    assert np.max(np.abs(many.g - g_ref)) < 1e-5


@pytest.mark.parametrize("backend", BACKENDS)
def test_output_times_leave_the_trajectory_bitwise_unchanged(backend):
    """rkmk853 evaluates the field at a step's end only for its extension, and the next step reuses it: it
    read the vertical carried by the chart (phi(-Theta) g^T gamma) where a step without outputs evaluates
    g1^T gamma — output times changed the last bits of everything after them (up to 6e-12 at t = 60)."""
    system, Omega0, Gamma0 = kt_body()
    kw = dict(Gamma0=Gamma0, reconstruct=True, method="rkmk853", rtol=1e-9, backend=backend)
    end = ls.integrate(system, Omega0, (0.0, 30.0), t_eval=[30.0], **kw)
    many = ls.integrate(system, Omega0, (0.0, 30.0), t_eval=np.linspace(0.0, 30.0, 301), **kw)
    assert many.stats["steps"] == end.stats["steps"]
    assert np.array_equal(many.g[-1], end.g[-1]) and np.array_equal(many.omega[-1], end.omega[-1])
    dense = ls.integrate(system, Omega0, (0.0, 30.0), dense_output=True, **kw)
    assert np.array_equal(dense.at([29.5]).g[0], dense.at(np.linspace(0.0, 29.5, 60)).g[-1])


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("method", ["rkmk4", "rkmk45"])
def test_output_at_the_step_times_is_the_run_of_every_step(backend, method):
    """t_eval = the steps of a run without it gives that run, bit for bit — also at the steps after which g is
    re-orthonormalised (every 64): those reported the re-projected g without t_eval, the step's own with it."""
    system, Omega0, Gamma0 = kt_body()
    kw = dict(Gamma0=Gamma0, reconstruct=True, method=method, backend=backend,
              **({"h": 0.05} if method == "rkmk4" else {"rtol": 1e-10}))
    t_span = (0.0, 10.0 if method == "rkmk4" else 30.0)
    steps = ls.integrate(system, Omega0, t_span, **kw)
    assert steps.t.size > 130
    at_steps = ls.integrate(system, Omega0, t_span, t_eval=steps.t, **kw)
    assert np.array_equal(at_steps.g, steps.g) and np.array_equal(at_steps.omega, steps.omega)
    pair = ls.integrate(system, np.stack([Omega0, Omega0]), t_span, t_eval=steps.t, **kw)
    assert np.array_equal(pair.g[:, 1], steps.g)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_return_plane_through_the_start_has_no_crossing_at_t0(backend):
    """The plane's value at t0 is its offset's rounding (+-1e-16): 68 (compiled) and 91 (numpy) of 200
    trajectories 'returned' at t ~ 1e-16 — a different set for each solver. A linear event within its rounding
    of 0 at t0 now starts on its surface."""
    system, _, _ = kt_body()
    rng = np.random.default_rng(3)
    x = rng.normal(size=(200, 3)) * 0.8
    Gamma0 = rng.normal(size=(200, 4))
    Gamma0 /= np.linalg.norm(Gamma0, axis=-1, keepdims=True)
    Omega0 = ls.so(4).hat(x @ system.constraints.basis)
    plane = return_plane(system, Omega0, Gamma0, terminal=True, direction=1)
    sol = ls.integrate(system, Omega0, (0.0, 2.0), Gamma0=Gamma0, method="rkmk45", events=plane, backend=backend)
    assert np.all(sol.events[0].t > 0.1)          # the real returns only
    assert np.count_nonzero(sol.status == 1) == sol.events[0].t.size


@pytest.mark.parametrize("backend", BACKENDS)
def test_terminal_count_stops_at_that_crossing(backend):
    """scipy's integer terminal: the N-th crossing stops the trajectory (a LinearEvent on the compiled path,
    a callable on numpy); 0 never stops; the crossings are the Euler top's zeros of w_2."""
    system = free_body()
    w0 = np.array([[0.3, 1.0, 0.4], [0.5, 0.6, -0.4]])

    def w2(t, Omega, Gamma, g):
        return Omega[..., 0, 2]
    w2.terminal = 3
    kw = dict(reconstruct=True, method="rkmk853", rtol=1e-11, atol=1e-13, backend=backend)
    for ev in (coordinate_plane("omega", 1, dim=3, terminal=3), w2):
        sol = ls.integrate(system, ls.hat3(w0), (0.0, 200.0), events=ev, **kw)
        assert sol.status.tolist() == [1, 1]
        rec = sol.events[0]
        assert rec.index.tolist() == [0, 0, 0, 1, 1, 1]
        for b in range(2):
            tb = rec.t[rec.index == b]
            assert sol.stats["t_stop"][b] == tb[-1] and np.all(np.diff(tb) > 0)
            top = EulerTop(J3, w0[b])
            assert max(abs(top.state(tc)[1]) for tc in tb) < 1e-8
    never = ls.integrate(system, ls.hat3(w0), (0.0, 200.0), events=coordinate_plane("omega", 1, dim=3, terminal=0),
                         **kw)
    assert never.status.tolist() == [0, 0] and len(never.events[0]) > 6
    for bad, exc in ((-1, ValueError), (1.5, TypeError), ("yes", TypeError)):
        with pytest.raises(exc, match="terminal"):
            coordinate_plane("omega", 1, dim=3, terminal=bad)
        w2.terminal = bad
        with pytest.raises(exc, match="event.terminal"):
            ls.integrate(system, ls.hat3(w0), (0.0, 1.0), events=w2, **kw)


@pytest.mark.parametrize("backend", BACKENDS)
def test_output_times_on_step_ends_cost_no_extension(backend):
    # rkmk8 (fixed step) has extra stages for its extension; an output time that is a step's end is that
    # step's own state, so t_eval on the step grid costs the evaluations of the bare run, and gives its states
    system, Omega0, Gamma0 = kt_body()
    kw = dict(Gamma0=Gamma0, reconstruct=True, method="rkmk8", h=0.25, backend=backend)
    bare = ls.integrate(system, Omega0, (0.0, 2.0), **kw)  # records every step
    on_grid = ls.integrate(system, Omega0, (0.0, 2.0), t_eval=bare.t, **kw)
    at_end = ls.integrate(system, Omega0, (0.0, 2.0), t_eval=[2.0], **kw)
    assert on_grid.stats["nfev"] == bare.stats["nfev"] == at_end.stats["nfev"]
    assert np.array_equal(on_grid.g, bare.g) and np.array_equal(on_grid.omega, bare.omega)
    # one output time inside a step needs the extension there: more evaluations
    inside = ls.integrate(system, Omega0, (0.0, 2.0), t_eval=[0.3, 2.0], **kw)
    assert inside.stats["nfev"] > bare.stats["nfev"]


@pytest.mark.parametrize("method,order", [("rkmk4", 4), ("rkmk5", 5), ("rkmk8", 7)])
def test_dense_output_order_and_structure(method, order):
    """Interpolated states between the steps converge like h^min(p, p*+1), on the group to rounding."""
    system = free_body()
    w0 = np.array([0.3, 1.0, 0.4])
    T = 2.0
    hs = np.array([0.2, 0.1, 0.05]) if order < 7 else np.array([1.0, 0.7, 0.5, 0.35])
    errs = []
    for h in hs:
        t_mid = np.arange(0.5, T / h - 0.49) * h  # the middle of every step
        sol = ls.integrate(system, w0, (0.0, T), reconstruct=True, method=method, h=h, t_eval=t_mid,
                           backend="numpy")
        _, g_ref = embedded_reference(system, w0, T, t_mid)
        errs.append(np.max(np.abs(sol.g - g_ref)))
        assert np.max(np.abs(np.swapaxes(sol.g, -1, -2) @ sol.g - np.eye(3))) < 1e-14
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert slope > order - 0.4, (errs, slope)


@pytest.mark.parametrize("backend", BACKENDS)
def test_at_gives_exact_structure_and_rejects_outside(backend):
    system, Omega0, Gamma0 = kt_body()
    sol = ls.integrate(system, np.stack([Omega0, 1.5 * Omega0]), (0.0, 10.0), Gamma0=Gamma0, reconstruct=True,
                       method="rkmk853", rtol=1e-10, atol=1e-12, dense_output=True, backend=backend)
    ts = np.array([7.3, 0.1, 3.3333])
    s = sol.at(ts)
    assert s.t.tolist() == ts.tolist() and s.g.shape == (3, 2, 4, 4)
    assert np.max(np.abs(np.swapaxes(s.g, -1, -2) @ s.g - np.eye(4))) < 1e-13
    assert np.max(np.abs(np.linalg.norm(s.Gamma, axis=-1) - 1.0)) < 1e-13
    _, g_ref = embedded_reference(system, ls.so(4).vee(1.5 * Omega0), 10.0, np.sort(ts), Gamma0)
    assert np.max(np.abs(s.g[[1, 2, 0], 1] - g_ref)) < 1e-8
    with pytest.raises(ValueError, match="t_span"):
        sol.at([11.0])
    with pytest.raises(ValueError, match="t is empty"):
        sol.at([])
    plain = ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=Gamma0, method="rkmk45")
    with pytest.raises(ValueError, match="dense_output"):
        plain.at([0.5])
    with pytest.raises(ValueError, match="1-D array of times"):
        sol.at(ts.reshape(3, 1))
    s.t[0] = -1.0  # the returned t is the solution's own
    assert ts[0] == 7.3
    # a pickled Solution keeps its dense output when its problem pickles: the same numbers, bitwise
    copied = pickle.loads(pickle.dumps(sol))
    assert np.array_equal(copied.g, sol.g)
    again = copied.at(ts)
    assert np.array_equal(again.g, sol.at(ts).g) and np.array_equal(again.omega, sol.at(ts).omega)
    # ... and says why not when it does not (a lambda event)
    lam = ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=Gamma0, method="rkmk45", dense_output=True,
                       events=lambda t, O, G, g: G[..., 0] - 0.5)
    with pytest.raises(ValueError, match="pickled or copied while its problem does not pickle"):
        pickle.loads(pickle.dumps(lam)).at([0.5])


def test_at_does_not_depend_on_the_callers_arrays_afterwards():
    """The solution owns its initial data: changing g0 after integrate changed what at() replayed (an audit:
    O(1) in omega)."""
    system, Omega0, Gamma0 = kt_body()
    R = np.linalg.qr(np.random.default_rng(3).normal(size=(4, 4)))[0]
    R[:, 0] *= np.sign(np.linalg.det(R))
    g0 = R.copy()
    sol = ls.integrate(system, Omega0, (0.0, 2.0), Gamma0=Gamma0, g0=g0, reconstruct=True, method="rkmk45",
                       dense_output=True)
    before = sol.at([1.0])
    g0[:] = np.eye(4)
    after = sol.at([1.0])
    assert np.array_equal(before.omega, after.omega) and np.array_equal(before.g, after.g)


@pytest.mark.parametrize("backend", BACKENDS)
def test_sol_t_is_not_the_callers_t_eval(backend):
    """On numpy, sol.t was the caller's t_eval array itself: writing one wrote the other (an audit)."""
    system, Omega0, Gamma0 = kt_body()
    te = np.linspace(0.0, 1.0, 5)
    sol = ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=Gamma0, h=0.05, t_eval=te, backend=backend)
    assert not np.shares_memory(sol.t, te)
    te[:] = -1.0
    assert np.array_equal(sol.t, np.linspace(0.0, 1.0, 5))


@pytest.mark.parametrize("backend", BACKENDS)
def test_g0_near_the_group_is_moved_onto_it(backend):
    """g0 within the 1e-8 tolerance but off SO(4) (or SE(3)'s rotation block) starts on the group: the structure
    is exact from t0 on, not 1e-9 off at every time (an audit)."""
    system, Omega0, Gamma0 = kt_body()
    R = np.linalg.qr(np.random.default_rng(4).normal(size=(4, 4)))[0]
    R[:, 0] *= np.sign(np.linalg.det(R))
    sol = ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=Gamma0, g0=R + 1e-9, reconstruct=True, method="rkmk45",
                       t_eval=[0.0, 0.5, 1.0], backend=backend)
    assert np.max(np.abs(np.swapaxes(sol.g, -1, -2) @ sol.g - np.eye(4))) < 1e-14
    assert np.max(np.abs(np.linalg.norm(sol.Gamma, axis=-1) - 1.0)) < 1e-14
    assert np.max(np.abs(sol.g[0] - R)) < 1e-8
    se3 = ls.SuslovSystem(ls.Inertia(ls.se(3), np.eye(6)), constraints="none")
    h0 = np.eye(4)
    Q = np.linalg.qr(np.ones((3, 3)) + np.eye(3))[0]
    h0[:3, :3] = Q * np.sign(np.linalg.det(Q)) + 1e-9  # (-Q has the other determinant in 3 dimensions)
    h0[:3, 3] = [1.0, 2.0, 3.0]
    se = ls.integrate(se3, 0.1 * np.ones(6), (0.0, 1.0), method="rkmk4", h=0.1, reconstruct=True, g0=h0,
                      t_eval=[0.0, 1.0], backend=backend)
    rot = se.g[..., :3, :3]
    assert np.max(np.abs(np.swapaxes(rot, -1, -2) @ rot - np.eye(3))) < 1e-14
    assert np.array_equal(se.g[0, :3, 3], h0[:3, 3])


# ---------------------------------------------------------------------------------------------------------
def _euler_zeros(top, component, T):
    """Zeros of the closed form's omega component in (0, T) by brentq on a fine grid (independent reference)."""
    ts = np.linspace(0.0, T, 4001)
    w = top.state(ts)[:, component]
    out = []
    for a, b, fa, fb in zip(ts[:-1], ts[1:], w[:-1], w[1:], strict=True):
        if fa * fb < 0:
            out.append(brentq(lambda t: top.state(t)[component], a, b, xtol=1e-15))
    return np.array(out)


@pytest.mark.parametrize("backend", BACKENDS)
def test_events_against_the_euler_top_closed_form(backend):
    system = free_body()
    w0 = np.array([0.3, 1.0, 0.4])
    top = EulerTop(J3, w0)
    assert np.allclose(top.state(0.0), w0)
    T = 30.0
    zeros = _euler_zeros(top, 1, T)
    w0 = ls.hat3(w0)  # the vector w in so(3) (its coordinate 1 is w_2: Omega_02)
    both = coordinate_plane("omega", 1, dim=3)
    up = coordinate_plane("omega", 1, dim=3, direction=1)
    sol = ls.integrate(system, w0, (0.0, T), method="rkmk853", rtol=1e-12, atol=1e-14, events=[both, up],
                       backend=backend)
    rec, rec_up = sol.events
    assert rec.t.size == zeros.size and np.max(np.abs(rec.t - zeros)) < 1e-9
    assert np.max(np.abs(rec.omega[:, 1])) < 1e-12  # located to near rounding on the extension
    slopes = np.array([top.state(t + 1e-6)[1] - top.state(t - 1e-6)[1] for t in zeros])
    assert np.allclose(rec_up.t, zeros[slopes > 0], atol=1e-9)


@pytest.mark.parametrize("backend", BACKENDS)
def test_terminal_event_stops_each_trajectory(backend):
    system = free_body()
    w0 = np.array([[0.3, 1.0, 0.4], [0.5, 0.6, -0.4]])
    ev = coordinate_plane("omega", 1, dim=3, terminal=True, direction=-1)
    t_eval = np.linspace(0, 20, 41)
    sol = ls.integrate(system, ls.hat3(w0), (0.0, 20.0), reconstruct=True, method="rkmk45", rtol=1e-10, atol=1e-12,
                       events=ev, t_eval=t_eval, backend=backend)
    assert sol.status.tolist() == [1, 1] and sol.success
    rec = sol.events[0]
    assert rec.index.tolist() == [0, 1]
    for b in range(2):
        tc = rec.t[b]
        assert sol.stats["t_stop"][b] == tc
        assert np.all(np.isnan(sol.omega[t_eval > tc, b])) and np.all(np.isfinite(sol.omega[t_eval <= tc, b]))
        top = EulerTop(J3, w0[b])
        assert abs(top.state(tc)[1]) < 1e-8


def test_gamma_crossing_and_return_plane_kt():
    """Klebsh–Tisserand: Gamma_3 = 0 crossings have Gamma_3 = 0 and unit Gamma; the return plane's
    first crossing after t0 is not t0 and returns the reduced state to its plane."""
    system, Omega0, Gamma0 = kt_body()
    sol = ls.integrate(system, Omega0, (0.0, 40.0), Gamma0=Gamma0, method="rkmk853", rtol=1e-11, atol=1e-13,
                       events=[gamma_crossing(4, 2), return_plane(system, Omega0, Gamma0)])
    rec, ret = sol.events
    assert rec.t.size > 0 and np.max(np.abs(rec.Gamma[:, 2])) < 1e-12
    assert np.max(np.abs(np.linalg.norm(rec.Gamma, axis=-1) - 1.0)) < 1e-13
    assert ret.t.size > 0 and ret.t[0] > 0.0
    E0 = system.energy(Omega0, Gamma0)
    assert np.max(np.abs(system.energy(ret.Omega, ret.Gamma) - E0)) < 1e-9


def test_user_callable_event_runs_on_numpy():
    system = free_body()

    def ev(t, Omega, Gamma, g):
        return Omega[..., 2, 0] - 0.25  # omega_2 in so(3)'s hat convention = Omega[2, 0]

    sol = ls.integrate(system, [0.3, 1.0, 0.4], (0.0, 10.0), method="rkmk45", rtol=1e-10, atol=1e-12, events=ev)
    assert sol.stats["backend"] == "numpy"
    rec = sol.events[0]
    assert rec.t.size > 0 and np.allclose(rec.Omega[:, 2, 0], 0.25, atol=1e-10)


def test_user_event_sees_the_batch_axes_and_may_use_per_trajectory_parameters():
    """A user callable is called with the batch axes leading (API.md): t batch-shaped, Omega (..., n, n),
    Gamma (..., n); per-trajectory parameters of the batch's shape then work, and a batch gives each
    trajectory the crossings it has alone."""
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I3), potential=ls.LinearPotential([0.0, 0.0, 1.0]))
    O = np.array([[[0.0, 0.5, 0.2], [0.0, -0.3, 0.4]], [[0.0, 0.1, 0.9], [0.0, 0.2, -0.6]]])  # batch (2, 2)
    Gamma0 = np.array([0.6, 0.0, 0.8])
    T = np.array([[1.0, 2.0], [3.0, 4.5]])
    shapes = set()

    def clock(t, Omega, Gamma, g):
        shapes.add((np.shape(t), Omega.shape, Gamma.shape, g))
        return t - T

    sol = ls.integrate(system, O, (0.0, 5.0), Gamma0=Gamma0, method="rkmk45", events=clock)
    assert shapes == {((2, 2), (2, 2, 3, 3), (2, 2, 3), None)}
    rec = sol.events[0]
    assert rec.index.tolist() == [0, 1, 2, 3]
    assert np.allclose(rec.t, T.ravel(), rtol=0, atol=1e-12)

    def level(t, Omega, Gamma, g):
        return Gamma[..., 2] - 0.5

    batch = ls.integrate(system, O, (0.0, 20.0), Gamma0=Gamma0, method="rkmk45", events=level).events[0]
    for b in range(4):
        alone = ls.integrate(system, O.reshape(4, 3)[b], (0.0, 20.0), Gamma0=Gamma0, method="rkmk45",
                             events=level).events[0]
        assert alone.t.size > 0 and np.array_equal(alone.t, batch.t[batch.index == b])
    with pytest.raises(ValueError, match=r"events\[0\].*shape \(2, 2\)"):
        ls.integrate(system, O, (0.0, 5.0), Gamma0=Gamma0, method="rkmk45", events=lambda t, O_, G, g: np.zeros(3))


def test_user_event_on_se2_sees_omega_coordinates_and_g():
    """On algebras other than so(n) an event gets Omega as coordinates (..., d) (there is no skew matrix;
    sol.Omega is None too) and g in SE(2) (..., 3, 3): a pure translation at speed v reaches x = 1/2 at 1/(2v)."""
    se2 = ls.SuslovSystem(ls.Inertia(ls.se(2), np.eye(3)), constraints="none")
    shapes = set()

    def x_half(t, Omega, Gamma, g):
        shapes.add((np.shape(t), Omega.shape, Gamma, g.shape))
        return g[..., 0, 2] - 0.5

    sol = ls.integrate(se2, np.array([[0.0, 1.0, 0.0], [0.0, 0.5, 0.0]]), (0.0, 3.0), method="rkmk45",
                       reconstruct=True, events=x_half)
    assert shapes == {((2,), (2, 3), None, (2, 3, 3))} and sol.Omega is None
    rec = sol.events[0]
    assert rec.index.tolist() == [0, 1] and np.allclose(rec.t, [0.5, 1.0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_root_on_a_step_end_is_one_crossing(backend):
    """A value that reaches exactly 0 at a step's end is one crossing (scipy's rule counts it again when
    the next step leaves 0); a trajectory that starts on the surface has not crossed it."""
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I3), potential=ls.LinearPotential([0.0, 0.0, 1.0]))
    O, Gamma0 = np.array([0.0, 0.5, 0.2]), np.array([0.6, 0.0, 0.8])
    run = {"method": "rkmk4", "h": 0.1, "Gamma0": Gamma0, "backend": backend}
    steps = ls.integrate(system, O, (0.0, 2.0), **run)
    level = steps.Gamma[5, 2]  # the value at t = 0.5, a step's end
    ev = LinearEvent(Gamma=[0.0, 0.0, 1.0], offset=level)
    rec = ls.integrate(system, O, (0.0, 2.0), events=ev, **run).events[0]
    assert rec.t[0] == 0.5 and np.count_nonzero(rec.t == 0.5) == 1
    crossings = np.flatnonzero(np.diff(np.sign(steps.Gamma[:, 2] - level)))  # sign changes between steps
    assert rec.t.size == crossings.size - 1  # the zero at 0.5 makes two sign changes of one crossing
    start = ls.integrate(system, O, (0.0, 2.0), events=LinearEvent(Gamma=[0.0, 0.0, 1.0], offset=0.8), **run)
    assert 0.0 not in start.events[0].t


@pytest.mark.parametrize("backend", BACKENDS)
def test_every_output_after_a_stop_is_nan(backend):
    """Also the components of omega outside D (0 while it runs), Omega's diagonal and the dense output."""
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I3), potential=ls.LinearPotential([0.0, 0.0, 1.0]))
    O = np.array([[0.0, 0.5, 0.2], [0.0, 30.0, 40.0]])
    sol = ls.integrate(system, O, (0.0, 5.0), Gamma0=[0.6, 0.0, 0.8], method="rkmk45", max_steps=60,
                       dense_output=True, backend=backend)
    assert sol.status.tolist() == [0, -1]
    assert np.all(np.isnan(sol.omega[-1, 1])) and np.all(np.isnan(sol.Omega[-1, 1]))
    assert np.all(np.isfinite(sol.omega[:, 0])) and np.all(np.isfinite(sol.Omega[:, 0]))
    late = sol.at([5.0])
    assert np.all(np.isnan(late.omega[0, 1])) and np.all(np.isnan(late.Omega[0, 1]))


@pytest.mark.parametrize("backend", BACKENDS)
def test_one_trajectory_ends_at_its_terminal_event(backend):
    """Without t_eval one trajectory reports every step and, stopped by a terminal event, the event's
    state last (as solve_ivp); a batch of one (shape (1,)) is a batch: the two ends."""
    system = free_body()
    ev = coordinate_plane("omega", 1, dim=3, terminal=True, direction=-1)
    sol = ls.integrate(system, [0.3, 1.0, 0.4], (0.0, 20.0), method="rkmk45", events=ev, backend=backend)
    assert sol.status == 1
    rec = sol.events[0]
    assert sol.t[-1] == rec.t[0] == sol.stats["t_stop"] and sol.t[-2] < sol.t[-1]
    assert np.array_equal(sol.omega[-1], rec.omega[0]) and abs(sol.omega[-1, 1]) < 1e-12
    one = ls.integrate(system, [[0.3, 1.0, 0.4]], (0.0, 3.0), method="rkmk45", backend=backend)
    assert one.t.tolist() == [0.0, 3.0] and one.omega.shape == (2, 1, 3)


# ---------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("backend", BACKENDS)
def test_adaptive_error_tracks_rtol(backend):
    """Global error at t = 20 within a small factor of rtol on the free body and the KT body in SO(4): measured
    0.02-0.12 rtol; the band [rtol/200, rtol/2] fails an error norm off by 10 either way (an audit: 20 rtol let
    a norm divided by 10 pass)."""
    system = free_body()
    w0 = np.array([0.3, 1.0, 0.4])
    _, g_ref = embedded_reference(system, w0, 20.0, [20.0])
    for rtol in (1e-6, 1e-9):
        sol = ls.integrate(system, w0, (0.0, 20.0), reconstruct=True, method="rkmk45", rtol=rtol, atol=rtol * 1e-2,
                           t_eval=[20.0], backend=backend)
        assert rtol / 200 < np.max(np.abs(sol.g[-1] - g_ref[-1])) < rtol / 2
    kt, Omega0, Gamma0 = kt_body()
    _, g_ref = embedded_reference(kt, ls.so(4).vee(Omega0), 20.0, [20.0], Gamma0)
    for rtol in (1e-6, 1e-9):
        sol = ls.integrate(kt, Omega0, (0.0, 20.0), Gamma0=Gamma0, reconstruct=True, method="rkmk853", rtol=rtol,
                           atol=rtol * 1e-2, t_eval=[20.0], backend=backend)
        assert rtol / 200 < np.max(np.abs(sol.g[-1] - g_ref[-1])) < rtol / 2


@pytest.mark.parametrize("backend", BACKENDS)
def test_global_error_at_equal_rtol_is_near_scipys_on_a_hard_state(backend):
    """An audit's state of the KT body: at rtol 1e-8 the global error of rkmk853 without an error scale is 29x that
    of scipy's DOP853 on the same embedded ODE (14x at 1e-6, 62x at 1e-10) — the DOP853 estimator applied to the
    chart stages underestimates RKMK's local error on coupled scenes. With the method's error_scale (20) it is 1.7x; the
    docs' distribution over random states: numerics.md "What the tolerance means"."""
    from scipy.integrate import solve_ivp

    kt, _, _ = kt_body()
    x0 = np.array([1.0721721964436268, -0.39376521484106375, -0.49637991985595237])
    Gamma0 = np.array([0.4391486717612886, 0.3199530451562827, 0.09450500914455738, -0.8341746197482305])
    omega0 = x0 @ kt.constraints.basis
    t_eval = np.linspace(0.0, 20.0, 41)
    _, g_ref = embedded_reference(kt, omega0, 20.0, t_eval, Gamma0)
    model = kt.model(gamma=True)

    def rhs(t, y):  # the embedded ODE, as embedded_reference integrates it
        x, g = y[:-16], y[-16:].reshape(4, 4)
        xi = model.xi_from_coords(x[None])
        return np.concatenate([model.omega_coords(model.xi_dot(xi, (g.T @ Gamma0)[None]))[0],
                               (g @ model.omega_matrix(xi)[0]).ravel()])
    for rtol in (1e-8, 1e-10):  # measured 1.7x and 2.9x (the bound: 3x; 2.3x and 5.9x with a scale of 10)
        sc = solve_ivp(rhs, (0.0, 20.0), np.concatenate([omega0, np.eye(4).ravel()]), method="DOP853", rtol=rtol,
                       atol=1e-2 * rtol, t_eval=t_eval)
        scipy_error = np.max(np.abs(sc.y[-16:].T.reshape(-1, 4, 4) - g_ref))
        sol = ls.integrate(kt, omega0, (0.0, 20.0), Gamma0=Gamma0, reconstruct=True, method="rkmk853", rtol=rtol,
                           atol=1e-2 * rtol, t_eval=t_eval, backend=backend)
        assert np.max(np.abs(sol.g - g_ref)) < 3.0 * scipy_error, rtol


@pytest.mark.parametrize("backend", BACKENDS)
def test_structure_without_reprojection(backend):
    """With re-orthonormalisation off, |g^T g - I| grows at most like C N eps (the chart alone)."""
    system, Omega0, Gamma0 = kt_body()
    N = 4000
    sol = ls.integrate(system, Omega0, (0.0, N * 0.01), Gamma0=Gamma0, reconstruct=True, method="rkmk4", h=0.01,
                       t_eval=[N * 0.01], reproject=False, backend=backend)
    defect = np.max(np.abs(sol.g[-1].T @ sol.g[-1] - np.eye(4)))
    assert defect < 4 * N * np.finfo(float).eps
    G = ls.integrate(system, Omega0, (0.0, N * 0.01), Gamma0=Gamma0, method="rkmk4", h=0.01, t_eval=[N * 0.01],
                     reproject=False, backend=backend).Gamma[-1]
    assert abs(np.linalg.norm(G) - 1.0) < 4 * N * np.finfo(float).eps


@pytest.mark.parametrize("backend", BACKENDS)
def test_so3_chart_domain_is_enforced(backend):
    """h |Omega| = 2 pi: the so(3) dexp^-1 is singular there — a fixed step fails, an adaptive run shrinks."""
    system = free_body()
    w0 = np.array([0.0, 0.0, 2 * np.pi])  # a steady rotation about a principal axis
    sol = ls.integrate(system, w0, (0.0, 2.0), reconstruct=True, method="rkmk4", h=1.0, backend=backend)
    assert sol.status == -1 and "domain" in sol.message
    ada = ls.integrate(system, w0, (0.0, 2.0), reconstruct=True, method="rkmk45", first_step=1.0, rtol=1e-10,
                       atol=1e-12, t_eval=[2.0], backend=backend)
    assert ada.success and np.allclose(ada.g[-1], np.eye(3), atol=1e-8)


def test_multiplier_form_checks_the_constraints():
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I3))
    with pytest.raises(ValueError, match="Omega0 is not in the constraint subspace"):
        ls.integrate(system, [0.4, 0.1, 0.0], (0.0, 1.0), method="rkmk4", h=0.1, form="multiplier")


def test_events_bad_input():
    system = free_body()
    kt, Omega0, Gamma0 = kt_body()
    two = np.stack([Omega0, Omega0])
    for ev, msg in ((LinearEvent(Gamma=[1.0, 0.0, 0.0]), r"events\[0\]: LinearEvent Gamma coefficients must have shape "
                     r"\(\.\.\., 4\)"),
                    (LinearEvent(g=np.eye(3)), r"LinearEvent g coefficients must have shape \(\.\.\., 4, 4\)"),
                    (LinearEvent(Gamma=[1.0, 0.0, 0.0, 0.0], offset=[0.1, 0.2, 0.3]),
                     r"do not broadcast to the batch shape \(2,\)")):
        with pytest.raises(ValueError, match=msg):  # numpy's broadcast error before (an audit)
            ls.integrate(kt, two, (0.0, 1.0), Gamma0=Gamma0, reconstruct=True, method="rkmk45", events=ev)
    # a zero normal is a constant, not a surface (an audit: a section with all-zero coefficients gave 0 crossings)
    with pytest.raises(ValueError, match="are all 0: the event is a constant"):
        ls.integrators.LinearEvent(omega=[0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="all 0 for some trajectory"):
        ls.integrators.LinearEvent(omega=[[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="are all 0"):
        ls.poincare_section(system, [0.3, 1.0, 0.4], (0.0, 1.0), ls.research.plane(omega=[0.0, 0.0, 0.0]))
    with pytest.raises(TypeError, match="events"):
        ls.integrate(system, [0.3, 1.0, 0.4], (0.0, 1.0), method="rkmk45", events=[1.0])
    ev = coordinate_plane("omega", 1, dim=3)
    ev.direction = 2
    with pytest.raises(ValueError, match="direction"):
        ls.integrate(system, [0.3, 1.0, 0.4], (0.0, 1.0), method="rkmk45", events=ev)
    with pytest.raises(ValueError, match="Gamma"):
        ls.integrate(system, [0.3, 1.0, 0.4], (0.0, 1.0), method="rkmk45", events=LinearEvent(Gamma=[0, 0, 1.0]))
    # one value per trajectory: a () or (1,) for a batch of 3 was broadcast (every trajectory got the first one's
    # value, and its crossings), (3, 1) was refused already; one trajectory may return one value in any shape
    batch = np.array([[0.3, 1.0, 0.4], [0.2, -1.0, 0.5], [0.1, 0.9, -0.3]])
    for bad in (lambda t, O, G, g: O[0, 0, 1], lambda t, O, G, g: O[:1, 0, 1], lambda t, O, G, g: O[:, :1, 1]):
        with pytest.raises(ValueError, match=r"an event returns one value per trajectory: shape \(3,\)"):
            ls.integrate(system, batch, (0.0, 1.0), method="rkmk45", events=bad)
    one = ls.integrate(system, batch[0], (0.0, 1.0), method="rkmk45", events=lambda t, O, G, g: np.reshape(t - 0.5, 1))
    assert one.events[0].t == pytest.approx([0.5], abs=1e-14)


@pytest.mark.parametrize("backend", BACKENDS)
def test_gamma_n_crossings_against_the_klebsh_tisserand_closed_form(backend):
    """Gamma_n = 0 crossings of a Klebsh–Tisserand body (n = 3, past the tori condition: Gamma_n changes sign)
    located by the event machinery, against the zeros of the closed form's Gamma_n(t) (its tau-solution,
    ``analytic.KlebshTisserandMotion``), found by brentq on a fine grid."""
    from .test_hard_cases import fk_omega, single_angle_state

    I, B = np.array([1.0, 1.5, 2.5]), np.array([4.0, 3.0, 1.0])
    case = ls.cases.klebsh_tisserand(I, B)
    u0, G0 = single_angle_state(I, B, -1e-2)
    km = ls.analytic.KlebshTisserandMotion(u0, G0, I, B, allow_crossing=True)
    T = 12.0

    def gamma_n(t):
        return float(km.state(np.array([t]))[1][0, -1])

    ts = np.linspace(0.0, T, 2401)
    gn = km.state(ts)[1][:, -1]
    zeros = np.array([brentq(gamma_n, a, b, xtol=1e-14) for a, b, fa, fb in zip(ts[:-1], ts[1:], gn[:-1], gn[1:],
                                                                                  strict=True) if fa * fb < 0])
    assert zeros.size >= 2
    sol = ls.integrate(case.system, fk_omega(u0), (0.0, T), Gamma0=G0, method="rkmk853", rtol=1e-12, atol=1e-14,
                       events=gamma_crossing(3), backend=backend)
    rec = sol.events[0]
    assert rec.t.size == zeros.size
    np.testing.assert_allclose(rec.t, zeros, rtol=0, atol=1e-8)
    assert np.max(np.abs(rec.Gamma[:, -1])) < 1e-13


@pytest.mark.parametrize("backend", BACKENDS)
def test_progress_bar_counts_trajectories(backend, capsys):
    pytest.importorskip("tqdm")
    system = free_body()
    w = np.array([[0.3, 1.0, 0.4], [0.5, 0.6, -0.4], [0.1, 0.2, 0.3]])
    sol = ls.integrate(system, w, (0.0, 1.0), method="rkmk45", progress=True, backend=backend)
    assert sol.success
    assert "3/3" in capsys.readouterr().err


def test_linear_event_called_directly_reads_so3_matrices():
    """Called as integrate calls an event (Omega skew (..., n, n) on so(n)), a LinearEvent on so(3) read the
    matrix as three coordinate vectors (n = d = 3; an audit): 0.1, 0, -0.3 for the value 0.2."""
    ev = ls.integrators.LinearEvent(omega=[0.0, 1.0, 0.0], offset=0.05)
    x = np.array([0.1, 0.2, 0.3])
    assert ev(0.0, ls.so(3).hat(x), None, None) == pytest.approx(0.15)
    assert ev(0.0, x, None, None) == pytest.approx(0.15)
    batch = np.arange(9.0).reshape(3, 3)  # three coordinate vectors (not skew)
    assert np.allclose(ev(0.0, batch, None, None), batch[:, 1] - 0.05)
    ev4 = ls.integrators.LinearEvent(omega=np.arange(6.0))
    assert ev4(0.0, ls.so(4).hat(np.ones(6)), None, None) == pytest.approx(15.0)


def test_float32_initial_data_is_accepted_to_its_own_rounding():
    """float32 Gamma0 and g0 were refused (their rounding, ~6e-8, is above the 1e-8 tolerance) with a message
    reading 'got |Gamma0| = 1'; they are accepted to 16 float32 ulps and moved onto the sphere and the group."""
    system, Omega0, _ = kt_body()
    R = np.linalg.qr(np.random.default_rng(1).normal(size=(4, 4)))[0]
    R[:, 0] *= np.sign(np.linalg.det(R))
    G32, g32 = np.float32([0.0, 0.0, 0.6, 0.8]), R.astype(np.float32)
    sol = ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=G32, g0=g32, reconstruct=True, method="rkmk45")
    assert sol.success and np.max(np.abs(np.linalg.norm(sol.Gamma, axis=-1) - 1.0)) < 1e-14
    assert np.max(np.abs(np.swapaxes(sol.g, -1, -2) @ sol.g - np.eye(4))) < 1e-14
    ens = ls.ensemble(system, np.stack([Omega0, 0.5 * Omega0]), (0.0, 1.0), Gamma0=G32, g0=g32, reconstruct=True,
                      method="rkmk45", chunk_size=1)
    assert np.array_equal(ens.g[-1, 0], sol.g[-1])
    with pytest.raises(ValueError, match=r"got \|Gamma0\| - 1 = 0.00802"):
        ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=[0.0, 0.0, 0.6, 0.81], method="rkmk45")
    with pytest.raises(ValueError, match="within 1e-08"):  # float64 data keeps the 1e-8 tolerance
        ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=G32.astype(float), method="rkmk45")


def test_options_are_checked_whether_or_not_the_method_reads_them():
    """From a fuzz audit: values accepted silently (or read as something else) are refused, naming them."""
    system = free_body()
    w = [0.3, 1.0, 0.4]
    with pytest.raises(ValueError, match="rtol"):
        ls.integrate(system, w, (0.0, 1.0), method="rkmk4", h=0.1, rtol=-1.0)
    with pytest.raises(ValueError, match="atol"):
        ls.integrate(system, w, (0.0, 1.0), method="rkmk4", h=0.1, atol=np.nan)
    with pytest.raises((ValueError, TypeError), match="first_step"):
        ls.integrate(system, w, (0.0, 1.0), method="rkmk4", h=0.1, first_step=-1.0)
    with pytest.raises(TypeError, match="progress must be True or False"):
        ls.integrate(system, w, (0.0, 1.0), method="rkmk45", progress="yes")
    with pytest.raises(TypeError, match="t_span"):
        ls.integrate(system, w, (True, 2.0), method="rkmk45")
    with pytest.raises(ValueError, match="form='multiplier' chooses the model"):
        ls.integrate(system.model(), w, (0.0, 1.0), method="rkmk45", form="multiplier")
    ev = coordinate_plane("omega", 1, dim=3)
    ev.direction = True
    with pytest.raises(ValueError, match="direction must be -1, 0 or \\+1, got True"):
        ls.integrate(system, w, (0.0, 1.0), method="rkmk45", events=ev)
    with pytest.raises(TypeError, match="not a boolean"):
        ls.integrate(system, w, (0.0, 1.0), method="rkmk45", events=lambda t, O, G, g: t > 0.5)


# ------------------------------------------------------------------------- found by a mutation audit of the suite
def test_return_plane_is_normal_to_the_reduced_velocity():
    """The plane through the initial state has the reduced velocity there as its unit normal (dGamma/dt =
    -Omega Gamma included), so the flow leaves it upward at t0 — checked against a finite difference."""
    system, Omega0, Gamma0 = kt_body()
    plane = return_plane(system, Omega0, Gamma0)
    dt = 1e-6
    sol = ls.integrate(system, Omega0, (0.0, dt), Gamma0=Gamma0, method="rkmk853", rtol=1e-13, atol=1e-15,
                       t_eval=[0.0, dt])
    v = np.concatenate([sol.omega[1] - sol.omega[0], sol.Gamma[1] - sol.Gamma[0]]) / dt
    normal = np.concatenate([plane.omega, plane.Gamma])
    assert abs(np.linalg.norm(normal) - 1.0) < 1e-14
    assert abs(normal @ v / np.linalg.norm(v) - 1.0) < 1e-5
    assert abs(normal @ np.concatenate([sol.omega[0], sol.Gamma[0]]) - plane.offset) < 1e-14


@pytest.mark.parametrize("backend", BACKENDS)
def test_reproject_false_is_honoured(backend):
    """Re-orthonormalising moves the state, so an FSAL method evaluates stage 0 again there: rkmk5 over 200
    steps takes 1 + 6 * 200 evaluations without it and 3 more with it (every 64 steps) — on both backends."""
    system, Omega0, Gamma0 = kt_body()
    nfev = {flag: ls.integrate(system, Omega0, (0.0, 2.0), Gamma0=Gamma0, reconstruct=True, method="rkmk5", h=0.01,
                               t_eval=[2.0], reproject=flag, backend=backend).stats["nfev"] for flag in (False, True)}
    assert nfev == {False: 1201, True: 1204}


@pytest.mark.parametrize("backend", BACKENDS)
def test_max_steps_counts_rejected_steps(backend):
    """max_steps bounds accepted + rejected steps, on both backends alike."""
    system, Omega0, Gamma0 = kt_body()
    sol = ls.integrate(system, 10 * Omega0, (0.0, 50.0), Gamma0=Gamma0, method="rkmk45", rtol=1e-10, atol=1e-12,
                       first_step=5.0, max_steps=40, t_eval=[50.0], backend=backend)
    assert sol.status == -1 and "max_steps" in sol.message
    assert sol.stats["rejected"] > 0 and sol.stats["steps"] + sol.stats["rejected"] == 40


def test_small_distances_from_D_and_bad_counts_are_refused():
    """Omega0 1e-6 off the constraint subspace is refused (not projected); max_steps=0 and repeated output
    times are refused; a batch of g0 with one reflection among rotations is refused."""
    system, Omega0, Gamma0 = kt_body()
    off = Omega0.copy()
    off[0, 1], off[1, 0] = 1e-6, -1e-6  # Fedorov–Kozlov: Omega_01 = 0 in D
    with pytest.raises(ValueError, match="not in the constraint subspace"):
        ls.integrate(system, off, (0.0, 1.0), Gamma0=Gamma0, method="rkmk45")
    with pytest.raises(ValueError, match="max_steps"):
        ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=Gamma0, method="rkmk45", max_steps=0)
    # a wrong type is a TypeError (1e7 is a float: the message says how to write it)
    with pytest.raises(TypeError, match=r"max_steps must be an integer, got 10000000.0 \(write 10_000_000"):
        ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=Gamma0, method="rkmk45", max_steps=1e7)
    # an empty batch names the input whose batch axes are empty (it named Omega0 for an empty Gamma0)
    with pytest.raises(ValueError, match=r"batch shape \(0,\): the batch axes of Gamma0 \(0,\)\); pass at least one"):
        ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=np.zeros((0, 4)), method="rkmk45")
    with pytest.raises(ValueError, match=r"the batch axes of Omega0 \(2, 0\), g0 \(0,\)\)"):
        ls.integrate(system, np.zeros((2, 0, 4, 4)), (0.0, 1.0), Gamma0=Gamma0, reconstruct=True,
                     g0=np.zeros((0, 4, 4)), method="rkmk45")
    for span in [(0.0, 1j), (0.0, np.complex128(1.0))]:  # complex: TypeError, as for Omega0 (was a ValueError)
        with pytest.raises(TypeError, match="t_span must be a pair of numbers"):
            ls.integrate(system, Omega0, span, Gamma0=Gamma0, method="rkmk45")
    with pytest.raises(ValueError, match="t_eval must be strictly increasing"):
        ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=Gamma0, method="rkmk45", t_eval=[0.0, 0.5, 0.5, 1.0])
    g0 = np.stack([np.eye(4), np.diag([1.0, 1.0, 1.0, -1.0]), np.eye(4)])
    with pytest.raises(ValueError, match="g0"):
        ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=Gamma0, method="rkmk45", reconstruct=True, g0=g0)


def test_run_message_names_the_first_failure():
    from liesuslov.integrators.problem import run_message

    msg = run_message(np.array([0, -1, 1, -1]), np.array([1.0, 0.25, 0.5, 0.75]), np.array([0, 1, 0, 3]))
    assert msg.startswith("2 of 4 trajectories failed; the first (index 1)") and "t = 0.25" in msg


def test_numpy_renormalises_gamma_to_unit_length():
    """The numpy solver's re-projection of Gamma is Gamma / |Gamma| (also far from the sphere)."""
    from types import SimpleNamespace

    from liesuslov.integrators.problem import Problem

    G = np.array([[0.0, 3.0, 4.0], [1.1, 0.0, 0.0]])
    out = Problem.reprojected(SimpleNamespace(mode="gamma", skew=True), G)
    assert np.allclose(out, [[0.0, 0.6, 0.8], [1.0, 0.0, 0.0]], rtol=0, atol=1e-15)


def test_output_time_at_a_terminal_event_is_the_state_there():
    """On numpy (a user callable): an output time exactly at a terminal event's time reports the state, as
    scipy does; the ones after it are NaN."""
    system = free_body()

    def at_125(t, Omega, Gamma, g):
        return t - 1.25

    at_125.terminal = True
    sol = ls.integrate(system, [0.3, 1.0, 0.4], (0.0, 2.0), method="rkmk45", events=at_125,
                       t_eval=[0.5, 1.25, 1.5])
    assert sol.stats["backend"] == "numpy" and sol.status == 1 and sol.events[0].t.tolist() == [1.25]
    assert np.all(np.isfinite(sol.omega[1])) and np.all(np.isnan(sol.omega[2]))
    assert np.allclose(sol.omega[1], sol.events[0].omega[0], rtol=0, atol=1e-12)
