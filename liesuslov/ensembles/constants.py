"""The ensemble constants: sampler blocks, reductions, the store format."""

from __future__ import annotations

#: Trajectories per random block: block ``j`` (trajectories ``[j B, (j + 1) B)``) is drawn by
#: ``sampler(numpy.random.default_rng(SeedSequence(seed).spawn(j + 1)[j]), B)``, whatever the chunking.
SAMPLER_BLOCK = 1024
#: Names accepted by ``reduce=`` (besides None and a module-level callable ``Solution -> Solution``).
REDUCTIONS = ("final",)
FORMAT = "liesuslov-ensemble/1"
MANIFEST = "manifest.json"
_ARRAYS = ("xi", "omega", "Gamma", "g")
_INIT_KEYS = ("Omega0", "Gamma0", "g0")
_SUMMED = ("nfev", "steps", "rejected")
_STAT = "stats__"  # shard key prefix of a per-trajectory statistic (e.g. stats__trajectory_steps)
_EVENT = "event__"  # shard key prefix of event crossings: event__{j}__{t,index,omega,Gamma,g} (index global)
_EVENT_FIELDS = ("t", "index", "omega", "Gamma", "g")
# trailing (non-batch) axes of the initial data a chunk carries: Omega0 always as coordinates (..., d)
_CORE = {"Omega0": 1, "Gamma0": 1, "g0": 2}
# Exceptions a task raises on bad input: deterministic, so they are raised here, never retried.
_USER_ERRORS = (ValueError, TypeError)


def _shard_name(i: int) -> str:
    return f"chunk-{i:06d}.npz"
