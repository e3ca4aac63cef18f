"""The vectorised numpy solve: a trajectory's numbers are the same, bit for bit, alone and in any batch.

Each scene mixes trajectories that part ways early: one runs into a region where the field is NaN (a
potential whose gradient is NaN there) and fails, one ends on a terminal event (a per-trajectory plane
only it crosses), one spins fast and, from a large first step, is rejected many times; the others run to
t1. The batch is compared with every trajectory alone, with the batch reversed and with a sub-batch:
output at t_eval (served by the continuous extension), status, failure time, counts, events.
"""

from __future__ import annotations

import numpy as np
import pytest

import liesuslov as ls
from liesuslov.integrators import LinearEvent

T1 = 4.0
T_EVAL = np.linspace(0.0, T1, 9)
METHODS = [("rkmk4", {"h": 0.05}), ("rkmk45", {"rtol": 1e-8, "first_step": 2.0}),
           ("rkmk853", {"rtol": 1e-9, "first_step": 2.0})]


def nan_potential(n: int, thr: float):
    """``V = b . Gamma`` with a NaN gradient where ``|Gamma_0| > thr``."""
    b = np.linspace(1.0, 2.0, n)

    def V(G):
        return G @ b

    def grad(G):
        return np.where(np.abs(G[..., :1]) > thr, np.nan, np.broadcast_to(b, G.shape))

    return ls.Potential(V, grad)


def mixed_scene(n: int):
    """A Suslov (Fedorov–Kozlov) body in SO(n) and five trajectories: 0 and 4 plain, 1 into the NaN region
    (dGamma_0/dt = -u_0 Gamma_n > 0 from 0.05 below it), 2 stopped by a terminal event, 3 fast."""
    I = np.diag(np.linspace(1.0, 2.0, n))
    thr = 0.95 if n == 3 else 0.8
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), potential=nan_potential(n, thr))
    rng = np.random.default_rng(n)
    B = 5
    u = 0.5 * rng.standard_normal((B, n - 1))
    u[3] *= 10.0
    u[1, 0] = 2.0
    O = np.zeros((B, n, n))
    O[:, : n - 1, n - 1] = u
    O[:, n - 1, : n - 1] = -u
    G = rng.standard_normal((B, n))
    G[:, 0] = 0.0
    G /= np.linalg.norm(G, axis=1, keepdims=True)
    G[1, 0], G[1, -1] = thr - 0.05, -0.3  # Gamma_0 grows at -u_0 Gamma_n = 0.6
    G[1, 1:-1] = np.sqrt((1.0 - G[1, 0] ** 2 - G[1, -1] ** 2) / (n - 2))
    offset = np.full(B, 2.0)  # |Gamma_1| <= 1: only trajectory 2 reaches its plane, where Gamma_1 goes
    offset[2] = G[2, 1] - 0.02 * np.sign(u[2, 1] * G[2, -1])
    stop = LinearEvent(Gamma=np.eye(n)[1], offset=offset, terminal=True)
    back = LinearEvent(Gamma=np.eye(n)[-1], offset=G[:, -1].copy())  # returns to the initial Gamma_n (from t0 on)
    return system, O, G, [stop, back]


def assert_same(one, batch, b):
    """Trajectory b of ``batch`` is ``one`` (a solution of one trajectory, or of a batch at ``b``), bit for bit."""
    sel = (slice(None), b)
    for name in ("omega", "Gamma", "g"):
        x, y = getattr(one, name), getattr(batch, name)[sel]
        assert np.array_equal(x.reshape(y.shape), y, equal_nan=True), name
    assert int(np.reshape(one.status, -1)[0]) == batch.status[b]
    for key in ("t_stop", "trajectory_nfev", "trajectory_steps", "trajectory_rejected"):
        assert np.reshape(one.stats[key], -1)[0] == batch.stats[key][b], key
    for e1, eb in zip(one.events, batch.events, strict=True):
        mine = eb.index == b
        assert np.array_equal(e1.t, eb.t[mine])
        assert np.array_equal(e1.omega, eb.omega[mine]) and np.array_equal(e1.g, eb.g[mine])


SCENES = [(3, "exp", "so3"), (4, "exp", "so4"), (5, "cayley", "dense"), (9, "exp", "dense")]


@pytest.mark.parametrize("method,kw", METHODS, ids=[m for m, _ in METHODS])
@pytest.mark.parametrize("n,chart,kind", SCENES, ids=[f"{k}-{c}-n{n}" for n, c, k in SCENES])
def test_mixed_batch_equals_alone_bitwise(n, chart, kind, method, kw):
    system, O, G, events = mixed_scene(n)

    def solve(rows):
        sl = np.asarray(rows)
        return ls.integrate(system, O[sl], (0.0, T1), Gamma0=G[sl], reconstruct=True, method=method, chart=chart,
                            t_eval=T_EVAL, events=[LinearEvent(Gamma=e.Gamma, offset=e.offset[sl], terminal=e.terminal)
                                                   for e in events], backend="numpy", **kw)

    batch = solve(range(5))
    if n < 9:
        from liesuslov.integrators.charts import make_chart

        assert make_chart(chart, n, skew=True, order=4).default_kernel(system.model()) == kind
    # the scene does what it is meant to: a failure, a terminal event, the fast one rejected many times
    assert batch.status.tolist() == [0, -1, 1, 0, 0] or (n == 3 and batch.status.tolist()[:3] == [0, -1, 1])
    assert batch.stats["t_stop"][1] < T1 and batch.stats["t_stop"][2] < T1
    if method != "rkmk4":
        assert batch.stats["trajectory_rejected"][3] >= 3
    for b in range(5):
        assert_same(solve(b), batch, b)  # one trajectory (a batch of one, on float lanes in the so(3)/so(4) kernels)
    back = solve(range(4, -1, -1))
    for b in range(5):
        assert_same(_pick(back, 4 - b), batch, b)
    part = solve([3, 1])
    assert_same(_pick(part, 0), batch, 3)
    assert_same(_pick(part, 1), batch, 1)


class _pick:
    """Trajectory ``b`` of a batch solution, shaped as a solution of one (for :func:`assert_same`)."""

    def __init__(self, sol, b):
        for name in ("omega", "Gamma", "g"):
            setattr(self, name, getattr(sol, name)[:, b])
        self.status = sol.status[b]
        self.stats = {key: sol.stats[key][b] for key in ("t_stop", "trajectory_nfev", "trajectory_steps",
                                                          "trajectory_rejected")}
        self.events = [_Events(e, b) for e in sol.events]


class _Events:
    def __init__(self, rec, b):
        mine = rec.index == b
        self.t, self.omega, self.g = rec.t[mine], rec.omega[mine], rec.g[mine]


@pytest.mark.parametrize("method,kw", METHODS[1:], ids=[m for m, _ in METHODS[1:]])
@pytest.mark.parametrize("n", [5, 16], ids=["coords", "lowrank"])
def test_coords_and_lowrank_batch_equals_alone(n, method, kw):
    """The so(n) coordinates kernel and the low-rank Fedorov–Kozlov kernel (exponential chart)."""
    I = np.diag(np.linspace(1.0, 2.0, n))
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), potential=ls.QuadraticPotential(np.linspace(4.0, 1.0, n)))
    rng = np.random.default_rng(0)
    u = 0.4 * rng.standard_normal((3, n - 1))
    u[1] *= 8.0
    O = np.zeros((3, n, n))
    O[:, : n - 1, n - 1] = u
    O[:, n - 1, : n - 1] = -u
    G = rng.standard_normal((3, n))
    G /= np.linalg.norm(G, axis=1, keepdims=True)
    kw = dict(reconstruct=True, method=method, t_eval=np.linspace(0.0, 2.0, 5), backend="numpy", **kw)
    batch = ls.integrate(system, O, (0.0, 2.0), Gamma0=G, **kw)
    assert batch.success and batch.stats["trajectory_rejected"][1] >= 3
    for b in range(3):
        assert_same(ls.integrate(system, O[b], (0.0, 2.0), Gamma0=G[b], **kw), batch, b)


def test_one_trajectory_records_every_step_and_matches_its_batch():
    """Without t_eval one trajectory reports every accepted step; its last state is its batch's at t1."""
    system, O, G, _ = mixed_scene(4)
    kw = dict(reconstruct=True, method="rkmk45", rtol=1e-8, backend="numpy")
    one = ls.integrate(system, O[0], (0.0, T1), Gamma0=G[0], **kw)
    batch = ls.integrate(system, O[[4, 0]], (0.0, T1), Gamma0=G[[4, 0]], **kw)
    assert one.t.size == one.stats["steps"] + 1 and one.t[-1] == T1
    assert np.array_equal(one.g[-1], batch.g[-1, 1]) and np.array_equal(one.omega[-1], batch.omega[-1, 1])


def test_progress_counts_every_trajectory_once(monkeypatch):
    """``done(n)`` reports each trajectory once, as it ends (failed, stopped by an event, or at t1)."""
    import importlib

    from liesuslov.integrators import solve_numpy

    front = importlib.import_module("liesuslov.integrators.integrate")

    system, O, G, events = mixed_scene(4)
    seen = []
    real = solve_numpy.solve
    monkeypatch.setattr(front, "_run", lambda solver, P, progress: real(P, done=seen.append))
    sol = ls.integrate(system, O, (0.0, T1), Gamma0=G, method="rkmk45", events=events, backend="numpy")
    assert sol.status.tolist() == [0, -1, 1, 0, 0]
    assert sum(seen) == 5 and all(n > 0 for n in seen) and len(seen) >= 3
