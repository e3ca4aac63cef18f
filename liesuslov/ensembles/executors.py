"""Executors: in process, any ``concurrent.futures.Executor``, or a ``dask.distributed.Client``."""

from __future__ import annotations

import concurrent.futures as cf
import os
import time
import warnings

from .tasks import _run_chunk, _Task


# ====================================================================== executors
def _is_dask(executor) -> bool:
    return type(executor).__module__.split(".")[0] == "distributed" and hasattr(executor, "scheduler_info")


def _pickles(executor) -> bool:
    """Whether ``executor`` pickles what it is sent: every executor but None and a thread pool.

    None runs the chunks here and a :class:`concurrent.futures.ThreadPoolExecutor` (or a subclass) runs them
    on threads of this process, which share the system, the sampler and ``reduce`` as they are. Anything
    else (a process pool, loky, an MPI pool, a Dask client, an executor this module does not know) is taken
    to send them to other processes, pickled: :func:`ensemble` checks that they pickle before submitting.
    """
    return executor is not None and not isinstance(executor, cf.ThreadPoolExecutor)


def _n_workers(executor) -> int:
    if executor is None:
        return 1
    if _is_dask(executor):
        try:
            return max(1, sum(w.get("nthreads", 1) for w in executor.scheduler_info()["workers"].values()))
        except Exception:  # noqa: BLE001 - only a default chunk size depends on it
            return 4
    return int(getattr(executor, "_max_workers", 4) or 4)


class _InProcess:
    """A future computed on the spot (executor=None): same interface as the others."""

    def __init__(self, fn, arg):
        try:
            self._value, self._exc = fn(arg), None
        except Exception as exc:  # noqa: BLE001 - reported like a worker's exception
            self._value, self._exc = None, exc

    def result(self):
        if self._exc is not None:
            raise self._exc
        return self._value


def _submit(executor, task: _Task, attempt: int):
    if executor is None:
        return _InProcess(_run_chunk, task)
    if _is_dask(executor):
        # pure=False: a resubmission gets a new key instead of Dask's cached failed result
        return executor.submit(_run_chunk, task, pure=False, key=f"liesuslov-chunk-{task.index}-{attempt}-"
                                                               f"{os.urandom(4).hex()}")
    return executor.submit(_run_chunk, task)


#: Seconds a Dask cluster may have no worker before :func:`_wait_first` warns (once) that the run is waiting.
NO_WORKER_WARNING = 60.0
#: Seconds between the checks of a Dask wait (for workers, and for Ctrl-C).
_POLL = 5.0


def _wait_first(executor, futures):
    """The futures that are done, waiting for at least one.

    A Dask cluster without workers holds its tasks until one joins — an adaptive cluster or a batch queue may
    take minutes to start them, so the wait does not give up; after :data:`NO_WORKER_WARNING` seconds with no
    worker it warns once, saying what it waits for (interrupt, or add workers)."""
    if executor is None:
        return list(futures)
    if _is_dask(executor):
        from distributed import wait

        idle_since, warned = None, False
        while True:
            try:
                return list(wait(list(futures), timeout=_POLL, return_when="FIRST_COMPLETED").done)
            except TimeoutError:
                pass
            if _n_dask_workers(executor) > 0:
                idle_since = None
                continue
            idle_since = idle_since or time.monotonic()
            if not warned and time.monotonic() - idle_since >= NO_WORKER_WARNING:
                warnings.warn(f"ensemble: the Dask cluster has had no worker for {NO_WORKER_WARNING:.0f} s; its "
                              f"{len(futures)} pending chunks wait for one (start workers, or interrupt: the store "
                              "keeps the finished chunks)", RuntimeWarning, stacklevel=4)
                warned = True
    return list(cf.wait(list(futures), return_when=cf.FIRST_COMPLETED).done)


def _n_dask_workers(client) -> int:
    try:
        return len(client.scheduler_info()["workers"])
    except Exception:  # noqa: BLE001 - a closed client: the wait itself reports it
        return 1


def _check_running(executor) -> None:
    """Raise ``ValueError`` naming ``executor`` when it can no longer run tasks (shut down, closed, broken).

    Before anything is written (a store): the stdlib pools' shutdown and broken flags, a Dask client's
    status. They are private attributes (read with a default, so a pool without them passes); the rule for
    every executor is the first submission: one refused is the same ValueError (:func:`~.run._run_all`)."""
    if executor is None:
        return
    if _is_dask(executor):
        if getattr(executor, "status", "running") in ("closing", "closed"):
            raise ValueError(f"executor: this dask.distributed.Client is {executor.status}; pass a running client")
        return
    if getattr(executor, "_shutdown_thread", False) or getattr(executor, "_shutdown", False) or \
            getattr(executor, "_broken", False):
        raise ValueError(f"executor: this {type(executor).__name__} is shut down or broken and cannot run tasks; "
                         "pass a running executor")
