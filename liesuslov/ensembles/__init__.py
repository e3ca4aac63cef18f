"""Ensembles beyond one process: one batch of initial data split into chunks run on any executor.

:func:`ensemble` integrates a batch of initial data (given, or drawn on the workers by a sampler)
chunk by chunk, in this process, on a :class:`concurrent.futures.Executor` (a thread pool, a process
pool, loky, an MPI pool) or on a Dask cluster through a ``dask.distributed.Client``, and returns an
:class:`Ensemble` with the arrays of a :class:`~liesuslov.Solution`. The numbers are those of one
:func:`~liesuslov.integrate` call on the whole batch, whatever the executor and the chunk size, because
each trajectory's numbers do not depend on its batch mates.

Results stream to a ``store`` directory (one ``.npz`` shard per chunk and a JSON manifest, both
written atomically), so memory stays bounded by a few chunks; :func:`open_ensemble` reads a finished
or partial store back lazily (a partial store's ``nfev``/``steps``/``rejected`` are the sums over the
chunks it holds). The system, the sampler and ``reduce`` must pickle except with ``executor=None`` or
a ``ThreadPoolExecutor``, which share them in memory. A chunk whose task fails for a reason other than
bad input (a lost worker, a broken pool) is resubmitted up to ``retries`` times, then reported as
``status = -1`` for its trajectories.

Store layout (``FORMAT = "liesuslov-ensemble/1"``)::

    DIR/manifest.json        batch shape, chunk bounds, the run's stats (from the start; the counts at
                             the end), times, array shapes, complete flag
    DIR/chunk-000000.npz     t, xi, omega, [Gamma], [g], status of trajectories [start, stop),
                             time axis first, then one flat batch axis; __meta__ (JSON) per chunk

Nothing here imports dask, xarray or tqdm until asked to.
"""

from .bench import benchmark
from .constants import FORMAT, REDUCTIONS, SAMPLER_BLOCK
from .result import Ensemble
from .run import ensemble
from .sampling import Perturbation, draw
from .store import open_ensemble

__all__ = ["ensemble", "open_ensemble", "Ensemble", "Perturbation", "draw", "REDUCTIONS", "SAMPLER_BLOCK",
           "FORMAT", "benchmark"]
