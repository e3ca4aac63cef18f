"""Analytic references against independent DOP853 integrations of the plain equations coded here.

Every reference in :mod:`liesuslov.analytic` is checked against ``solve_ivp(..., method="DOP853",
rtol=1e-12, atol=1e-12)`` of the equations of motion written out in this file ((4.3), (3.1), the
pendulum, the multiplier form of Suslov's problem), never against the library's own vector fields.
The tests named ``test_errata_*`` demonstrate the paper's misprints listed in ``docs/errata.md``.
"""

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

import liesuslov as ls
from liesuslov.analytic import (
    KharlamovaMotion,
    KlebshTisserandMotion,
    SphericalPendulumMotion,
    Suslov3Free,
    family3_integral,
    gyroscopic3_free_integrals,
    gyroscopic3_linear_integral,
    gyroscopic3_quadratic_integral,
    kharlamova3_integral,
    kharlamova_coordinates,
    kharlamova_from_coordinates,
    kharlamova_integrals,
    kharlamova_partial_energies,
    kharlamova_quartic,
    klebsh_tisserand3_integral,
    klebsh_tisserand_angles,
    klebsh_tisserand_energy,
    klebsh_tisserand_frequencies,
    klebsh_tisserand_integrals,
    klebsh_tisserand_two_tori,
    lagrange3_integral,
    suslov3_asymptotic_points,
    suslov3_energy,
    suslov_asymptotic_points,
    suslov_energy,
    suslov_limits,
    suslov_lyapunov,
    suslov_reduced_field,
)

RTOL = ATOL = 1e-12          # the reference integrations
TOL = 1e-9                   # analytic state vs DOP853 over times O(10)


def dop(f, y0, ts, **kw):
    """DOP853 solution of y' = f(t, y) at the times ``ts`` (any sign), shape (len(ts), len(y0))."""
    ts = np.asarray(ts, dtype=float)
    out = np.empty((ts.size, len(y0)))
    for sgn in (1.0, -1.0):
        sel = (ts * sgn > 0) | ((ts == 0) & (sgn > 0))
        if not np.any(sel):
            continue
        tend = float(np.max(np.abs(ts[sel]))) * sgn
        if tend == 0.0:
            out[sel] = y0
            continue
        sol = solve_ivp(f, (0.0, tend), y0, method="DOP853", rtol=RTOL, atol=ATOL, dense_output=True, **kw)
        assert sol.success
        out[sel] = sol.sol(ts[sel]).T
    return out


# ----------------------------------------------------------------------------------- plain equations
def pendulum_rhs(n, mass, B, gamma):
    """m q'' = -B (gamma - <gamma, q> q) - m |v|^2 q."""
    def f(t, y):
        q, v = y[:n], y[n:]
        return np.concatenate([v, -(B / mass) * (gamma - (gamma @ q) * q) - (v @ v) * q])
    return f


def fk_rhs(I, grad_V, with_tau=False):
    """(4.3): (I_i + I_n) u_i' = dV_i Gamma_n - Gamma_i dV_n, Gamma_i' = -Gamma_n u_i,
    Gamma_n' = sum Gamma_i u_i (with ``with_tau`` also tau' = Gamma_n)."""
    n = len(I)

    def f(t, y):
        u, G = y[:n - 1], y[n - 1:2 * n - 1]
        dV = grad_V(G)
        du = (dV[:-1] * G[-1] - G[:-1] * dV[-1]) / (I[:-1] + I[-1])
        dG = np.concatenate([-G[-1] * u, [G[:-1] @ u]])
        extra = [G[-1]] if with_tau else []
        return np.concatenate([du, dG, extra])
    return f


def suslov3_rhs(J, grad_V=None, eps=0.0):
    """(3.1) with omega_3 = 0: rows 1, 2 of J w' = J w x w + Gamma x dV + eps Gamma x w;
    Gamma' = Gamma x w."""
    J = np.asarray(J, dtype=float)
    J = np.diag(J) if J.ndim == 1 else J

    def f(t, y):
        w = np.array([y[0], y[1], 0.0])
        G = y[2:5]
        torque = np.cross(J @ w, w) + eps * np.cross(G, w)
        if grad_V is not None:
            torque = torque + np.cross(G, grad_V(G))
        return np.concatenate([np.linalg.solve(J[:2, :2], torque[:2]), np.cross(G, w)])
    return f


def unit(x):
    x = np.asarray(x, dtype=float)
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def tangent(rng, q):
    v = rng.normal(size=q.shape)
    return v - np.sum(v * q, axis=-1, keepdims=True) * q


# ============================================================================ spherical pendulum
@pytest.mark.parametrize("n", [3, 4, 6])
def test_pendulum_state_matches_ode(n):
    rng = np.random.default_rng(n)
    gamma = unit(rng.normal(size=n))
    q0 = unit(rng.normal(size=(3, n)))
    v0 = 1.2 * tangent(rng, q0)
    ts = np.array([0.0, 0.4, 1.7, 4.0, -2.5])
    for mass, B in [(1.3, 2.0), (0.8, -1.5), (1.0, 0.0)]:
        p = SphericalPendulumMotion(q0, v0, gamma, mass, B)
        q, v = p.state(ts)
        assert q.shape == v.shape == (5, 3, n)
        for b in range(3):
            ref = dop(pendulum_rhs(n, mass, B, gamma), np.concatenate([q0[b], v0[b]]), ts)
            np.testing.assert_allclose(q[:, b], ref[:, :n], atol=TOL)
            np.testing.assert_allclose(v[:, b], ref[:, n:], atol=TOL)
        np.testing.assert_allclose(p.height(ts), q @ gamma, atol=1e-15)


def test_pendulum_cubic_roots_and_batch_shapes():
    rng = np.random.default_rng(1)
    n = 4
    gamma = unit(rng.normal(size=n))
    q0 = unit(rng.normal(size=(2, 3, n)))
    v0 = tangent(rng, q0)
    p = SphericalPendulumMotion(q0, v0, gamma, 1.5, -2.0)
    assert p.roots.shape == (2, 3, 3) and p.cubic.shape == (2, 3, 4) and p.height_period.shape == (2, 3)
    z0 = q0 @ gamma
    lo, hi = p.height_range[..., 0], p.height_range[..., 1]
    assert np.all(lo <= z0 + 1e-15) and np.all(z0 <= hi + 1e-15)
    for k in range(3):   # the cubic vanishes at its roots
        assert np.max(np.abs(p.cubic_value(p.roots[..., k]))) < 1e-12
    # (dz/dt)^2 = C(z) along the motion
    q, v = p.state(np.linspace(0.0, 3.0, 7))
    np.testing.assert_allclose((v @ gamma) ** 2, p.cubic_value(q @ gamma), atol=1e-12)
    # t of any shape
    q, _ = p.state(np.zeros((4, 5)))
    assert q.shape == (4, 5, 2, 3, n)
    np.testing.assert_allclose(q[1, 2], q0, atol=1e-15)


def test_pendulum_height_period_and_precession():
    """z(T) = z0 with the same velocity; the azimuth about gamma advances by the precession (ODE, n = 3)."""
    gamma = np.array([0.0, 0.0, 1.0])
    cases = [(np.array([0.6, 0.0, -0.8]), np.array([0.1, 1.1, 0.0755]), 1.0, 3.0),
             (np.array([0.0, 0.8, 0.6]), np.array([-1.4, 0.3, -0.4]), 2.0, -1.0)]
    for q0, v0, mass, B in cases:
        v0 = v0 - (v0 @ q0) * q0
        p = SphericalPendulumMotion(q0, v0, gamma, mass, B)
        T = float(p.height_period)
        ts = np.linspace(0.0, T, 4001)
        y = dop(pendulum_rhs(3, mass, B, gamma), np.concatenate([q0, v0]), ts)
        np.testing.assert_allclose(y[-1, 2], q0[2], atol=1e-10)
        np.testing.assert_allclose(y[-1, 5], v0[2], atol=1e-10)
        phi = np.unwrap(np.arctan2(y[:, 1], y[:, 0]))
        sense = np.sign(q0[0] * v0[1] - q0[1] * v0[0])
        np.testing.assert_allclose(sense * (phi[-1] - phi[0]), float(p.precession), atol=1e-9)
        # and the state after one height period is q0 turned by the precession about gamma
        q, _ = p.state(T)
        np.testing.assert_allclose(q, y[-1, :3], atol=1e-10)


def test_pendulum_degenerate_cases():
    rng = np.random.default_rng(7)
    n = 5
    gamma = unit(rng.normal(size=n))
    e = unit(tangent(rng, gamma))
    ts = np.array([0.0, 0.9, 2.6, -1.3])
    q_side = np.cos(2.0) * gamma + np.sin(2.0) * e
    data = [
        (q_side, np.zeros(n)),                                   # released from rest (planar)
        (q_side, 0.7 * (-np.sin(2.0) * gamma + np.cos(2.0) * e)),  # planar, in a plane containing gamma
        (-gamma, 0.9 * e), (gamma, 0.5 * e),                     # through the poles
        (gamma, 5.0 * e),                                        # rotation over the top
        (-gamma, np.zeros(n)), (gamma, np.zeros(n)),              # equilibria
    ]
    q0 = np.array([d[0] for d in data])
    v0 = np.array([d[1] for d in data])
    mass, B = 1.0, -2.0 * 1.0     # B < 0: the stable equilibrium is q = +gamma
    p = SphericalPendulumMotion(q0, v0, gamma, mass, B)
    assert np.all(p.planar)
    q, v = p.state(ts)
    for b in range(len(data)):
        ref = dop(pendulum_rhs(n, mass, B, gamma), np.concatenate([q0[b], v0[b]]), ts)
        np.testing.assert_allclose(q[:, b], ref[:, :n], atol=TOL)
        np.testing.assert_allclose(v[:, b], ref[:, n:], atol=TOL)
    assert p.height_period[-2] == np.inf                # upright equilibrium (-gamma here): separatrix
    np.testing.assert_allclose(p.height_period[-1], np.pi / np.sqrt(2.0), rtol=1e-14)   # small oscillations
    np.testing.assert_allclose(p.precession[:2], np.pi)
    # a tiny angular momentum about gamma: the general formula, continuous with the planar one
    pert = 1e-9 * unit(tangent(rng, q0[1]) - (tangent(rng, q0[1]) @ gamma) * gamma)
    p2 = SphericalPendulumMotion(q0[1], v0[1] + pert - (pert @ q0[1]) * q0[1], gamma, mass, B)
    assert not p2.planar
    np.testing.assert_allclose(p2.state(ts)[0], q[:, 1], atol=1e-8)
    np.testing.assert_allclose(p2.precession, np.pi, atol=1e-7)


def test_pendulum_circular_orbit():
    """Relative equilibrium: z constant, azimuth uniform (a double root of the cubic)."""
    gamma = np.array([0.0, 0.0, 1.0])
    beta, z0 = 2.0, -0.5
    speed = np.sqrt(-beta * (1 - z0 ** 2) / z0)
    q0 = np.array([np.sqrt(1 - z0 ** 2), 0.0, z0])
    for scale in (1.0, 1.0 + 1e-9, 1.0 + 1e-4):
        v0 = np.array([0.0, speed * scale, 0.0])
        p = SphericalPendulumMotion(q0, v0, gamma, 1.0, beta)
        ts = np.linspace(0.0, 6.0, 5)
        ref = dop(pendulum_rhs(3, 1.0, beta, gamma), np.concatenate([q0, v0]), ts)
        np.testing.assert_allclose(p.state(ts)[0], ref[:, :3], atol=TOL)


def _k_careful(m1):
    """K(1 - m1) by adaptive quadrature of int_0^{pi/2} d psi / sqrt(sin^2 psi + m1 cos^2 psi), split at
    multiples of sqrt(m1) where the integrand peaks (independent of scipy's ellipk)."""
    f = lambda p: 1.0 / np.sqrt(np.sin(p) ** 2 + m1 * np.cos(p) ** 2)  # noqa: E731
    pts = [np.sqrt(m1) * 10.0 ** k for k in range(-2, 6) if np.sqrt(m1) * 10.0 ** k < np.pi / 2]
    edges = [0.0] + pts + [np.pi / 2]
    return sum(quad(f, a, b, epsabs=0.0, epsrel=1e-13, limit=200)[0]
               for a, b in zip(edges[:-1], edges[1:], strict=True))


def test_pendulum_near_separatrix_period():
    """Started next to the upright position, modulus 1 - 1e-8: period and m1 to full accuracy."""
    gamma = np.array([0.0, 0.0, 1.0])
    beta, mass = 2.0, 1.0
    # (a) planar, released from rest at angle alpha from the top: m1 = sin^2(alpha/2)
    m1 = 2e-8
    alpha = 2.0 * np.arcsin(np.sqrt(m1))
    p = SphericalPendulumMotion([np.sin(alpha), 0.0, np.cos(alpha)], np.zeros(3), gamma, mass, beta * mass)
    np.testing.assert_allclose(p.complementary_parameter, m1, rtol=1e-13)
    np.testing.assert_allclose(p.height_period, 2.0 * _k_careful(m1) / np.sqrt(beta), rtol=1e-12)
    # (b) spatial: prescribe z2 = 1 - a (start there), z3 = 1 + c; then 1 + z1 = a c/(2 - a + c),
    #     l^2 = 2 beta (1 - z1) a c exactly, m1 = (a + c)/(z3 - z1)
    a, c = 4e-9, 6e-9
    opz1 = a * c / (2.0 - a + c)
    z1, z2, z3 = -1.0 + opz1, 1.0 - a, 1.0 + c
    l2 = 2.0 * beta * (2.0 - opz1) * a * c
    rho0 = np.sqrt(a * (2.0 - a))
    q0, v0 = np.array([rho0, 0.0, z2]), np.array([0.0, np.sqrt(l2) / rho0, 0.0])
    p = SphericalPendulumMotion(q0, v0, gamma, mass, beta * mass)
    assert not p.planar
    m1 = (a + c) / (z3 - z1)
    np.testing.assert_allclose(p.complementary_parameter, m1, rtol=1e-12)
    np.testing.assert_allclose(p.roots, [z1, z2, z3], rtol=0, atol=1e-15)
    T = 4.0 * _k_careful(m1) / np.sqrt(2.0 * beta * (z3 - z1))
    np.testing.assert_allclose(p.height_period, T, rtol=1e-12)
    # the state over the first quarter period (the flow near the top amplifies the ODE's errors)
    ts = np.linspace(0.0, 0.25 * T, 4)
    ref = dop(pendulum_rhs(3, mass, beta * mass, gamma), np.concatenate([q0, v0]), ts)
    np.testing.assert_allclose(p.state(ts)[0], ref[:, :3], atol=1e-8)


def test_lagrange_case_reduces_to_the_pendulum():
    """(4.3) with I = diag(I1, .., I1, In), V = Bn Gamma_n and g' = g Omega: q = g e_n is the pendulum."""
    n, I1, In, Bn = 4, 0.8, 1.4, 1.7
    I = np.array([I1] * (n - 1) + [In])
    rng = np.random.default_rng(11)
    g0, _ = np.linalg.qr(rng.normal(size=(n, n)))
    g0 *= np.sign(np.linalg.det(g0))
    gamma = unit(rng.normal(size=n))
    G0 = g0.T @ gamma
    u0 = rng.normal(size=n - 1)
    base = fk_rhs(I, lambda G: np.concatenate([np.zeros(n - 1), [Bn]]))

    def f(t, y):
        u = y[:n - 1]
        g = y[2 * n - 1:].reshape(n, n)
        Om = np.zeros((n, n))
        Om[:-1, -1], Om[-1, :-1] = u, -u
        return np.concatenate([base(t, y[:2 * n - 1]), (g @ Om).ravel()])
    ts = np.array([0.0, 1.0, 2.5, 5.0])
    y = dop(f, np.concatenate([u0, G0, g0.ravel()]), ts)
    g = y[:, 2 * n - 1:].reshape(-1, n, n)
    q_ref = g[:, :, -1]
    Om0 = np.zeros((n, n))
    Om0[:-1, -1], Om0[-1, :-1] = u0, -u0
    p = SphericalPendulumMotion(g0[:, -1], g0 @ Om0[:, -1], gamma, I1 + In, Bn)
    q, _ = p.state(ts)
    np.testing.assert_allclose(q, q_ref, atol=TOL)
    np.testing.assert_allclose(q @ gamma, y[:, 2 * n - 2], atol=TOL)    # Gamma_n = <gamma, q>


# ==================================================================================== Kharlamova
def kharlamova_setup(n, seed):
    rng = np.random.default_rng(seed)
    I = rng.uniform(0.5, 2.0, n)
    B = rng.uniform(0.5, 1.5, n - 1) * rng.choice([-1.0, 1.0], n - 1)
    u0 = 0.7 * rng.normal(size=(3, n - 1))
    G0 = unit(rng.normal(size=(3, n)))
    return I, B, u0, G0, (lambda G, B=B: np.concatenate([B, [0.0]]))


@pytest.mark.parametrize("n", [3, 4, 5])
def test_kharlamova_state_and_period(n):
    I, B, u0, G0, dV = kharlamova_setup(n, 20 + n)
    km = KharlamovaMotion(u0, G0, I, B)
    assert np.all(km.kind == "periodic")
    ts = np.array([0.0, 0.8, 3.1, 7.5, -2.2])
    u, G = km.state(ts)
    for b in range(3):
        y0 = np.concatenate([u0[b], G0[b]])
        ref = dop(fk_rhs(I, dV), y0, ts)
        np.testing.assert_allclose(u[:, b], ref[:, :n - 1], atol=TOL)
        np.testing.assert_allclose(G[:, b], ref[:, n - 1:], atol=TOL)
        # the period: time between two minima of omega_1 (Gamma_n = d omega_1/dt crosses 0 upwards)
        ev = lambda t, y: y[-1]  # noqa: E731
        ev.direction = 1.0
        T = float(km.period[b])
        sol = solve_ivp(fk_rhs(I, dV), (0.0, 2.2 * T), y0, method="DOP853", rtol=RTOL, atol=ATOL, events=ev)
        tev = sol.t_events[0]
        assert len(tev) >= 2
        np.testing.assert_allclose(np.diff(tev)[0], T, rtol=1e-10)
        # omega_1 ranges over the bracket
        w1 = (I[0] + I[-1]) / B[0] * sol.y_events[0][:, 0]
        np.testing.assert_allclose(w1, km.bracket[b, 0], atol=1e-9)
    G_T = km.state(km.period)[1]                                       # (3, 3, n): time index = batch index
    np.testing.assert_allclose(G_T[np.arange(3), np.arange(3)], G0, atol=1e-10)   # the state is T-periodic


def test_kharlamova_quartic_is_the_papers_P4():
    """kharlamova_quartic = 1 - (B1/(I1+In))^2 gamma_1^2 - sum (B_i/(I_i+I_n))^2 (gamma_1+gamma_i)^2
    with gamma from (4.6), (4.8); and (d omega_1/dt)^2 = P4(omega_1) along the ODE."""
    n = 5
    I, B, u0, G0, dV = kharlamova_setup(n, 3)
    k = (B / (I[:-1] + I[-1])) ** 2
    for b in range(3):
        P4 = kharlamova_quartic(u0[b], G0[b], I, B)
        om0, ga0 = kharlamova_coordinates(u0[b], G0[b], I, B)
        w1 = om0[0] + np.linspace(-1.5, 1.5, 7)
        g1 = ga0[0] + 0.5 * (w1 ** 2 - om0[0] ** 2)                         # (4.8)
        gi = ga0[1:-1, None] + om0[1:, None] * (w1 - om0[0])
        paper = 1.0 - k[0] * g1 ** 2 - np.sum(k[1:, None] * (g1 + gi) ** 2, axis=0)
        np.testing.assert_allclose(np.polyval(P4, w1), paper, atol=1e-12)
        ts = np.linspace(0.0, 4.0, 6)
        y = dop(fk_rhs(I, dV), np.concatenate([u0[b], G0[b]]), ts)
        w1t = (I[0] + I[-1]) / B[0] * y[:, 0]
        np.testing.assert_allclose(np.polyval(P4, w1t), y[:, -1] ** 2, atol=1e-10)
    km = KharlamovaMotion(u0, G0, I, B)
    np.testing.assert_allclose(km.quartic, kharlamova_quartic(u0, G0, I, B), atol=1e-14)
    for j in range(2):
        assert np.max(np.abs(np.polyval(km.quartic[0], km.bracket[0, j]))) < 1e-12


def test_kharlamova_coordinates_integrals_and_time_of():
    n = 4
    I, B, u0, G0, dV = kharlamova_setup(n, 5)
    om, ga = kharlamova_coordinates(u0, G0, I, B)
    u1, G1 = kharlamova_from_coordinates(om, ga, I, B)
    np.testing.assert_allclose(u1, u0, atol=1e-14)
    np.testing.assert_allclose(G1, G0, atol=1e-14)
    ts = np.linspace(0.0, 5.0, 6)
    y = dop(fk_rhs(I, dV), np.concatenate([u0[0], G0[0]]), ts)
    u, G = y[:, :n - 1], y[:, n - 1:]
    F = kharlamova_integrals(u, I, B)
    assert F.shape == (6, n - 1, n - 1)
    np.testing.assert_allclose(F - F[0], 0.0, atol=1e-10)
    E = kharlamova_partial_energies(u, G, I, B)
    np.testing.assert_allclose(E - E[0], 0.0, atol=1e-10)
    om_t, _ = kharlamova_coordinates(u, G, I, B)
    np.testing.assert_allclose(om_t[:, 1:] - om_t[0, 1:], 0.0, atol=1e-10)      # (4.7): omega_i' = 0
    # t(omega_1) = int d w / (+-sqrt(P4)) by plain quadrature inside the interval, the sign of Gamma_n(0);
    # both signs of Gamma_n(0) (the time-reversed start) and the two turning points as starts
    for G0n in (G0[0], G0[0] * np.r_[np.ones(n - 1), -1.0]):
        km = KharlamovaMotion(u0[0], G0n, I, B)
        xi1, xi2 = km.bracket
        w0 = float(km.omega1_0)
        P4 = km.quartic
        sign = np.sign(G0n[-1])
        for w in (xi1 + 0.3 * (xi2 - xi1), w0 + 0.4 * (xi2 - w0), w0 - 0.4 * (w0 - xi1)):
            ref = quad(lambda x, P4=P4: 1.0 / np.sqrt(np.polyval(P4, x)), w0, w, epsabs=1e-14, epsrel=1e-13)[0]
            np.testing.assert_allclose(km.time_of(w), sign * ref, rtol=1e-11)
            np.testing.assert_allclose(km.omega1(km.time_of(w)), w, atol=1e-12)
        # from xi1 to xi2 is half a period (at the ends t(w) ~ sqrt(w - xi): the rounding of w shows at 1e-8)
        np.testing.assert_allclose(sign * (km.time_of(xi2) - km.time_of(xi1)), 0.5 * km.period, rtol=1e-7)
        for t_turn in (km.time_of(xi1), km.time_of(xi2)):
            # a start within rounding of a turning point (Gamma_n ~ 1e-17 at the top): its root of P4 near 0
            # came out on either side of 0 and gave a bracket [0, 0]; the motion is the same one shifted
            u_turn, G_turn = km.state(t_turn)
            near = KharlamovaMotion(u_turn, G_turn, I, B)
            ts = np.linspace(-3.0, 3.0, 7)
            for a, b in zip(near.state(ts), km.state(t_turn + ts), strict=True):
                np.testing.assert_allclose(a, b, atol=1e-12)
            # exactly on it (Gamma_n = 0): every value of the bracket is ahead
            G_turn[-1] = 0.0
            turn = KharlamovaMotion(u_turn, G_turn / np.linalg.norm(G_turn), I, B)
            w = np.mean(turn.bracket)
            assert turn.time_of(w) > 0.0
            np.testing.assert_allclose(turn.omega1(turn.time_of(w)), w, atol=1e-12)


def test_kharlamova_asymptotic_motion():
    """Data on a separatrix (P4 has a double root at an end): kind asymptotic, T = inf, state still right."""
    n = 4
    I, B = np.array([1.0, 1.5, 2.0, 0.5]), np.array([1.0, -0.7, 1.3])
    c = (I[:-1] + I[-1]) / B
    Gs = unit([0.6, -0.3, 0.0])
    us = np.array([0.1, 0.2, 0.0])
    us = us - (us @ Gs) * Gs                     # equilibrium: Gamma_n = 0, sum Gamma_i u_i = 0
    assert Gs @ (1.0 / c) - us @ us > 0.0       # unstable: P4'' > 0 at the double root
    data = []
    for y0, sgn in [(-0.3, 1.0), (-0.3, -1.0), (0.3, 1.0), (0.3, -1.0)]:
        Gp = Gs - us * y0 - y0 ** 2 / (2.0 * c)  # the state a shift y0 away along the same orbit
        data.append((us + y0 / c, np.concatenate([Gp, [sgn * np.sqrt(1.0 - Gp @ Gp)]])))
    u0 = np.array([d[0] for d in data])
    G0 = np.array([d[1] for d in data])
    km = KharlamovaMotion(u0, G0, I, B)
    assert np.all(km.kind == "asymptotic") and np.all(np.isinf(km.period))
    ts = np.array([0.0, 1.0, 4.0, 8.0])
    u, G = km.state(ts)
    dV = lambda G: np.concatenate([B, [0.0]])  # noqa: E731
    for b in range(4):
        ref = dop(fk_rhs(I, dV), np.concatenate([u0[b], G0[b]]), ts)
        np.testing.assert_allclose(G[:, b], ref[:, n - 1:], atol=1e-8)
        np.testing.assert_allclose(u[:, b], ref[:, :n - 1], atol=1e-8)
    # the ones moving towards the equilibrium reach it
    far, _ = km.state(60.0)
    np.testing.assert_allclose(far[0], us, atol=1e-6)
    eq = KharlamovaMotion(us, np.concatenate([Gs, [0.0]]), I, B)
    assert eq.kind == "equilibrium"
    np.testing.assert_allclose(eq.state([0.0, 5.0])[1], np.concatenate([Gs, [0.0]])[None].repeat(2, 0))


# ============================================================================ Klebsh–Tisserand
def kt_setup(n, seed):
    rng = np.random.default_rng(seed)
    I = rng.uniform(0.5, 2.0, n)
    B = np.concatenate([rng.uniform(2.0, 4.0, n - 1), [1.0]])
    while True:
        G0 = rng.normal(size=(3, n))
        G0[:, -1] = 3.0 * np.abs(G0[:, -1]) * np.array([1.0, -1.0, 1.0])
        G0 = unit(G0)
        u0 = 0.3 * rng.normal(size=(3, n - 1))
        if np.all(klebsh_tisserand_two_tori(klebsh_tisserand_integrals(u0, G0, I, B), B)):
            return I, B, u0, G0, (lambda G, B=B: B * G)


@pytest.mark.parametrize("n", [3, 4, 5])
def test_klebsh_tisserand_state_and_tau(n):
    I, B, u0, G0, dV = kt_setup(n, 40 + n)
    kt = KlebshTisserandMotion(u0, G0, I, B)
    ts = np.array([0.0, 1.3, 6.0, 14.0, -3.5])
    u, G = kt.state(ts)
    tau = kt.tau(ts)
    assert u.shape == (5, 3, n - 1) and tau.shape == (5, 3)
    for b in range(3):
        ref = dop(fk_rhs(I, dV, with_tau=True), np.concatenate([u0[b], G0[b], [0.0]]), ts)
        np.testing.assert_allclose(u[:, b], ref[:, :n - 1], atol=TOL)
        np.testing.assert_allclose(G[:, b], ref[:, n - 1:2 * n - 1], atol=TOL)
        np.testing.assert_allclose(tau[:, b], ref[:, -1], atol=TOL)          # d tau/dt = Gamma_n
        # angles: phi_i(t) = phi_i^0 + omega_i tau(t)
        _, phi = klebsh_tisserand_angles(ref[:, :n - 1], ref[:, n - 1:2 * n - 1], I, B)
        want = kt.phases[b] + klebsh_tisserand_frequencies(I, B) * ref[:, -1:]
        np.testing.assert_allclose(np.angle(np.exp(1j * (phi - want))), 0.0, atol=TOL)
    back = kt.time_of_tau(tau)                      # (5, 3, 3): tau[:, b] belongs to initial data b
    np.testing.assert_allclose(back[:, np.arange(3), np.arange(3)], ts[:, None] + 0 * tau, atol=1e-12)
    _, GG = kt.state_at_tau(tau[:, 0])
    np.testing.assert_allclose(GG[:, 0], G[:, 0], atol=1e-13)


def test_klebsh_tisserand_integrals_and_two_tori():
    """The F_i are conserved; sum c_i/(B_i - B_n) < 1 keeps Gamma_n away from 0 (|Gamma_n| >= sqrt(delta));
    data violating it can reach Gamma_n = 0 and are refused."""
    n = 4
    I, B, u0, G0, dV = kt_setup(n, 9)
    ts = np.linspace(0.0, 40.0, 4001)
    y = dop(fk_rhs(I, dV), np.concatenate([u0[0], G0[0]]), ts)
    F = klebsh_tisserand_integrals(y[:, :n - 1], y[:, n - 1:], I, B)
    np.testing.assert_allclose(F - F[0], 0.0, atol=1e-10)
    kt = KlebshTisserandMotion(u0[0], G0[0], I, B)
    assert np.min(np.abs(y[:, -1])) >= np.sqrt(kt.margin) - 1e-9
    # violating data: |Gamma'|^2 = 0.99, Gamma_n = 0.1 decreasing
    Gp = np.sqrt(0.99) * unit([1.0, 1.0, 1.0])
    Gb = np.concatenate([Gp, [0.1]])
    ub = np.array([0.3, 0.2, 0.25])
    c = klebsh_tisserand_integrals(ub, Gb, I, B)
    assert not klebsh_tisserand_two_tori(c, B)
    ev = lambda t, y: y[-1]  # noqa: E731
    sol = solve_ivp(fk_rhs(I, dV), (0.0, 5.0), np.concatenate([ub, Gb]), method="DOP853", rtol=RTOL,
                    atol=ATOL, events=ev)
    assert len(sol.t_events[0]) >= 1                   # Gamma_n vanishes
    with pytest.raises(ValueError, match="4.10"):
        KlebshTisserandMotion(ub, Gb, I, B)


def test_klebsh_tisserand3_integral():
    """F = <Jw, Jw>/2 - <A Gamma, Gamma>/2, A = eps det(J) J^-1, along (3.1), V = eps <J Gamma, Gamma>/2."""
    J, eps = np.array([1.0, 2.0, 2.6]), 0.7
    y0 = np.concatenate([[0.4, -0.9], unit([0.3, -0.5, 0.8])])
    y = dop(suslov3_rhs(J, lambda G: eps * J * G), y0, np.linspace(0.0, 10.0, 11))
    w = np.concatenate([y[:, :2], np.zeros((11, 1))], axis=1)
    F = klebsh_tisserand3_integral(w, y[:, 2:], J, eps)
    np.testing.assert_allclose(F - F[0], 0.0, atol=1e-10)
    assert np.ptp(F) < 1e-10 < np.ptp(0.5 * np.sum((J * w) ** 2, axis=1))
    # on |Gamma| = 1 it is the family integral with v1 = eps (J1 - J3) x^2/2, v2 = eps (J2 - J3) x^2/2
    fam = family3_integral(w, y[:, 2:], J, lambda x, s: 0.5 * eps * (J[0] - J[2]) * x ** 2,
                           lambda x, s: 0.5 * eps * (J[1] - J[2]) * x ** 2)
    np.testing.assert_allclose(F, fam - 0.5 * eps * J[0] * J[1], atol=1e-12)


# ======================================================================================= Suslov
def test_suslov3_explicit_solution_and_limits():
    J = np.array([[2.0, 0.1, 0.3], [0.1, 3.0, 0.4], [0.3, 0.4, 4.0]])
    rng = np.random.default_rng(2)
    w0 = np.concatenate([rng.normal(size=(4, 2)), np.zeros((4, 1))], axis=1)
    S = Suslov3Free(w0, J)
    ts = np.array([0.0, 0.7, 3.0, -2.0, 12.0])
    om = S.omega(ts)

    def f(t, w):
        x = np.array([w[0], w[1], 0.0])
        return np.linalg.solve(J[:2, :2], np.cross(J @ x, x)[:2])
    for b in range(4):
        ref = dop(f, w0[b, :2], ts)
        np.testing.assert_allclose(om[:, b, :2], ref, atol=TOL)
        far = dop(f, w0[b, :2], [60.0 / S.rate[b], -60.0 / S.rate[b]])
        np.testing.assert_allclose(far[0], S.w_plus[b, :2], atol=1e-9)
        np.testing.assert_allclose(far[1], S.w_minus[b, :2], atol=1e-9)
    np.testing.assert_allclose(S.energy, suslov3_energy(w0, J), rtol=1e-14)
    wp, wm = suslov3_asymptotic_points(J, S.energy)
    np.testing.assert_allclose(wp, S.w_plus)
    np.testing.assert_allclose(wm, -wp)
    np.testing.assert_allclose(wp[:, :2] @ J[:2, 2], 0.0, atol=1e-14)       # on the line <b, w> = 0
    np.testing.assert_allclose(S.omega(1e6), S.w_plus, atol=1e-15)
    # a fixed point is its own limit
    S2 = Suslov3Free(S.w_minus[0], J)
    np.testing.assert_allclose(S2.limit_plus, S.w_minus[0], atol=1e-14)


def _suslov_nd_rhs(I):
    """Multiplier form projected on D = span{E_in}: Gram matrix and [M, Omega] from matrices."""
    n = I.shape[0]
    E = []
    for i in range(n - 1):
        Ei = np.zeros((n, n))
        Ei[i, -1], Ei[-1, i] = 1.0, -1.0
        E.append(Ei)
    pair = lambda A, C: -0.5 * np.trace(A @ C)  # noqa: E731
    Jop = lambda X: I @ X + X @ I  # noqa: E731
    Gram = np.array([[pair(Ea, Jop(Eb)) for Eb in E] for Ea in E])

    def f(t, u):
        Om = sum(ui * Ei for ui, Ei in zip(u, E, strict=True))
        M = Jop(Om)
        r = np.array([pair(Ea, M @ Om - Om @ M) for Ea in E])
        return np.linalg.solve(Gram, r)
    return f


@pytest.mark.parametrize("n", [3, 4, 5])
def test_suslov_nd_reduced_equation_and_limits(n):
    rng = np.random.default_rng(60 + n)
    A = rng.normal(size=(n, n))
    I = A @ A.T / n + np.eye(n)
    f = _suslov_nd_rhs(I)
    u0 = rng.normal(size=(3, n - 1))
    for b in range(3):      # K u' = u (b.u) - |u|^2 b
        np.testing.assert_allclose(suslov_reduced_field(u0[b], I), f(0.0, u0[b]), atol=1e-13)
    wp, wm = suslov_limits(u0, I)
    h = suslov_energy(u0, I)
    np.testing.assert_allclose(wp, suslov_asymptotic_points(I, h)[0])
    for b in range(3):
        ys = dop(f, u0[b], [0.0, 2.0, 400.0, -400.0])
        np.testing.assert_allclose(ys[-2], wp[b], atol=1e-10)
        np.testing.assert_allclose(ys[-1], wm[b], atol=1e-10)
        np.testing.assert_allclose(suslov_energy(ys, I), h[b], rtol=1e-10)
        L = suslov_lyapunov(ys[[3, 0, 1, 2]], I)          # t = -400, 0, 2, 400
        assert np.all(np.diff(L) < 0.0)
    if n == 3:   # the 3-D vector form: omega = (-u_2, u_1), J = tr(I) Id - I
        J = np.trace(I) * np.eye(3) - I
        w0 = np.stack([-u0[:, 1], u0[:, 0], 0.0 * u0[:, 0]], axis=-1)
        S = Suslov3Free(w0, J)
        np.testing.assert_allclose(S.w_plus[:, :2], np.stack([-wp[:, 1], wp[:, 0]], -1), atol=1e-14)


# ============================================================================ 3-D first integrals
def _drift(F):
    return float(np.max(np.abs(F - F[0])))


def test_3d_integrals_along_the_flow():
    rng = np.random.default_rng(4)
    ts = np.linspace(0.0, 12.0, 13)
    G0 = unit(rng.normal(size=3))
    w0 = np.array([0.8, -0.5])

    def run(J, grad_V=None, eps=0.0):
        y = dop(suslov3_rhs(J, grad_V, eps), np.concatenate([w0, G0]), ts)
        return np.concatenate([y[:, :2], np.zeros((len(ts), 1))], axis=1), y[:, 2:]
    # Lagrange
    J = np.array([1.5, 1.5, 2.2])
    w, G = run(J, lambda G: np.array([0.0, 0.0, 1.3]))
    assert _drift(lagrange3_integral(w, G, J)) < 1e-10
    # Kharlamova
    J, Bk = np.array([1.0, 2.0, 2.5]), np.array([0.9, -0.6])
    w, G = run(J, lambda G: np.array([Bk[0], Bk[1], 0.0]))
    assert _drift(kharlamova3_integral(w, J, Bk)) < 1e-10
    # the family with genuinely nonlinear v1, v2 (weights J2 on v1, J1 on v2 as printed)
    v1 = lambda x, s: np.sin(x) + 0.3 * s ** 2  # noqa: E731
    v2 = lambda x, s: 0.5 * x ** 3 - 0.7 * s  # noqa: E731

    def grad_family(G):
        g1, g2, g3 = G
        s1 = g2 ** 2 + g3 ** 2
        d1x, d1s = np.cos(g1), 0.6 * s1
        d2x, d2s = 1.5 * g2 ** 2, -0.7
        return np.array([d1x + 2 * g1 * d2s, 2 * g2 * d1s + d2x, 2 * g3 * (d1s + d2s)])
    w, G = run(J, grad_family)
    assert _drift(family3_integral(w, G, J, v1, v2)) < 1e-10
    swapped = 0.5 * np.sum((J * w) ** 2, axis=1) + J[0] * v1(G[:, 0], G[:, 1] ** 2 + G[:, 2] ** 2) \
        + J[1] * v2(G[:, 1], G[:, 0] ** 2 + G[:, 2] ** 2)
    assert _drift(swapped) > 1e-3
    # gyroscopic, three potentials
    eps = 0.8
    w, G = run(J, None, eps)
    F2 = gyroscopic3_free_integrals(w, G, J, eps)
    assert F2.shape == (13, 2) and _drift(F2) < 1e-10
    w, G = run(J, lambda G: np.array([Bk[0], Bk[1], 0.0]), eps)
    assert _drift(gyroscopic3_linear_integral(w, G, J, eps, Bk)) < 1e-10
    for a in (np.array([1.0, 2.0, 0.5]), np.array([-0.5, 0.3, 0.9]), np.array([1.0, 1.0, 1.0])):
        w, G = run(J, lambda G, a=a: a * G, eps)
        F = gyroscopic3_quadratic_integral(w, G, J, eps, a)
        assert _drift(F) < 1e-10 * max(1.0, float(np.max(np.abs(F))))


# ============================================================================ the paper's misprints
def test_errata_4_4_lagrange_equation():
    """Unconstrained Lagrange body: (I_1+I_n) Omega_in' = (I_1-I_n) sum_k Omega_ik Omega_kn - B_n Gamma_i
    (the paper prints Omega_1k and B_n Gamma_n)."""
    rng = np.random.default_rng(0)
    n, I1, In, Bn = 5, 1.3, 0.7, 2.1
    I = np.diag([I1] * (n - 1) + [In])
    A = rng.normal(size=(n, n))
    Om = A - A.T
    G = unit(rng.normal(size=n))
    dV = np.zeros(n)
    dV[-1] = Bn
    M = I @ Om + Om @ I
    Mdot = M @ Om - Om @ M + np.outer(dV, G) - np.outer(G, dV)       # (2.2) without constraints
    lhs = Mdot[:-1, -1]                                             # = (I_1 + I_n) Omega_in'
    corrected = (I1 - In) * (Om @ Om)[:-1, -1] - Bn * G[:-1]
    printed = (I1 - In) * (Om[0] @ Om[:, -1]) - Bn * G[-1]
    np.testing.assert_allclose(lhs, corrected, atol=1e-13)
    assert np.max(np.abs(lhs - printed)) > 0.1
    # the first line is right: [M, Omega]_ij = (I_i - I_j) (Omega^2)_ij, which vanishes for i, j < n
    Id = np.diag(I)
    np.testing.assert_allclose(M @ Om - Om @ M, (Id[:, None] - Id[None, :]) * (Om @ Om), atol=1e-13)
    np.testing.assert_allclose(Mdot[:-1, :-1], 0.0, atol=1e-13)


def test_errata_4_7_kharlamova_coordinates():
    """(4.7) read with the missing d's: d omega_1/dt = gamma_n, d omega_i/dt = 0,
    d gamma_i/dt = gamma_n omega_i, d gamma_n/dt = -(B_1/(I_1+I_n))^2 gamma_1 omega_1
    - sum_i (B_i/(I_i+I_n))^2 (gamma_1+gamma_i)(omega_1+omega_i)."""
    n = 5
    I, B, u0, G0, dV = kharlamova_setup(n, 8)
    for b in range(3):
        y = np.concatenate([u0[b], G0[b]])
        yd = fk_rhs(I, dV)(0.0, y)
        h = 1e-6     # the coordinates are linear in the state: central differences are exact
        om_p, ga_p = kharlamova_coordinates(y[:n - 1] + h * yd[:n - 1], y[n - 1:] + h * yd[n - 1:], I, B)
        om_m, ga_m = kharlamova_coordinates(y[:n - 1] - h * yd[:n - 1], y[n - 1:] - h * yd[n - 1:], I, B)
        omd, gad = (om_p - om_m) / (2 * h), (ga_p - ga_m) / (2 * h)
        om, ga = kharlamova_coordinates(u0[b], G0[b], I, B)
        k = (B / (I[:-1] + I[-1])) ** 2
        np.testing.assert_allclose(omd, np.concatenate([[ga[-1]], np.zeros(n - 2)]), atol=1e-9)
        np.testing.assert_allclose(gad[:-1], ga[-1] * om, atol=1e-9)
        want = -k[0] * ga[0] * om[0] - np.sum(k[1:] * (ga[0] + ga[1:-1]) * (om[0] + om[1:]))
        np.testing.assert_allclose(gad[-1], want, atol=1e-9)


def test_errata_4_9_klebsh_tisserand_equation():
    """(4.3) with V = 1/2 sum B_i Gamma_i^2 gives (B_i - B_n) Gamma_i Gamma_n (the paper prints B_1 - B_n)."""
    n = 4
    I = np.array([1.0, 1.5, 2.0, 0.7])
    B = np.array([5.0, 4.0, 3.0, 1.0])
    G = unit([0.3, -0.5, 0.4, 0.6])
    u = np.array([0.2, -0.1, 0.3])
    udot = fk_rhs(I, lambda G: B * G)(0.0, np.concatenate([u, G]))[:n - 1]
    np.testing.assert_allclose((I[:-1] + I[-1]) * udot, (B[:-1] - B[-1]) * G[:-1] * G[-1], atol=1e-15)
    assert np.max(np.abs((I[:-1] + I[-1]) * udot - (B[0] - B[-1]) * G[:-1] * G[-1])) > 0.1


def test_errata_klebsh_tisserand_energy():
    """E = (B_n + sum F_i)/2 on |Gamma| = 1; the paper's (n B_n + sum F_i)/2 is off by (n-1) B_n/2."""
    for n in (3, 5):
        I, B, u0, G0, _ = kt_setup(n, n)
        E = 0.5 * np.sum((I[:-1] + I[-1]) * u0 ** 2, axis=-1) + 0.5 * np.sum(B * G0 ** 2, axis=-1)
        F = klebsh_tisserand_integrals(u0, G0, I, B)
        np.testing.assert_allclose(klebsh_tisserand_energy(F, B), E, rtol=1e-14)
        np.testing.assert_allclose(0.5 * (n * B[-1] + np.sum(F, axis=-1)) - E, 0.5 * (n - 1) * B[-1])


def test_errata_4_10_two_tori_condition_is_sharp():
    """sum_i c_i/(B_i - B_n) (first term c_1/(B_1 - B_n), not c_1/(B_i - B_n)) is the sup of 1 - Gamma_n^2
    on T_c = {F_1 = c_1, ..., F_{n-1} = c_{n-1}} (n - 1 conditions, not n)."""
    n = 3
    I, B = np.array([1.0, 1.7, 0.6]), np.array([3.0, 2.0, 1.0])
    rng = np.random.default_rng(3)
    c = np.array([0.9, 0.5])
    phi = rng.uniform(-np.pi, np.pi, size=(20000, n - 1))
    G2 = np.sum(c / (B[:-1] - B[-1]) * np.cos(phi) ** 2, axis=-1)
    assert np.max(G2) <= np.sum(c / (B[:-1] - B[-1])) + 1e-15
    np.testing.assert_allclose(np.max(G2), np.sum(c / (B[:-1] - B[-1])), rtol=1e-3)
    assert klebsh_tisserand_two_tori(c, B) == (np.sum(c / (B[:-1] - B[-1])) < 1.0)
    u = np.sqrt(c / (I[:-1] + I[-1])) * np.sin(phi[0])
    Gp = np.sqrt(c / (B[:-1] - B[-1])) * np.cos(phi[0])
    G = np.concatenate([Gp, [np.sqrt(1 - Gp @ Gp)]])
    np.testing.assert_allclose(klebsh_tisserand_integrals(u, G, I, B), c, rtol=1e-14)   # n - 1 integrals


# ==================================================================================== validation
def test_validation_errors():
    g3 = np.array([0.0, 0.0, 1.0])
    q, v = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    bad = [
        (lambda: SphericalPendulumMotion([1.0, 0.1, 0.0], v, g3, 1.0, 1.0), "q0 must be a unit vector"),
        (lambda: SphericalPendulumMotion(q, [0.1, 1.0, 0.0], g3, 1.0, 1.0), "tangent"),
        (lambda: SphericalPendulumMotion(q, v, [0.0, 0.0, 2.0], 1.0, 1.0), "gamma must be a unit vector"),
        (lambda: SphericalPendulumMotion(q, v, g3, 0.0, 1.0), "mass"),
        (lambda: SphericalPendulumMotion(q[:2], v[:2], g3, 1.0, 1.0), "q0 must have shape"),
        (lambda: SphericalPendulumMotion(q, v, [[0.0, 0.0, 1.0]], 1.0, 1.0), "gamma"),
        (lambda: SphericalPendulumMotion(q, [np.nan, 1.0, 0.0], g3, 1.0, 1.0), "NaN"),
        (lambda: SphericalPendulumMotion(np.tile(q, (2, 1)), np.tile(v, (3, 1)), g3, 1.0, 1.0), "broadcast"),
    ]
    I, B = np.array([1.0, 2.0, 3.0]), np.array([1.0, 0.5])
    u0, G0 = np.array([0.1, 0.2]), unit([0.3, 0.4, 0.5])
    bad += [
        (lambda: KharlamovaMotion(u0, G0, I, [1.0, 0.0]), "B_i != 0"),
        (lambda: KharlamovaMotion(u0, G0, I, [1.0, 0.5, 0.2]), "B must have shape"),
        (lambda: KharlamovaMotion(u0, [0.3, 0.4, 0.6], I, B), "Gamma must be a unit vector"),
        (lambda: KharlamovaMotion([0.1, 0.2, 0.3], G0, I, B), "u must have shape"),
        (lambda: KharlamovaMotion(u0, G0, [1.0, -2.0, 0.5], B), "I_i \\+ I_j > 0"),
        (lambda: KharlamovaMotion(u0, G0, [1.0, 2.0], [1.0]), "n >= 3"),
        (lambda: KharlamovaMotion(u0, G0, I, B).time_of(1e3), "oscillation interval"),
        (lambda: kharlamova_coordinates(u0, G0[:2], I, B), "Gamma must have shape"),
        (lambda: kharlamova_integrals(u0, I, [0.0, 1.0]), "B_i != 0"),
    ]
    Bk = np.array([3.0, 2.0, 1.0])
    bad += [
        (lambda: KlebshTisserandMotion(u0, G0, I, [3.0, 0.5, 1.0]), "B_i > B_n"),
        (lambda: KlebshTisserandMotion(u0, G0, I, [3.0, 2.0]), "B must have shape"),
        (lambda: KlebshTisserandMotion([2.0, 2.0], unit([0.9, 0.4, 0.1]), I, Bk), "4.10"),
        (lambda: KlebshTisserandMotion(u0, [1.0, 1.0, 1.0], I, Bk), "Gamma0 must be a unit vector"),
        (lambda: klebsh_tisserand_energy([1.0, 2.0, 3.0], Bk), "F must have shape"),
        (lambda: klebsh_tisserand_two_tori([-0.1, 0.2], Bk), "nonnegative"),
        (lambda: klebsh_tisserand_two_tori([0.1, 0.2], [1.0, 2.0, 3.0]), "B_i > B_n"),
        (lambda: klebsh_tisserand_frequencies(I, [1.0, 2.0, 3.0]), "B_i > B_n"),
    ]
    J = np.array([[2.0, 0.1, 0.3], [0.1, 3.0, 0.4], [0.3, 0.4, 4.0]])
    w0 = np.array([0.3, 0.2, 0.0])
    bad += [
        (lambda: Suslov3Free(w0, np.diag([1.0, 2.0, 3.0])), "eigenvector"),
        (lambda: Suslov3Free([0.3, 0.2, 0.1], J), "omega_3 = 0"),
        (lambda: Suslov3Free(w0, J + np.triu(np.ones((3, 3)), 1)), "symmetric"),
        (lambda: Suslov3Free(w0, -J), "positive definite"),
        (lambda: suslov3_asymptotic_points(J, -1.0), "energy must be nonnegative"),
        (lambda: suslov_limits([0.1, 0.2], np.diag([1.0, 2.0, 3.0])), "eigenspace"),
        (lambda: suslov_limits([0.1, 0.2, 0.3], J), "u0 must have shape"),
        (lambda: suslov_energy([0.1], np.eye(2)), "n >= 3"),
        (lambda: suslov_asymptotic_points(np.diag([1.0, -5.0, 1.0]), 1.0), "lambda_i \\+ lambda_j > 0"),
    ]
    Jd = np.array([1.0, 2.0, 3.0])
    bad += [
        (lambda: lagrange3_integral(w0, G0, Jd), "J1 = J2"),
        (lambda: lagrange3_integral(w0, G0, [1.0, 1.0]), "principal moments"),
        (lambda: kharlamova3_integral(w0, Jd, [1.0, 2.0, 3.0]), "B must be"),
        (lambda: gyroscopic3_quadratic_integral(w0, G0, Jd, 0.1, [1.0, 2.0]), "a must be"),
        (lambda: gyroscopic3_linear_integral([0.1, 0.2, 0.3], G0, Jd, 0.1, [1.0, 2.0]), "omega_3 = 0"),
        (lambda: klebsh_tisserand3_integral(w0, [1.0, 0.0, 1.0], Jd, 0.1), "unit vector"),
        (lambda: family3_integral(w0, G0, [1.0, 2.0, -3.0], np.add, np.add), "all > 0"),
    ]
    for call, msg in bad:
        with pytest.raises(ValueError, match=msg):
            call()


def test_suslov3_asymptotic_points_for_a_general_constraint_vector():
    # <a, w> = 0 with a not e3: the trajectory tends to w_+ = mu (a x J a) on its energy ellipse.
    from liesuslov.analytic import suslov3_asymptotic_points

    J = np.array([[2.0, 0.2, 0.1], [0.2, 3.0, -0.3], [0.1, -0.3, 4.0]])
    a = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    # so(3) coordinates x = (O12, O13, O23), w = (-x3, x2, -x1): <a, w> = <(-a3, a2, -a1), x>
    D = ls.Subspace.annihilator(ls.so(3), [[-a[2], a[1], -a[0]]])
    system = ls.SuslovSystem(ls.Inertia.from_principal_moments(J), constraints=D)
    x0 = np.array([0.4, -0.2, 0.0]) @ D.basis.T @ D.basis
    sol = ls.integrate(system, x0, (0.0, 400.0), method="rkmk45", rtol=1e-11, atol=1e-13,
                       t_eval=[100.0, 200.0, 400.0])
    x1 = sol.omega
    w1 = np.stack([-x1[..., 2], x1[..., 1], -x1[..., 0]], axis=-1)
    w0 = np.array([-x0[2], x0[1], -x0[0]])
    h = 0.5 * w0 @ J @ w0
    wp, wm = suslov3_asymptotic_points(J, h, a=a)
    assert abs(wp @ a) < 1e-15 and abs(0.5 * wp @ J @ wp - h) < 1e-14 * h
    dist = np.linalg.norm(w1 - wp, axis=-1)
    assert dist[0] > dist[1] > dist[2] and dist[2] < 1e-9  # an exponential approach to w_+
    np.testing.assert_allclose(wm, -wp)
    # a = e3 given explicitly is the default
    J3 = np.array([[2.0, 0.0, 0.3], [0.0, 3.0, 0.4], [0.3, 0.4, 4.0]])
    np.testing.assert_allclose(suslov3_asymptotic_points(J3, 1.0, a=[0, 0, 1.0])[0],
                               suslov3_asymptotic_points(J3, 1.0)[0], atol=1e-15)
    with pytest.raises(ValueError, match="a must be a unit vector"):
        suslov3_asymptotic_points(J, 1.0, a=[0.0, 0.0, 2.0])
    with pytest.raises(ValueError, match="a is an eigenvector of J"):
        suslov3_asymptotic_points(np.diag([1.0, 2.0, 3.0]), 1.0, a=[0.0, 1.0, 0.0])


def test_euler_top_at_the_middle_axis_is_steady_or_refused():
    """The steady rotation about the middle axis (the separatrix's end) gave NaN states; exactly on the axis it
    is that rotation, off it by less than rounding resolves a ValueError."""
    from liesuslov.analytic.euler_top import EulerTop

    top = EulerTop([1.0, 2.0, 3.0], [[0.3, 0.2, 1.0], [0.0, 2.0, 0.0]])
    w = top.state([0.0, 1.0, 50.0])
    assert np.array_equal(w[:, 1], np.tile([0.0, 2.0, 0.0], (3, 1))) and np.all(np.isfinite(w))
    with pytest.raises(ValueError, match="middle axis"):
        EulerTop([1.0, 2.0, 3.0], [1e-9, 1.0, 0.0])
