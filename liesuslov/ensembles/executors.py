"""Executors: in process, any ``concurrent.futures.Executor``, or a ``dask.distributed.Client``."""

from __future__ import annotations

import concurrent.futures as cf
import os

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


def _wait_first(executor, futures):
    if executor is None:
        return list(futures)
    if _is_dask(executor):
        from distributed import wait

        return list(wait(list(futures), return_when="FIRST_COMPLETED").done)
    return list(cf.wait(list(futures), return_when=cf.FIRST_COMPLETED).done)
