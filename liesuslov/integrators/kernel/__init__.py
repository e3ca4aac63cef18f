"""The whole solve compiled (numba), one trajectory at a time: :func:`solve` takes a :class:`~.problem.Problem`.

Per trajectory, inside one compiled loop (no Python per step, no allocation per step): the RKMK stages of
the method's :class:`~.plan.StagePlan`, the step-size controller and the error norm of :mod:`.control`
(those very functions, compiled by numba), the continuous extension for ``t_eval`` and events, event
location by a bracketing root finder (Illinois), re-projection, failures with their time and code; the loop
(:func:`.loop._solve_one`) runs the stages and the step's end inline (a call per step would pass ~30
arrays, each reference-counted on the way in and out) and calls one function per rarer job — the first
step, the error norm, event location, output, re-projection. The group code is inlined into it by family
(:mod:`.group`). A batch runs in contiguous chunks on the process's pool of threads, made on first use and
kept (the loop releases the GIL; no parfor; :func:`.wrapper._solve_batch`: 8 free bodies × 10 steps 0.82 ->
0.36 ms a call against a pool made per call); a
trajectory's numbers do not depend on its batch mates or the chunking (no reduction across trajectories,
the same code path for B = 1 and B > 1).

Specialisations: one loop per *family* of kinds (:data:`~.common.FAMILIES`), the family a numba literal —
no group part (xi alone: ~20 s to compile, half the closed forms'), the closed forms (so3, so4) and the
matrix algorithms (dense, lowrank) — so a scene compiles only its family's group code; the kind inside a
family, the chart, the mode and every size are run-time values (one int64 and one float64 parameter array
carry the scene), so no other scene compiles again. :mod:`.warm` compiles the families in parallel processes
(``python -m liesuslov.integrators.kernel.warm``; the test session does it first).

Calls that LLVM does not inline pass every array argument field by field, so the small functions of each
stage are inlined at numba IR level (:func:`~.common._jit_inline`: the polynomial field, the so(3) Omega and
dexp⁻¹, the closed forms' action on Gamma), and the closed-form kinds' operations take only the arguments they
read (the family dispatch in :mod:`.group` passes those). Inlining has a compile-time price that grows faster
than the loop: numba's typing of the loop took ~10 s more with event location and output inlined into it, so
only the stages' calls are inlined — the finiteness test of a step is folded into the loops that form its
state, the start of a trajectory and the rarer jobs are calls, the first step computes the group velocity in
one function.
Only the loop has numba's CPython wrapper (the others are called from compiled code only).

Reference counting: numba counts references to an array atomically — for every view made by indexing,
slicing or reshape, and, in a compiled function that calls another compiled function (or, after LLVM, has a
loop in one branch only), for each of its array arguments on entry and exit. On the 5×5 matrices of a dense
stage this was ~30% of the step. The group operations therefore get their arrays *borrowed*
(:func:`~.common._view`, :func:`~.common._borrow`: the same memory without the owner's meminfo, which numba
does not count), the matrix kinds view their flat scratch as matrices the same way, and the so(3) operations are
straight-line code on scalars. The loop itself works on borrowed views of its arguments and of its scratch
(:func:`.loop._solve_one`), so that the code inlined into it at IR level (the stage's field, Omega and dexp⁻¹) and
the calls it makes count nothing either. numba releases a variable right after its last use (``v = _borrow(a)``
is followed by ``del a``): a borrowed view of an array the function allocated is safe only while something
still holds the owner — the loop keeps its scratch's owners in one tuple that it hands to a no-op
(``_keepalive``) at its very end. (An earlier variant borrowed inside the IR-inlined code without keeping the
owners and gave wrong numbers in one test — most likely memory released under the views; the variant here
passes the suite.) One scratch allocation for the loop's ~35 work arrays (slices of it) was tried too: one
allocation less per array, but LLVM no longer knew they do not alias — an so(3) step ~13% slower, reverted.
Measured (interleaved processes, same machine): the Kharlamova scene's compiled solve (dense SO(5), Cayley,
16 RKMK8 steps) 232 -> 165 µs; dense SO(5) RKMK4 with reconstruction 3.0 -> 2.2 µs per step; Fedorov–Kozlov
low rank n = 64 40 -> 34 µs per step; so(3) ~3% per step. The borrowed loop (2026-11-25): so(3) 0.33 -> 0.29 µs
per step; a batch of 10⁴ so(3) trajectories 1.44 -> 1.06–1.18x the single-threaded plain loop per
trajectory-step; the dense kind's step ~3% slower (Kharlamova 16 steps 125 -> 129 µs cache-loaded; compiled in
the process, 11.0 -> 10.5 µs per step: code placement, not more work). The closed forms' action on Gamma
inlined in the stage (``_so3_rotate``, ``_so4_rotate``; 2026-11-25): Klebsh–Tisserand so(4) RKMK4 0.62 -> 0.60 µs
per step (1.94 -> 1.88x the plain loop, four interleaved pairs), the family's compile time unchanged (40–43 s
against 41–44 s); inlining the update of g as well (``_so3_update``, ``_so4_update``, once a step) gave
another ~5% (so(3) 0.289 -> 0.271 µs) for ~8 s more compile (48–53 s): left as calls.

The on-disk cache: numba stamps a cached function with its own file, but a compiled caller embeds its
callees' code; every function here is stamped with the contents of all the kernel's sources
(:data:`~.common.KERNEL_SOURCES`: this package but its Python side — ``wrapper``, ``warm`` —, ``control.py``
and ``groups/``), so a change in any of them recompiles (:class:`~.common._KernelCache`).

Compiled at install: the package's build (``build_backend/liesuslov_build.py``, pip's build of a local project, on
the machine it installs on) runs :mod:`.warm` with every family into :data:`~.common.PRECOMPILED_DIR` beside these
files (~1 minute on a 2-core machine), which the kernel reads before numba's own cache
(:class:`~.common._KernelCacheFile`): the first compiled call in a fresh process loads it (~0.5 s). It is used
only where numba's index key (the numba release, the CPU) and the sources' stamp match; otherwise, or when the
build skipped it (``LIESUSLOV_PRECOMPILE=0``), the first call compiles as below. Why not fewer or leaner
specialisations instead: a family's compilation is numba's Python work on ~2500 lines of kernel code (type
inference and lowering of ~120 functions, then LLVM once per level of the call tree): the family without a
group part alone takes ~12 s on a quiet machine, the closed forms ~27 s — a first call under 10 s needs code
compiled beforehand (numba's cache is specific to the CPU and the numba release, so it is built where the package
is installed, not shipped).

Cost (2-core machine shared with other work, 2026-11-24): a first compiled call that finds no compiled kernel
compiles its family (in a child process, :func:`.wrapper._compile_apart`, then loads it from the cache: the loop loaded
from numba's cache runs faster than the same loop compiled in the calling process — so(3) RKMK4 0.58 -> 0.34 µs
per step, measured 2026-11-25): ~20 s with no group part (9 s of it in LLVM, the rest numba's typing and
lowering), ~30 s for the closed forms, ~70–80 s for the matrix family (whose time is mostly LLVM: numba
optimises each compiled function's module with all its callees linked in, so the matrix maps' deep call chain
is optimised once per level); later processes load it from the cache (~1 s). RKMK4 with reconstruction,
h = 0.005, best of 20 runs (thread CPU time): so(3) 0.29–0.30 µs per step (2.2–2.3x a plain loop hard-coded for
that method: the kernel's loops run over run-time sizes — k, stages, layouts — and read the field and Omega(xi) as
coefficient lists, where the plain loop has constants); so(4) 0.60–0.62 µs per step (so4 kind, the
Klebsh–Tisserand scene of the benchmark; 1.9–2.1x the plain loop's ~0.31 µs; benchmark at bfb9aac);
Fedorov–Kozlov SO(256) (low-rank kind) ~0.55 ms per step.

What is compiled
----------------
* the field: :func:`~.compiled.compile_plan` probes ``model.xi_dot`` as a verified polynomial of degree <= 2
  in ``(xi, Gamma)`` (sparse COO lists) and ``Omega(xi)`` as a linear map;
* the group part in one of the kinds of :func:`kind_for`:

  - ``"so3"``: rotation vectors, closed forms (Rodrigues, the exact so(3) dexp⁻¹ and Cayley maps);
  - ``"so4"``: so(4) = so(3) ⊕ so(3) as the pair (p, q) (:func:`liesuslov.groups.so4_split`), the closed
    forms of :mod:`liesuslov.groups.so4` (exp as two Rodrigues factors, Cayley by four coefficients, dexp⁻¹
    the truncated so(3) series on each factor, dcay⁻¹ exact), as the numpy solver's so(4) kernel
    (:mod:`.so4`);
  - ``"dense"``: m×m matrices — so(n) (skew brackets, Padé scaling and squaring with the skew norm bound
    and a Newton–Schulz polish, Cayley by LU) or a general matrix algebra (se(2), se(3): full brackets,
    Padé with the 1-norm, Cayley by LU); dexp⁻¹ is the series ``Σ_{k < p-1} (B_k/k!) ad^k`` with the
    sign of the right side (:func:`liesuslov.groups.dexpinv_terms` terms);
  - ``"lowrank"``: Fedorov–Kozlov models (``Omega = u e_n^T - e_n u^T``): stage values ``Q M Q^T`` in a
    per-step orthonormal basis Q (n × r, r <= S + 1) built stage by stage by Gram–Schmidt (twice), as
    :class:`~.charts._LowRankKernel`: O(n r + r³) per stage, O(n² r) per step.

Layouts of an algebra element (a stage's ``h K_j``): so3 3 numbers ``(X21, X02, X10)``, so4 6 numbers
``(p, q)``, dense m² (row major), lowrank r² (the r×r coordinates M in the step's basis).

Shared closed forms: ``groups._cayley_coefficients`` and ``groups._dexp3_series`` are jitted as they stand;
``groups._rodrigues`` and ``groups._dexp3_coefficient`` branch on ``isinstance`` (numpy
arrays or floats) and cannot be compiled: :func:`.maps._rodrigues` and :func:`.maps._dexp3_coefficient` are
their scalar branches.
The so(4) closed forms of :mod:`liesuslov.groups.so4` are registered with ``numba.extending.register_jitable``
in :mod:`.so4` and compiled as they stand (its docstring names the two scalar branches written there).

Importing this module imports numba; ``import liesuslov`` does not import it.
"""


from __future__ import annotations

from ..compiled import CompilePlan, NotCompilable, compile_plan, numba_available  # noqa: F401

if not numba_available():  # imported directly (python -m ...kernel.warm): say what is missing, not numba's traceback
    raise ModuleNotFoundError("the compiled kernel needs numba: pip install 'liesuslov[fast]' (without it, "
                              "integrate runs on the numpy solver)", name="numba")

from .common import EVENT_CAP, KINDS, LOWRANK_MIN_N  # noqa: E402, F401
from .wrapper import check, kind_for, solve  # noqa: E402, F401

__all__ = ["solve", "check", "kind_for", "NotCompilable", "KINDS", "LOWRANK_MIN_N"]
