"""Work-precision benchmark: liesuslov's RKMK integrators against scipy's ``solve_ivp``, speed against error,
and against a plain compiled loop of the same method (the floor).

Run it as ``python -m liesuslov.bench`` (or ``liesuslov bench``); ``--quick`` takes under a minute.
Regenerate the documentation page with::

    python -m liesuslov.bench --docs docs/performance.md

What is measured
----------------
* **Work-precision sweeps** on five reference scenes with exact or analytic solutions
  (:data:`SCENES`): every liesuslov method × chart over a sweep of step sizes (fixed-step methods) or
  tolerances (adaptive ones), and scipy's ``solve_ivp`` (RK45, DOP853, Radau) on the equivalent
  embedded ODE — state ``(xi, vec g)`` with ``Gamma = g^T gamma`` when the attitude is reconstructed,
  ``(xi, Gamma)`` otherwise — with a hand-written numpy right-hand side, as a user would write it.
  Each run records the wall time (minimum over repeats after one warm-up run), ``nfev``, steps, the
  errors in Omega, Gamma and g at the final time against the reference, the orthogonality defect
  ``max |g^T g - I|``, the sphere defect ``max ||Gamma| - 1|``, the constraint defect ``max |<a^i, Omega>|``
  and the drift of every first integral (maxima over all steps).
* **The ratio table**: for each scene and error level 1e-5 … 1e-10 the fastest liesuslov route and
  the fastest scipy route that reach it (log time interpolated linearly in log error along each
  route's sweep) and the ratio liesuslov / scipy.
* **Batch throughput** (trajectory-steps per second, RKMK4 with reconstruction, n = 3 and 4),
  **per-step cost against n** (Fedorov–Kozlov D, reconstruction, n = 3 … 256, with a fitted
  exponent) and a **long run** (10⁶ RKMK4 steps, n = 3: orthogonality and energy error).

Outputs (in the folder given): ``results.csv`` (one row per work-precision run), ``throughput.csv``,
``nscaling.csv``, ``longrun.csv``, ``ratios.csv``, ``summary.md`` and PNG plots. Every file is
written to a temporary name and renamed, after all measurements succeeded.

The numbers are reported, never asserted: the tests (``tests/test_bench.py``) check the machinery.

Modules, in the order the data flows: :mod:`.scenes` (what is integrated), :mod:`.config` (what is
measured), :mod:`.timing` (timed repeats, child processes with limits), :mod:`.runners` (the
measurements), :mod:`.metrics` (errors, defects, ratios, fits), :mod:`.machine`, :mod:`.tables` and
:mod:`.plots` (the report), :mod:`.files` (atomic writing), :mod:`.run` (:func:`run_bench`) and
:mod:`.cli` (the command line).
"""

from __future__ import annotations

from .cli import add_arguments, main, run_from_args
from .config import LEVELS, RESULT_COLUMNS, BenchConfig, BenchReport
from .machine import machine_info
from .metrics import time_to_reach
from .run import run_bench
from .scenes import SCENES, BenchScene, build_scene

__all__ = ["SCENES", "LEVELS", "RESULT_COLUMNS", "BenchConfig", "BenchReport", "BenchScene", "add_arguments",
           "build_scene", "machine_info", "main", "run_bench", "run_from_args", "time_to_reach"]
