"""Executors: in process, any ``concurrent.futures.Executor``, or a ``dask.distributed.Client``."""

from __future__ import annotations

import concurrent.futures as cf
import os

from .tasks import _run_chunk, _Task


# ====================================================================== executors
def _is_dask(executor) -> bool:
    return type(executor).__module__.split(".")[0] == "distributed" and hasattr(executor, "scheduler_info")


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
