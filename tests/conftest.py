"""Session setup: the compiled kernel's loops are compiled (or loaded from numba's cache) up front, in
parallel processes — one per core — rather than one after the other inside the first tests that need them
(see :mod:`liesuslov.integrators.kernel.warm`). Without numba there is nothing to compile."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session", autouse=True)
def _compiled_kernel_loops():
    try:
        import numba  # noqa: F401
    except ImportError:
        return
    from liesuslov.integrators.kernel.warm import compile_kinds

    compile_kinds()
