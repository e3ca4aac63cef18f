"""Ensembles (ls.ensemble): the numbers of one integrate call whatever the executor and chunk size,
stores, samplers, reductions, lost workers, pickling, xarray export, bad input."""

from __future__ import annotations

import importlib.util
import json
import os
import pickle
import sys
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

import liesuslov as ls
from liesuslov.ensembles import SAMPLER_BLOCK, Perturbation, draw, ensemble, open_ensemble

T_SPAN = (0.0, 1.5)
FIXED = {"method": "rkmk4", "h": 0.01}
ADAPTIVE = {"method": "rkmk45", "rtol": 1e-8, "atol": 1e-10}


# ---------------------------------------------------------------------------- scenes (module level: they pickle)
def _system():
    J = ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0]))
    return ls.SuslovSystem(J, potential=ls.LinearPotential([0.2, 0.0, 1.0]))


def _initial(shape=(5, 4), seed=0):
    system = _system()
    rng = np.random.default_rng(seed)
    # widely different speeds, so that an adaptive method takes different steps per trajectory
    Omega0 = (rng.normal(size=shape + (2,)) * rng.uniform(0.1, 3.0, size=shape + (1,))) @ system.constraints.basis
    Gamma0 = rng.normal(size=shape[-1:] + (3,))  # broadcast against the first batch axis
    Gamma0 /= np.linalg.norm(Gamma0, axis=-1, keepdims=True)
    return system, Omega0, Gamma0


def _assert_same(ens, sol, final_only=False):
    """Bitwise equal (a trajectory's numbers do not depend on its batch mates, so chunks change nothing)."""
    rows = slice(-1, None) if final_only else slice(None)
    assert np.array_equal(ens.t, sol.t[rows])
    for name in ("omega", "xi", "Gamma", "g", "Omega"):
        a, b = getattr(ens, name), getattr(sol, name)
        assert (a is None) == (b is None), name
        if a is not None:
            assert a.shape == b[rows].shape, name
            # equal_nan: every value after a terminal event stopped a trajectory is NaN
            assert np.array_equal(a, b[rows], equal_nan=True), \
                f"{name}: max difference {np.nanmax(np.abs(a - b[rows]))}"
    assert np.shape(sol.status) == ens.status.shape == sol.omega.shape[1:-1]  # a status per trajectory
    assert np.array_equal(ens.status, sol.status)
    assert ens.success == bool(np.all(np.asarray(sol.status) >= 0))


@dataclass(frozen=True)
class KillOnce:
    """A reduce that kills its own process the first time any worker runs it (marker file), then passes."""

    marker: str

    def __call__(self, sol):
        try:
            fd = os.open(self.marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            return sol
        os.close(fd)
        os._exit(1)


def uniform_sampler(rng, size):
    """Omega0 uniform in the constraint plane of the test system, Gamma0 uniform on the sphere."""
    system = _system()
    Omega0 = rng.uniform(-1.0, 1.0, size=(size, 2)) @ system.constraints.basis
    G = rng.normal(size=(size, 3))
    return {"Omega0": Omega0, "Gamma0": G / np.linalg.norm(G, axis=-1, keepdims=True)}


def fail_short_chunks(sol):
    """A module-level reduce that fails (deterministically) on every chunk of fewer than 7 trajectories."""
    if sol.omega.shape[1] < 7:
        raise RuntimeError("a short chunk")
    return sol


def shifted_final(sol):
    """A module-level reduce: the final row only, as a Solution."""
    from dataclasses import replace

    return replace(sol, t=sol.t[-1:], xi=sol.xi[-1:], omega=sol.omega[-1:], Gamma=sol.Gamma[-1:])


# ---------------------------------------------------------------------------- in process
@pytest.mark.parametrize("chunk_size", [None, 1, 3, 7, 20])
def test_fixed_step_equals_one_integrate_call(chunk_size):
    system, Omega0, Gamma0 = _initial()
    sol = ls.integrate(system, Omega0, T_SPAN, Gamma0=Gamma0, t_eval=[0.0, 0.5, 1.5], **FIXED)
    ens = ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, t_eval=[0.0, 0.5, 1.5], chunk_size=chunk_size, **FIXED)
    _assert_same(ens, sol)
    assert ens.stats["chunks"] == (1 if chunk_size is None else -(-20 // chunk_size))
    assert ens.stats["failed_chunks"] == [] and ens.complete


@pytest.mark.parametrize("chunk_size", [1, 6])
def test_adaptive_equals_one_integrate_call(chunk_size):
    system, Omega0, Gamma0 = _initial()
    sol = ls.integrate(system, Omega0, T_SPAN, Gamma0=Gamma0, t_eval=[0.0, 1.5], **ADAPTIVE)
    ens = ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, chunk_size=chunk_size, **ADAPTIVE)
    _assert_same(ens, sol)


def test_reconstruction_and_matrix_input_and_backward_time():
    system, Omega0, Gamma0 = _initial((6,))
    O = system.algebra.hat(Omega0)  # matrices (6, 3, 3)
    kw = dict(Gamma0=Gamma0[0], reconstruct=True, **FIXED)
    sol = ls.integrate(system, O, (1.0, -0.5), t_eval=[1.0, -0.5], **kw)
    ens = ensemble(system, O, (1.0, -0.5), chunk_size=4, **kw)
    _assert_same(ens, sol)
    assert ens.g.shape == (2, 6, 3, 3)


def test_reduce_final_and_callable():
    system, Omega0, Gamma0 = _initial()
    sol = ls.integrate(system, Omega0, T_SPAN, Gamma0=Gamma0, t_eval=[0.0, 1.5], **FIXED)
    for reduce in ("final", shifted_final):
        ens = ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, chunk_size=8, reduce=reduce, **FIXED)
        _assert_same(ens, sol, final_only=True)


def test_stats_sum_the_chunks_counts():
    system, Omega0, Gamma0 = _initial()
    many = ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, chunk_size=5, **FIXED).stats
    O, G = Omega0.reshape(20, 3), np.broadcast_to(Gamma0, (5, 4, 3)).reshape(20, 3)
    parts = [ls.integrate(system, O[a:a + 5], T_SPAN, Gamma0=G[a:a + 5], **FIXED).stats for a in range(0, 20, 5)]
    for key in ("steps", "nfev", "rejected"):
        assert many[key] == sum(p[key] for p in parts), key
    assert many["method"] == "rkmk4" and many["batch"] == 20 and many["executor"] == "none"


def test_events_come_back_as_in_a_solution(pool, tmp_path):
    """The crossings of events= were computed on the workers and dropped; now ens.events is a Solution's."""
    system, Omega0, Gamma0 = _initial()
    stop = ls.integrators.gamma_crossing(3, index=0)
    stop.terminal = True
    # and a plane per trajectory (coefficients with the batch axes: each chunk gets its rows of them)
    events = [stop, ls.integrators.gamma_crossing(3, index=1),
              ls.integrators.return_plane(system, Omega0, np.broadcast_to(Gamma0, Omega0.shape[:-1] + (3,)))]
    span = (0.0, 20.0)
    sol = ls.integrate(system, Omega0, span, Gamma0=Gamma0, t_eval=list(span), events=events, **FIXED)
    assert sum(len(r) for r in sol.events) > 20 and np.any(sol.status == 1)
    runs = [ensemble(system, Omega0, span, Gamma0=Gamma0, chunk_size=cs, executor=ex, store=st, events=events,
                     **FIXED) for cs, ex, st in ((None, None, None), (3, pool, None), (7, None, tmp_path / "s"))]
    for ens in (*runs, open_ensemble(tmp_path / "s"), pickle.loads(pickle.dumps(runs[-1])), runs[1].to_solution()):
        _assert_same(ens, sol)
        assert len(ens.events) == 3
        for a, b in zip(ens.events, sol.events, strict=True):
            for f in ("t", "index", "omega", "Gamma", "g"):
                x, y = getattr(a, f), getattr(b, f)
                assert (x is None) == (y is None) and (x is None or np.array_equal(x, y)), f
            assert a.Omega.shape == b.Omega.shape
    assert ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, **FIXED).events == []
    with pytest.raises(TypeError, match="dense_output"):
        ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, dense_output=True, **FIXED)


# ---------------------------------------------------------------------------- a process pool
@pytest.fixture(scope="module")
def pool():
    with ProcessPoolExecutor(2) as ex:
        yield ex


@pytest.mark.parametrize("chunk_size", [3, 11])
@pytest.mark.parametrize("opts", [FIXED, ADAPTIVE], ids=["fixed", "adaptive"])
def test_process_pool_equals_one_integrate_call(pool, chunk_size, opts):
    system, Omega0, Gamma0 = _initial()
    sol = ls.integrate(system, Omega0, T_SPAN, Gamma0=Gamma0, t_eval=[0.0, 1.5], **opts)
    ens = ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, chunk_size=chunk_size, executor=pool, **opts)
    _assert_same(ens, sol)
    assert ens.stats["executor"] == "ProcessPoolExecutor"


def test_a_lost_process_pool_is_a_failed_status_not_a_crash(tmp_path):
    system, Omega0, Gamma0 = _initial()
    with ProcessPoolExecutor(1) as ex:  # its own pool: a killed worker breaks the whole pool
        ens = ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, chunk_size=5, executor=ex, retries=1,
                       reduce=KillOnce(str(tmp_path / "killed")), **FIXED)
    assert not ens.success
    failed = ens.stats["failed_chunks"]
    assert failed and all("BrokenProcessPool" in f["error"] for f in failed)
    flat = ens.status.reshape(-1)
    for f in failed:
        assert np.all(flat[f["start"]:f["stop"]] == -1)
        assert np.all(np.isnan(ens.omega.reshape(2, 20, 3)[:, f["start"]:f["stop"]]))
    assert "chunks failed" in ens.message


# ---------------------------------------------------------------------------- samplers
def test_sampler_is_reproducible_across_chunks_executors_and_equals_integrate(pool):
    system = _system()
    n = SAMPLER_BLOCK + 300  # more than one block, not a multiple of it
    span = (0.0, 0.1)  # short: many trajectories
    runs = [ensemble(system, None, span, sampler=uniform_sampler, n=n, seed=7, chunk_size=cs, executor=ex,
                     reduce="final", **FIXED) for cs, ex in ((None, None), (100, None), (700, pool), (2000, pool))]
    init = draw(uniform_sampler, n, seed=7)
    sol = ls.integrate(system, init["Omega0"], span, Gamma0=init["Gamma0"], t_eval=list(span), **FIXED)
    for ens in runs:
        _assert_same(ens, sol, final_only=True)
        assert ens.stats["seed"] == 7
    # block j is drawn from SeedSequence(seed).spawn(...)[j]; a prefix does not depend on n
    child = np.random.SeedSequence(7).spawn(2)[1]
    expect = uniform_sampler(np.random.default_rng(child), SAMPLER_BLOCK)["Omega0"][:300]
    assert np.array_equal(init["Omega0"][SAMPLER_BLOCK:], expect)
    assert np.array_equal(draw(uniform_sampler, 10, seed=7)["Omega0"], init["Omega0"][:10])


def test_perturbation_sampler_stays_in_D_and_on_the_sphere():
    system, Omega0, Gamma0 = _initial((1,))
    s = Perturbation.around(system, Omega0[0], Gamma0=Gamma0[0], scale=0.1)
    pickle.loads(pickle.dumps(s))
    init = draw(s, 50, seed=1)
    D = system.constraints
    assert np.allclose(D.project(init["Omega0"]), init["Omega0"], atol=1e-14)
    assert np.allclose(np.linalg.norm(init["Gamma0"], axis=-1), 1.0, atol=1e-14)
    assert 0.01 < np.std(init["Omega0"] - Omega0[0]) < 1.0
    ens = ensemble(system, None, T_SPAN, sampler=s, n=50, seed=1, **FIXED)
    assert ens.success and ens.omega.shape == (2, 50, 3)


# ---------------------------------------------------------------------------- stores
def test_store_round_trip_and_partial_store(tmp_path):
    system, Omega0, Gamma0 = _initial()
    kw = dict(Gamma0=Gamma0, reconstruct=True, **FIXED)
    mem = ensemble(system, Omega0, T_SPAN, chunk_size=6, **kw)
    disk = ensemble(system, Omega0, T_SPAN, chunk_size=6, store=tmp_path / "s", **kw)
    back = open_ensemble(tmp_path / "s")
    sol = ls.integrate(system, Omega0, T_SPAN, t_eval=list(T_SPAN), **kw)
    for ens in (disk, back, pickle.loads(pickle.dumps(back))):
        assert ens.store == tmp_path / "s" and ens.complete
        _assert_same(ens, mem.to_solution())
        assert ens.stats["steps"] == mem.stats["steps"]
        # statistics integrate reports per trajectory (arrays of the batch shape) come back assembled
        for name, v in sol.stats.items():
            if isinstance(v, np.ndarray) and v.shape == (5, 4):
                assert np.array_equal(ens.stats[name], v) and np.array_equal(mem.stats[name], v), name
    manifest = json.loads((tmp_path / "s" / "manifest.json").read_text())
    assert manifest["complete"] and manifest["batch_shape"] == [5, 4] and len(manifest["bounds"]) == 4
    assert [a for a, _, _ in back.chunks()] == [0, 6, 12, 18]
    # a partial store: a missing chunk reads as status -1 and NaN, with a message
    (tmp_path / "s" / "chunk-000001.npz").unlink()
    part = open_ensemble(tmp_path / "s")
    assert not part.complete and not part.success and "1 of 4 chunks missing" in part.message
    assert "successfully" not in part.message  # (the finished run's message said so, below the missing count)
    flat = part.status.reshape(-1)
    assert np.all(flat[6:12] == -1) and np.all(flat[:6] == 0) and np.all(flat[12:] == 0)
    om = part.omega.reshape(2, 20, 3)
    assert np.all(np.isnan(om[:, 6:12])) and np.array_equal(om[:, 12:], mem.omega.reshape(2, 20, 3)[:, 12:])
    with pytest.raises(ValueError, match="overwrite=True"):
        ensemble(system, Omega0, T_SPAN, chunk_size=6, store=tmp_path / "s", **kw)
    again = ensemble(system, Omega0, T_SPAN, chunk_size=6, store=tmp_path / "s", overwrite=True, **kw)
    assert again.complete
    with pytest.raises(FileNotFoundError, match="manifest.json"):
        open_ensemble(tmp_path)


def test_two_runs_on_one_store_at_once_do_not_mix(tmp_path, monkeypatch):
    """Two runs started on one store at the same moment both passed the check for a manifest, both reported
    success, and the store held chunks of both (an audit: 1664 of one seed, 384 of the other). The store is
    now claimed by creating its manifest exclusively; a run that replaces it with overwrite=True while another
    runs is detected by the run id every chunk file carries."""
    from liesuslov.ensembles import run as run_module
    from liesuslov.ensembles import store as store_module

    system, Omega0, Gamma0 = _initial()
    kw = dict(Gamma0=Gamma0, chunk_size=6, **FIXED)
    store = tmp_path / "s"
    real_prepare = run_module._prepare_store

    def other_run_claims_first(st, overwrite):  # the other run creates its manifest right after this one's check
        root = real_prepare(st, overwrite)
        monkeypatch.setattr(run_module, "_prepare_store", real_prepare)  # (the other run is not interrupted)
        ensemble(system, Omega0, T_SPAN, store=root, **kw)
        return root

    monkeypatch.setattr(run_module, "_prepare_store", other_run_claims_first)
    with pytest.raises(ValueError, match="another run started on it at the same time"):
        ensemble(system, 2 * Omega0, T_SPAN, store=store, **kw)
    monkeypatch.undo()
    first = open_ensemble(store)
    assert first.complete and np.array_equal(first.omega, ensemble(system, Omega0, T_SPAN, **kw).omega)

    # replaced during the run (another run with overwrite=True, to its end): this run stops before writing
    # another chunk into it, and the other run's store is intact
    real_write = store_module._write_shard
    calls = []

    def other_run_replaces_the_store(root, i, payload, run):
        real_write(root, i, payload, run)
        calls.append(i)
        if len(calls) == 1:
            ensemble(system, 2 * Omega0, T_SPAN, store=root, overwrite=True, **kw)

    monkeypatch.setattr(run_module, "_write_shard", other_run_replaces_the_store)
    with pytest.raises(RuntimeError, match="was replaced by another run"):
        ensemble(system, Omega0, T_SPAN, store=store, overwrite=True, **kw)
    monkeypatch.undo()
    other = open_ensemble(store)
    assert other.complete and np.array_equal(other.omega, ensemble(system, 2 * Omega0, T_SPAN, **kw).omega)
    # a finished store with one chunk file of another run in it: refused when that chunk is read
    ensemble(system, Omega0, T_SPAN, store=tmp_path / "a", **kw)
    ensemble(system, Omega0, T_SPAN, store=tmp_path / "b", **kw)
    (tmp_path / "b" / "chunk-000002.npz").replace(tmp_path / "a" / "chunk-000002.npz")
    mixed = open_ensemble(tmp_path / "a")
    with pytest.raises(ValueError, match="chunk-000002.npz was written by another run"):
        _ = mixed.omega
    # ... and one without a run id (an older version's) under a manifest with one
    path = tmp_path / "b" / "chunk-000001.npz"
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(arrays["__meta__"].tobytes().decode())
    del meta["run"]
    arrays["__meta__"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    np.savez(path, **arrays)
    with pytest.raises(ValueError, match="chunk-000001.npz was written by another run"):
        _ = open_ensemble(tmp_path / "b").omega


def test_a_store_killed_mid_run_reopens_with_the_counts_of_the_computed_trajectories(tmp_path):
    """SIGKILL after 3 of 20 chunks: the reopened store has nfev/steps/rejected (as a Solution's), summed over
    the 15 trajectories computed, and the run's seed (drawn fresh: seed=None), so its initial data can be redrawn."""
    import signal
    import subprocess

    root = Path(__file__).resolve().parents[1]
    store = tmp_path / "killed"
    script = f"""
import os, signal
from tests.test_ensemble import FIXED, _system, uniform_sampler
from liesuslov.ensembles import ensemble
calls = []
def kill_at_the_fourth_chunk(sol):  # executor=None: chunk i is written to the store before chunk i + 1 runs
    calls.append(1)
    if len(calls) == 4:
        os.kill(os.getpid(), signal.SIGKILL)
    return sol
ensemble(_system(), None, (0.0, 0.2), sampler=uniform_sampler, n=100, chunk_size=5, store={str(store)!r},
         reduce=kill_at_the_fourth_chunk, t_eval=[0.0, 0.2], **FIXED)
"""
    res = subprocess.run([sys.executable, "-c", script], cwd=root, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONPATH": str(root)})
    assert res.returncode == -signal.SIGKILL, res.stderr[-3000:]
    ens = open_ensemble(store)
    assert not ens.complete and "17 of 20 chunks missing" in ens.message
    flat = ens.status.reshape(-1)
    assert np.all(flat[:15] == 0) and np.all(flat[15:] == -1)
    st = ens.stats
    assert {"nfev", "steps", "rejected"} <= set(st) and st["steps"] == 15 * 20 and st["nfev"] > 0
    assert st["chunks"] == 20 and st["batch"] == 100 and st["method"] == "rkmk4" and st["failed_chunks"] == []
    init = draw(uniform_sampler, 100, seed=st["seed"])
    O, G = init["Omega0"][:15], init["Gamma0"][:15]
    parts = [ls.integrate(_system(), O[a:a + 5], (0.0, 0.2), Gamma0=G[a:a + 5], t_eval=[0.0, 0.2], **FIXED)
             for a in range(0, 15, 5)]
    for key in ("nfev", "steps", "rejected"):
        assert st[key] == sum(p.stats[key] for p in parts), key
    assert np.array_equal(ens.omega[:, :15], np.concatenate([p.omega for p in parts], axis=1))
    assert np.all(np.isnan(ens.omega[:, 15:]))


def test_a_finished_store_with_failed_chunks_is_complete_and_counts_are_always_there(tmp_path):
    system, Omega0, Gamma0 = _initial()  # 20 trajectories in chunks of 7, 7, 6: the last one fails
    kw = dict(Gamma0=Gamma0, chunk_size=7, reduce=fail_short_chunks, **FIXED)
    mem = ensemble(system, Omega0, T_SPAN, **kw)
    disk = ensemble(system, Omega0, T_SPAN, store=tmp_path / "s", **kw)
    back = open_ensemble(tmp_path / "s")
    for ens in (mem, disk, back):
        assert ens.complete and not ens.success, ens.message  # finished: the failed chunk is not "missing"
        assert "missing" not in ens.message and "1 of 3 chunks failed" in ens.message
        assert [f["chunk"] for f in ens.stats["failed_chunks"]] == [2]
        assert np.all(ens.status.reshape(-1)[14:] == -1) and np.all(ens.status.reshape(-1)[:14] == 0)
        assert ens.stats["steps"] == mem.stats["steps"] == 14 * 150
    # every chunk failed: the counts are still there, zero
    alone = ensemble(system, Omega0[0], T_SPAN, **kw)
    assert alone.stats["failed_chunks"] and all(alone.stats[k] == 0 for k in ("nfev", "steps", "rejected"))


def test_a_store_from_an_interrupted_run_opens(tmp_path):
    system, Omega0, Gamma0 = _initial()
    ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, chunk_size=5, store=tmp_path, **FIXED)
    man = json.loads((tmp_path / "manifest.json").read_text())
    for key in ("t", "tails", "meta", "stats"):  # as written before the first chunk finished
        man.pop(key)
    man["complete"] = False
    (tmp_path / "manifest.json").write_text(json.dumps(man))
    (tmp_path / "chunk-000003.npz").unlink()
    part = open_ensemble(tmp_path)
    assert part.omega.shape == (2, 5, 4, 3) and part.algebra_name == "so(3)"
    assert np.count_nonzero(part.status == -1) == 5
    for key in ("nfev", "steps", "rejected"):  # summed over the 3 chunks in the store
        assert part.stats[key] == int(np.sum(part.stats["trajectory_" + key])), key
    assert part.stats["steps"] == 15 * 150


# ---------------------------------------------------------------------------- pickling and xarray
def test_solution_and_ensemble_pickle():
    system, Omega0, Gamma0 = _initial()
    sol = ls.integrate(system, Omega0, T_SPAN, Gamma0=Gamma0, t_eval=[0.0, 1.5], **FIXED)
    back = pickle.loads(pickle.dumps(sol))
    assert np.array_equal(back.omega, sol.omega) and back.stats.keys() == sol.stats.keys()
    assert all(np.array_equal(back.stats[k], v) for k, v in sol.stats.items() if k != "wall_time")
    ens = ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, chunk_size=7, **FIXED)
    _assert_same(pickle.loads(pickle.dumps(ens)), sol)


def test_systems_pickle_also_after_integrate():
    system, Omega0, Gamma0 = _initial()
    ls.integrate(system, Omega0, T_SPAN, Gamma0=Gamma0, **FIXED)
    back = pickle.loads(pickle.dumps(system))
    a = ls.integrate(back, Omega0, T_SPAN, Gamma0=Gamma0, t_eval=[1.5], **FIXED)
    b = ls.integrate(system, Omega0, T_SPAN, Gamma0=Gamma0, t_eval=[1.5], **FIXED)
    assert np.array_equal(a.omega, b.omega)


def test_to_xarray():
    xr = pytest.importorskip("xarray")
    system, Omega0, Gamma0 = _initial()
    sol = ls.integrate(system, Omega0, T_SPAN, Gamma0=Gamma0, reconstruct=True, t_eval=[0.0, 1.0, 1.5], **FIXED)
    ds = sol.to_xarray()
    assert isinstance(ds, xr.Dataset)
    assert ds["omega"].dims == ("time", "batch_0", "batch_1", "omega_component")
    assert ds["g"].dims == ("time", "batch_0", "batch_1", "g_row", "g_column")
    assert np.array_equal(ds["Gamma"].values, sol.Gamma) and np.array_equal(ds["time"].values, sol.t)
    assert ds.attrs["algebra_name"] == "so(3)" and json.loads(ds.attrs["stats"])["method"] == "rkmk4"
    ens = ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, chunk_size=7, **FIXED).to_xarray()
    assert ens["status"].dims == ("batch_0", "batch_1")
    # per-trajectory statistics are variables over the batch dims, event records over their own dimension
    # (an audit: both were lost, or kept only as lists in the JSON attribute); the attribute is strict JSON
    plane = ls.integrators.gamma_crossing(3, index=0)
    sol = ls.integrate(system, Omega0, (0.0, 20.0), Gamma0=Gamma0, reconstruct=True, events=plane, **FIXED)
    ds = sol.to_xarray()
    assert ds["t_stop"].dims == ("batch_0", "batch_1") and np.array_equal(ds["failure"].values, sol.stats["failure"])
    rec = sol.events[0]
    assert rec.t.size > 0 and ds["event0_t"].dims == ("event0_crossing",)
    for name in ("t", "index", "omega", "Gamma", "g"):
        assert np.array_equal(ds[f"event0_{name}"].values, getattr(rec, name)), name
    stats = json.loads(ds.attrs["stats"], parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))
    assert "t_stop" not in stats and stats["nfev"] == sol.stats["nfev"]
    from liesuslov.xarray_io import _plain
    assert json.dumps(_plain({"a": np.array([1.0, np.nan]), "b": np.float64(np.inf)}), allow_nan=False) == \
        '{"a": [1.0, null], "b": null}'


def test_to_xarray_without_xarray_names_the_extra(monkeypatch):
    system, Omega0, Gamma0 = _initial((2,))
    sol = ls.integrate(system, Omega0, T_SPAN, Gamma0=Gamma0[0], **FIXED)
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(ImportError, match=r"liesuslov\[xarray\]"):
        sol.to_xarray()


def test_progress_bar(capsys):
    pytest.importorskip("tqdm")
    system, Omega0, Gamma0 = _initial()
    ens = ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, chunk_size=10, progress=True, **FIXED)
    assert ens.success
    assert "20/20" in capsys.readouterr().err


def test_ls_ensemble_stays_callable_after_the_module_is_imported():
    import liesuslov.ensembles  # the module is ensembles: ls.ensemble stays the function

    system, Omega0, Gamma0 = _initial((3,))
    ens = ls.ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, **FIXED)
    assert isinstance(ens, ls.Ensemble) and ens.success
    assert liesuslov.ensembles.ensemble is ensemble and ls.open_ensemble is open_ensemble


def test_import_liesuslov_stays_light():
    import subprocess

    code = ("import sys, liesuslov; print(sorted(m for m in ('dask', 'distributed', 'xarray', 'zarr', 'tqdm') "
            "if m in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])})
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]"


# ---------------------------------------------------------------------------- bad input
def test_bad_input(tmp_path):
    system, Omega0, Gamma0 = _initial()
    good = dict(Gamma0=Gamma0, **FIXED)
    cases = [
        (dict(chunk_size=0), ValueError, "chunk_size"),
        (dict(chunk_size=True), TypeError, "chunk_size"),
        (dict(chunk_size=2.5), TypeError, "chunk_size"),
        (dict(executor="threads"), TypeError, "executor"),
        # the class, not an instance: its unbound submit used to fail inside as "'function' object has no attribute"
        (dict(executor=ThreadPoolExecutor), TypeError, r"executor must be an executor instance, got the class "
                                                       r"ThreadPoolExecutor; pass ThreadPoolExecutor\(...\)"),
        (dict(reduce="mean"), ValueError, "reduce"),
        (dict(n=10), ValueError, "sampler"),
        (dict(seed=1), ValueError, "sampler"),
        (dict(retries=-1), ValueError, "retries"),
        (dict(store=3), TypeError, "store"),
        (dict(progress="yes"), TypeError, "progress"),
        (dict(frobnicate=1), TypeError, "frobnicate"),
        (dict(t_eval=[0.0, 2.0]), ValueError, "t_eval"),
    ]
    for extra, exc, word in cases:
        with pytest.raises(exc, match=word):
            ensemble(system, Omega0, T_SPAN, **{**good, **extra})
    with pytest.raises(ValueError, match="t_span"):
        ensemble(system, Omega0, (1.0, 1.0), **good)
    with pytest.raises(TypeError, match="system"):
        ensemble("not a system", Omega0, T_SPAN, **good)
    with pytest.raises(ValueError, match="Omega0"):
        ensemble(system, np.zeros((4, 5)), T_SPAN, **good)
    with pytest.raises(ValueError, match="broadcast"):
        ensemble(system, Omega0, T_SPAN, **{**good, "Gamma0": np.tile(Gamma0, (3, 1, 1))})
    with pytest.raises(ValueError, match="Omega0"):
        ensemble(system, None, T_SPAN, **good)
    with pytest.raises(ValueError, match="Omega0 must be None"):
        ensemble(system, Omega0, T_SPAN, sampler=uniform_sampler, n=5, **FIXED)
    with pytest.raises(ValueError, match="n "):
        ensemble(system, None, T_SPAN, sampler=uniform_sampler, **FIXED)
    with pytest.raises(TypeError, match="sampler"):
        ensemble(system, None, T_SPAN, sampler=3, n=5, **FIXED)
    # a bad initial state is found by integrate on the worker and raised here, not retried
    with pytest.raises(ValueError, match="Omega0"):
        ensemble(system, Omega0 + [0.1, 0.0, 0.0], T_SPAN, chunk_size=7, **good)
    with pytest.raises(ValueError, match="Gamma0"):
        ensemble(system, Omega0, T_SPAN, **{**good, "Gamma0": 2 * Gamma0})
    with pytest.raises(ValueError, match="h"):
        ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, method="rkmk4")


def _lambda_system():
    """A system that does not pickle: its potential is built from lambdas (V = Gamma_3^2 / 2)."""
    J = ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0]))
    V = ls.Potential(lambda G: 0.5 * G[..., 2] ** 2, lambda G: G * np.array([0.0, 0.0, 1.0]), n=3)
    return ls.SuslovSystem(J, potential=V)


def test_threads_and_this_process_need_no_pickling():
    """executor=None and a ThreadPoolExecutor share the system in memory: a lambda potential is fine there."""
    system = _lambda_system()
    with pytest.raises((pickle.PicklingError, AttributeError)):
        pickle.dumps(system)
    _, Omega0, Gamma0 = _initial()
    sol = ls.integrate(system, Omega0, T_SPAN, Gamma0=Gamma0, t_eval=[0.0, 1.5], **FIXED)
    with ThreadPoolExecutor(2) as threads:
        for ex in (None, threads):
            ens = ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, chunk_size=3, executor=ex,
                           reduce=lambda s: s, **FIXED)
            _assert_same(ens, sol)
        ens = ensemble(system, None, T_SPAN, sampler=lambda rng, size: uniform_sampler(rng, size), n=30, seed=2,
                       chunk_size=4, executor=threads, **FIXED)
        assert ens.success and ens.stats["executor"] == "ThreadPoolExecutor"


def test_what_does_not_pickle_is_named_before_anything_runs(pool):
    system, Omega0, Gamma0 = _initial()
    with pytest.raises(TypeError, match="system must pickle.*ProcessPoolExecutor"):
        ensemble(_lambda_system(), Omega0, T_SPAN, Gamma0=Gamma0, executor=pool, **FIXED)
    with pytest.raises(TypeError, match="events must pickle"):
        ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, executor=pool, events=lambda t, O, G, g: G[..., 0], **FIXED)
    with pytest.raises(TypeError, match="sampler must pickle"):
        ensemble(system, None, T_SPAN, sampler=lambda rng, size: {}, n=5, executor=pool, **FIXED)
    with pytest.raises(TypeError, match="reduce must pickle"):
        ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, reduce=lambda sol: sol, executor=pool, **FIXED)


# ---------------------------------------------------------------------------- a real Dask cluster
@pytest.fixture(scope="module")
def client():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1, dashboard_address=None,
                                       host="127.0.0.1")
    c = distributed.Client(cluster)
    try:
        yield c
    finally:
        c.close()
        cluster.close()


@pytest.mark.slow
@pytest.mark.parametrize("options", [FIXED, ADAPTIVE], ids=["rkmk4", "rkmk45"])
def test_dask_equals_one_integrate_call(client, options):
    system, Omega0, Gamma0 = _initial((8, 5))
    sol = ls.integrate(system, Omega0, T_SPAN, Gamma0=Gamma0, t_eval=[0.0, 0.7, 1.5], **options)
    runs = [ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, t_eval=[0.0, 0.7, 1.5], chunk_size=cs, executor=client,
                     **options) for cs in (1, 7, None)]
    for ens in runs:
        _assert_same(ens, sol)
        assert ens.stats["executor"] == "Client"


@pytest.mark.slow
def test_dask_worker_killed_while_tasks_run(client, tmp_path):
    system, Omega0, Gamma0 = _initial((8, 5))
    sol = ls.integrate(system, Omega0, T_SPAN, Gamma0=Gamma0, t_eval=list(T_SPAN), **FIXED)
    marker = tmp_path / "killed"
    ens = ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, chunk_size=4, executor=client, store=tmp_path / "s",
                   reduce=KillOnce(str(marker)), **FIXED)
    assert marker.exists()  # a worker did die in the middle of the run
    assert ens.complete and ens.stats["failed_chunks"] == []
    _assert_same(ens, sol)
    client.wait_for_workers(2, timeout=60)  # the nanny restarts it; leave the cluster as found


@pytest.mark.slow
def test_dask_sampler_reproducible_across_worker_counts(client, pool):
    system = _system()
    kw = dict(sampler=uniform_sampler, n=2 * SAMPLER_BLOCK + 5, seed=3, reduce="final", **FIXED)
    span = (0.0, 0.1)
    on_dask = ensemble(system, None, span, chunk_size=300, executor=client, **kw)
    with ProcessPoolExecutor(1) as one:
        on_one = ensemble(system, None, span, chunk_size=1024, executor=one, **kw)
    here = ensemble(system, None, span, **kw)
    for ens in (on_dask, on_one):
        _assert_same(ens, here.to_solution())


@pytest.mark.slow
def test_the_docs_examples_run(tmp_path):
    """docs/ensembles.md: its Python blocks, run in order as one script (the Dask one starts a LocalCluster)."""
    import re
    import subprocess

    root = Path(__file__).resolve().parents[1]
    text = (root / "docs" / "ensembles.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) >= 2
    script = "\n".join(blocks) + "\nassert ens.success and ens.omega.shape == (2, 20, 10, 3)\nprint('ok')\n"
    (tmp_path / "example.py").write_text(script)
    env = {**os.environ, "PYTHONPATH": str(root)}
    res = subprocess.run([sys.executable, "example.py"], cwd=tmp_path, capture_output=True, text=True, env=env,
                         timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.strip().endswith("ok")
    assert ls.open_ensemble(tmp_path / "runs" / "torus").success


# ---------------------------------------------------------------------------- the run's message, unusable executors
def _V_half(G):
    return 0.5 * np.sum(G * G, axis=-1)


def _dV_nan_at_0123(G):
    """The gradient of _V_half, NaN for a vertical with Gamma_1 = 0.123 (one trajectory fails at t = 0)."""
    out = np.array(G, dtype=float)
    out[np.abs(out[..., 0] - 0.123) < 1e-12] = np.nan
    return out


def test_the_message_is_the_whole_runs(tmp_path):
    """It was the first collected chunk's ('successfully reached the end' with trajectory 17 failed; with a
    store the same text went into the manifest); now what one integrate call on the whole batch says."""
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0])),
                             potential=ls.Potential(_V_half, _dV_nan_at_0123))
    rng = np.random.default_rng(0)
    Omega0 = rng.normal(size=(40, 2)) @ system.constraints.basis
    Gamma0 = rng.normal(size=(40, 3))
    Gamma0 /= np.linalg.norm(Gamma0, axis=1, keepdims=True)
    Gamma0[17] = [0.123, 0.0, np.sqrt(1.0 - 0.123 ** 2)]
    kw = dict(Gamma0=Gamma0, method="rkmk45", t_eval=[0.0, 1.0])
    sol = ls.integrate(system, Omega0, (0.0, 1.0), **kw)
    assert sol.message.startswith("1 of 40 trajectories failed; the first (index 17): non-finite state at t = 0")
    assert sol.stats["failure"][17] == 1 and np.count_nonzero(sol.stats["failure"]) == 1
    ens = ensemble(system, Omega0, (0.0, 1.0), chunk_size=4, **kw)
    stored = ensemble(system, Omega0, (0.0, 1.0), chunk_size=4, store=tmp_path / "s", **kw)
    for e in (ens, stored, open_ensemble(tmp_path / "s")):
        assert e.message == sol.message
        assert np.array_equal(e.stats["failure"], sol.stats["failure"])


def test_an_executor_that_cannot_run_is_bad_input():
    """A shut-down pool was accepted: every chunk failed after the retries, and a store was marked complete."""
    system, Omega0, Gamma0 = _initial()
    pool = ProcessPoolExecutor(1)
    pool.shutdown()
    with pytest.raises(ValueError, match="executor: this ProcessPoolExecutor is shut down"):
        ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, executor=pool, **FIXED)


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore:Port 8787 is already in use")  # (the module's cluster holds it)
def test_dask_client_closed_or_without_workers(monkeypatch):
    """A closed client is bad input; a client closed mid-run fails the remaining chunks (it raised the client's
    ClosedClientError from the clean-up); a cluster scaled to no worker waits for one and warns once."""
    distributed = pytest.importorskip("distributed")
    import threading

    from liesuslov.ensembles import executors

    system, Omega0, Gamma0 = _initial((40,))
    slow = {"method": "rkmk4", "h": 1e-4, "backend": "numpy"}
    cluster = distributed.LocalCluster(n_workers=1, processes=True, threads_per_worker=1, dashboard_address=None,
                                       host="127.0.0.1")
    try:
        c = distributed.Client(cluster)
        threading.Timer(2.0, c.close).start()
        ens = ensemble(system, Omega0, (0.0, 2.0), Gamma0=Gamma0, chunk_size=4, executor=c, **slow)
        assert not ens.success and "chunks failed" in ens.message and "Closed" in ens.message
        with pytest.raises(ValueError, match="executor: this dask.distributed.Client is closed"):
            ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, executor=c, **FIXED)
        monkeypatch.setattr(executors, "NO_WORKER_WARNING", 2.0)
        monkeypatch.setattr(executors, "_POLL", 0.5)
        c = distributed.Client(cluster)
        threading.Timer(1.0, lambda: cluster.scale(0)).start()
        threading.Timer(8.0, lambda: cluster.scale(1)).start()
        with pytest.warns(RuntimeWarning, match="no worker for 2 s"):
            ens = ensemble(system, Omega0, (0.0, 2.0), Gamma0=Gamma0, chunk_size=4, executor=c, **slow)
        assert ens.success
        c.close()
    finally:
        cluster.close()


def test_a_batch_beyond_the_memory_is_refused():
    system = _system()
    with pytest.raises(ValueError, match="bookkeeping"):
        ensemble(system, None, T_SPAN, sampler=uniform_sampler, n=10**13, **FIXED)


_TAU = np.full((5, 4), 0.5)


def _clock_of_the_whole_batch(t, Omega, Gamma, g):
    return t - _TAU


def test_an_event_with_parameters_of_the_whole_batch_names_itself_in_an_ensemble():
    """integrate calls an event on the batch's shape, an ensemble on a chunk's (chunk,): an event reading a
    (5, 4) parameter works in integrate and raised numpy's bare broadcast error in ensemble."""
    system, Omega0, Gamma0 = _initial()
    sol = ls.integrate(system, Omega0, (0.0, 1.0), Gamma0=Gamma0, method="rkmk45", events=_clock_of_the_whole_batch)
    assert sol.events[0].t.size == 20
    with pytest.raises(ValueError, match=r"events\[0\] raised ValueError: .*called on a batch of shape \(20,\)"):
        ensemble(system, Omega0, (0.0, 1.0), Gamma0=Gamma0, method="rkmk45", events=_clock_of_the_whole_batch)


# ---------------------------------------------------------------------------- initial data read as integrate reads it
def _se_system(n, constraints="none"):
    alg = ls.se(n)
    return ls.SuslovSystem(ls.Inertia(alg, np.diag(np.arange(1.0, alg.dim + 1.0))), constraints=constraints)


def _chaplygin_sleigh():
    """se(2) with the sleigh's knife edge: no sideways velocity, the covector (0, 0, 1) annihilates D."""
    return _se_system(2, ls.Subspace.annihilator(ls.se(2), np.array([[0.0, 0.0, 1.0]])))


def _se_matrices(system, shape, seed=0):
    """Representation matrices (shape..., m, m) of random states in D."""
    D = system.constraints
    x = np.random.default_rng(seed).normal(size=shape + (system.algebra.dim,))
    return system.algebra.hat(x if D is None else D.project(x))


@pytest.mark.parametrize("scene", ["se2", "sleigh", "se3"])
@pytest.mark.parametrize("chunk_size", [None, 1, 3])
def test_representation_matrices_on_se_n_are_read_as_integrate_reads_them(scene, chunk_size):
    """ensemble decided matrix-or-coordinates itself, taking only so(n) arrays for matrices: (5, 3, 3) se(2)
    matrices became 15 trajectories of coordinates (success True), the sleigh's matrices were 'not in D', se(3)'s
    (..., 4, 4) matrices were refused and one matrix crashed in a reshape."""
    system = {"se2": lambda: _se_system(2), "sleigh": _chaplygin_sleigh, "se3": lambda: _se_system(3)}[scene]()
    m = system.algebra.matrix_size
    X = _se_matrices(system, (5,))
    assert X.shape == (5, m, m)
    for O in (X, X[0]):  # a batch of matrices, and one matrix (no batch axes)
        sol = ls.integrate(system, O, (0.0, 1.0), t_eval=[0.0, 1.0], **ADAPTIVE)
        ens = ensemble(system, O, (0.0, 1.0), chunk_size=chunk_size, **ADAPTIVE)
        assert ens.omega.shape == (2,) + O.shape[:-2] + (system.algebra.dim,)
        assert ens.status.shape == O.shape[:-2]
        _assert_same(ens, sol)
    if scene == "se3":  # with the attitudes g0 in SE(3), one per trajectory
        rng = np.random.default_rng(3)
        g0 = np.tile(np.eye(4), (5, 1, 1))
        R = np.linalg.qr(rng.normal(size=(5, 3, 3)))[0]
        g0[:, :3, :3] = R * np.sign(np.linalg.det(R))[:, None, None]  # (-R for a reflection R: a rotation)
        g0[:, :3, 3] = rng.normal(size=(5, 3))
        kw = dict(g0=g0, reconstruct=True, **ADAPTIVE)
        sol = ls.integrate(system, X, (0.0, 1.0), t_eval=[0.0, 1.0], **kw)
        _assert_same(ensemble(system, X, (0.0, 1.0), chunk_size=chunk_size, **kw), sol)


#: Three states in the Suslov plane D of so(3) (Omega_12 = 0) whose coordinates, stacked, are a skew matrix.
_SKEW_ROWS = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.7], [0.0, -0.7, 0.0]])


def _skew_rows_sampler(rng, size):
    """Omega0 repeating _SKEW_ROWS (coordinates), Gamma0 random: chunks of 3 from 0 are a (3, 3) skew array."""
    G = rng.normal(size=(size, 3))
    return {"Omega0": np.resize(_SKEW_ROWS, (size, 3)), "Gamma0": G / np.linalg.norm(G, axis=-1, keepdims=True)}


def test_a_chunk_of_three_coordinate_vectors_is_not_read_as_one_matrix():
    """On so(3) and se(2) (d = m = 3) a chunk of 3 trajectories is a (3, 3) array: 3 states that form a matrix of
    the algebra (zero states, say) were read as one matrix by the chunk's integrate call."""
    se2 = _se_system(2)
    X = np.zeros((6, 3))  # coordinates: a (6, 3) batch of six states, three of them zero
    X[3:] = np.random.default_rng(1).normal(size=(3, 3))
    sol = ls.integrate(se2, X, (0.0, 1.0), t_eval=[0.0, 1.0], **ADAPTIVE)
    _assert_same(ensemble(se2, X, (0.0, 1.0), chunk_size=3, **ADAPTIVE), sol)
    # so(3) with Gamma and per-trajectory LinearEvent rows (split with the batch), and a sampler drawing such rows
    system, Omega0, Gamma0 = _initial((6,))
    Omega0[:3] = _SKEW_ROWS
    assert np.allclose(system.constraints.project(Omega0), Omega0)
    G = np.broadcast_to(Gamma0, (6, 3))
    events = [ls.integrators.return_plane(system, Omega0 + 0.1 * system.constraints.basis[0], G),
              ls.integrators.gamma_crossing(3, index=1)]
    span = (0.0, 10.0)
    sol = ls.integrate(system, Omega0, span, Gamma0=Gamma0, t_eval=list(span), events=events, **FIXED)
    ens = ensemble(system, Omega0, span, Gamma0=Gamma0, chunk_size=3, events=events, **FIXED)
    _assert_same(ens, sol)
    for a, b in zip(ens.events, sol.events, strict=True):
        assert a.t.size > 0 and np.array_equal(a.t, b.t) and np.array_equal(a.index, b.index)
    drawn = draw(_skew_rows_sampler, 6, 4)
    sol = ls.integrate(system, drawn["Omega0"], T_SPAN, Gamma0=drawn["Gamma0"], t_eval=list(T_SPAN), **FIXED)
    _assert_same(ensemble(system, None, T_SPAN, sampler=_skew_rows_sampler, n=6, seed=4, chunk_size=3, **FIXED), sol)


def test_the_so3_se2_ambiguity_is_integrate_s():
    """A (3, 3) array on so(3) or se(2): one matrix when it is one (to rounding), else 3 coordinate vectors, and
    refused when close to a matrix — whatever integrate decides, the ensemble decides (once, on the whole batch)."""
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0])), constraints="none")
    for alg_system in (system, _se_system(2)):
        alg = alg_system.algebra
        one = alg.hat(np.array([0.3, -0.2, 0.5]))
        three = np.random.default_rng(2).normal(size=(3, 3))
        for O in (one, three):
            sol = ls.integrate(alg_system, O, (0.0, 1.0), t_eval=[0.0, 1.0], **FIXED)
            for cs in (None, 1):
                ens = ensemble(alg_system, O, (0.0, 1.0), chunk_size=cs, **FIXED)
                assert ens.status.shape == sol.status.shape == (() if O is one else (3,))
                _assert_same(ens, sol)
        near = one + 1e-9 * three  # neither a matrix to rounding nor clearly three vectors
        with pytest.raises(ValueError, match="ambiguous") as e1:
            ls.integrate(alg_system, near, (0.0, 1.0), **FIXED)
        with pytest.raises(ValueError, match="ambiguous") as e2:
            ensemble(alg_system, near, (0.0, 1.0), **FIXED)
        assert str(e1.value) == str(e2.value)


def test_input_integrate_rejects_is_rejected_the_same_way():
    """A complex Omega0 was cast to real with numpy's ComplexWarning and integrated; a boolean Gamma0 read as 0/1."""
    import warnings

    system, Omega0, Gamma0 = _initial()
    good = dict(Gamma0=Gamma0, **FIXED)
    cases = [((system, Omega0 + 1e-3j, T_SPAN), good, "Omega0"),
             ((system, Omega0, T_SPAN), {**good, "Gamma0": np.array([False, False, True])}, "Gamma0"),
             ((system, Omega0.tolist(), T_SPAN), {**good, "Gamma0": [0.0, 0.6 + 0j, 0.8]}, "Gamma0"),
             ((_se_system(2), ls.se(2).hat(np.ones(3)) + 0j, T_SPAN), FIXED, "Omega0")]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a cast would be a ComplexWarning, not the TypeError
        for args, kw, word in cases:
            with pytest.raises(TypeError, match=word) as e1:
                ls.integrate(*args, **kw)
            with pytest.raises(TypeError, match=word) as e2:
                ensemble(*args, **kw)
            assert str(e1.value) == str(e2.value)
        with pytest.raises(TypeError, match="sampler's 'Omega0' must be real"):
            ensemble(system, None, T_SPAN, sampler=_complex_sampler, n=4, seed=0, **FIXED)


def _complex_sampler(rng, size):
    return {"Omega0": np.zeros((size, 3)) + 0j, "Gamma0": np.tile([0.0, 0.6, 0.8], (size, 1))}


# ---------------------------------------------------------------------------- store, reduce and seed errors
def test_an_empty_store_path_is_refused_and_writes_nothing(tmp_path, monkeypatch):
    """store="" wrote the shards and the manifest into the current directory (overwrite=True deleted chunks there)."""
    system, Omega0, Gamma0 = _initial()
    monkeypatch.chdir(tmp_path)
    (tmp_path / "chunk-000000.npz").write_bytes(b"someone else's file")
    for overwrite in (False, True):
        with pytest.raises(ValueError, match="store must be a directory path, got the empty string"):
            ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, store="", overwrite=overwrite, chunk_size=5, **FIXED)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["chunk-000000.npz"]


def test_an_unusable_store_path_names_store(tmp_path):
    system, Omega0, Gamma0 = _initial()
    (tmp_path / "a_file").write_text("x")
    bad = [tmp_path / "a_file" / "run"]  # under a file: was a bare NotADirectoryError
    if Path("/proc/self").is_dir():
        bad.append("/proc/liesuslov-store")  # a file system that takes no directories: was FileNotFoundError
    for store in bad:
        with pytest.raises(ValueError, match=r"store .* cannot be created as a directory .* pass a directory path"):
            ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, store=store, **FIXED)


def test_a_damaged_store_names_the_file_and_what_is_wrong(tmp_path):
    """A corrupt manifest gave a raw JSONDecodeError, a missing key KeyError: 'bounds', a corrupt shard numpy's
    advice to pass allow_pickle=True."""
    import shutil

    system, Omega0, Gamma0 = _initial()
    good = tmp_path / "good"
    ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, store=good, chunk_size=5, **FIXED)
    man = json.loads((good / "manifest.json").read_text())

    def damaged(name, edit):
        d = tmp_path / name
        shutil.copytree(good, d)
        edit(d)
        return d

    cases = [
        (damaged("not_json", lambda d: (d / "manifest.json").write_text("{not json")),
         "manifest.json is not valid JSON"),
        (damaged("a_list", lambda d: (d / "manifest.json").write_text("[1, 2]")), "manifest.json holds a JSON list"),
        (damaged("no_bounds", lambda d: (d / "manifest.json").write_text(
            json.dumps({k: v for k, v in man.items() if k != "bounds"}))), r"manifest.json lacks \['bounds'\]"),
        (damaged("bad_bounds", lambda d: (d / "manifest.json").write_text(
            json.dumps({**man, "bounds": [[0, 5], [7, 20]]}))), "bounds must be the chunks"),
    ]
    for store, match in cases:
        with pytest.raises(ValueError, match=match) as err:
            open_ensemble(store)
        assert str(store) in str(err.value) and "overwrite=True" in str(err.value)
    # a damaged shard: named when read (lazily, by a finished store; at once by a partial one, for its times)
    shard = damaged("bad_shard", lambda d: (d / "chunk-000001.npz").write_bytes(b"garbage"))
    ens = open_ensemble(shard)
    for read in (lambda: ens.omega, lambda: ens.status, lambda: list(ens.chunks())):
        with pytest.raises(ValueError, match="the shard chunk-000001.npz is damaged") as err:
            read()
        assert "allow_pickle" not in str(err.value)
    partial = damaged("partial", lambda d: ((d / "chunk-000000.npz").write_bytes(b"\x00" * 10),
                                           (d / "manifest.json").write_text(json.dumps(
                                               {k: v for k, v in man.items() if k not in ("t", "tails")}))))
    with pytest.raises(ValueError, match="the shard chunk-000000.npz is damaged"):
        open_ensemble(partial)


class CountingBadReduce:
    """A reduce that returns 42 instead of a Solution, counting its calls."""

    def __init__(self):
        self.calls = 0

    def __call__(self, sol):
        self.calls += 1
        return 42


def _drop_a_trajectory(sol):
    from dataclasses import replace

    return replace(sol, xi=sol.xi[:, 1:], omega=sol.omega[:, 1:], Gamma=sol.Gamma[:, 1:], status=sol.status[1:])


def test_a_reduce_that_returns_no_solution_is_bad_input_raised_at_once(tmp_path):
    """It was taken for a numerical failure: status -1 everywhere, "AttributeError: 'int' object has no attribute
    't'" in the message, after every chunk had run."""
    system, Omega0, Gamma0 = _initial()
    for in_flight in (None, 1):  # (the default: 3 chunks in flight, run before the first result is looked at)
        bad = CountingBadReduce()
        with pytest.raises(TypeError, match="reduce must return a Solution .* returned int"):
            ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, chunk_size=2, reduce=bad, store=tmp_path / "s",
                     overwrite=True, max_in_flight=in_flight, **FIXED)
        # the first chunk's result raised it: of the 10 chunks, only those already in flight ran
        assert bad.calls == (3 if in_flight is None else 1)
    with pytest.raises(ValueError, match="reduce must keep the chunk's trajectories"):
        ensemble(system, Omega0, T_SPAN, Gamma0=Gamma0, chunk_size=4, reduce=_drop_a_trajectory, **FIXED)


@pytest.mark.parametrize("seed, exc", [("x", TypeError), (-1, ValueError), (True, TypeError), (1.5, TypeError),
                                       ([1, -2], ValueError), ([], TypeError)])
def test_a_bad_seed_names_seed(seed, exc):
    """numpy's messages ("SeedSequence expects int or sequence of ints...", "expected non-negative integer") did
    not name the argument."""
    system = _system()
    with pytest.raises(exc, match="seed must be None, an integer >= 0"):
        ensemble(system, None, T_SPAN, sampler=uniform_sampler, n=5, seed=seed, **FIXED)
    with pytest.raises(exc, match="seed must be"):
        draw(uniform_sampler, 5, seed)


def test_good_seeds_still_work():
    a = draw(uniform_sampler, 5, [1, 2])
    b = draw(uniform_sampler, 5, np.random.SeedSequence([1, 2]))
    assert np.array_equal(a["Omega0"], b["Omega0"])
    assert np.array_equal(draw(uniform_sampler, 5, np.int64(3))["Omega0"], draw(uniform_sampler, 5, 3)["Omega0"])


def test_backward_events_are_sorted_by_index_and_t(tmp_path):
    """A backward run's crossings come sorted by (index, t), as API.md says (they came in the order of
    integration, decreasing t), on both backends, and the ensemble gives integrate's records whatever the
    chunks."""
    system, Omega0, Gamma0 = _initial((6,))
    span = (20.0, 0.0)
    plane = ls.integrators.gamma_crossing(3, index=0)
    sol = ls.integrate(system, Omega0, span, Gamma0=Gamma0, events=plane, **FIXED)
    rec = sol.events[0]
    assert rec.t.size > 6 and np.all(np.diff(rec.t)[np.diff(rec.index) == 0] > 0) and np.all(np.diff(rec.index) >= 0)
    for backend in ("numpy", "numba") if importlib.util.find_spec("numba") else ("numpy",):
        other = ls.integrate(system, Omega0, span, Gamma0=Gamma0, events=plane, backend=backend, **FIXED).events[0]
        assert np.array_equal(other.index, rec.index) and np.allclose(other.t, rec.t, rtol=0, atol=1e-12)
    # each crossing's state is its own (sorted with its time): Gamma_0 = 0 there
    assert np.abs(rec.Gamma[:, 0]).max() < 1e-12
    for ens in (ensemble(system, Omega0, span, Gamma0=Gamma0, chunk_size=2, events=plane, **FIXED),
                ensemble(system, Omega0, span, Gamma0=Gamma0, chunk_size=4, store=tmp_path / "s", events=plane,
                         **FIXED)):
        assert np.array_equal(ens.events[0].t, rec.t) and np.array_equal(ens.events[0].index, rec.index)
