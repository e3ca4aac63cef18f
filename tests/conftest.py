"""Session setup: the compiled kernel's loops are compiled (or loaded: from the kernel compiled at install, or
from numba's cache) up front, in parallel processes — one per core — rather than one after the other inside
the first tests that need them (see :mod:`liesuslov.integrators.kernel.warm`). With pytest-xdist (``-n auto``)
this runs once, in the controlling process, before the workers start; the workers load the cache. Without
numba there is nothing to compile."""

from __future__ import annotations


def pytest_configure(config):
    if hasattr(config, "workerinput"):  # an xdist worker: the controller has compiled already
        return
    try:
        import numba  # noqa: F401
    except ImportError:
        return
    from liesuslov.integrators.kernel.warm import compile_kinds

    compile_kinds()
