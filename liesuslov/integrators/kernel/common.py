"""The kernel's shared pieces: the jit decorators, the codes of kinds, modes and charts, the formulas of
:mod:`~liesuslov.integrators.control` and :mod:`liesuslov.groups` compiled as they stand."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from numba import njit, types
from numba.core import cgutils
from numba.core.caching import FunctionCache, IndexDataCacheFile
from numba.extending import intrinsic, overload
from numba.np.arrayobj import make_array, populate_array

from ... import groups
from .. import control

KINDS = {None: 0, "so3": 1, "dense": 2, "lowrank": 3, "so4": 4}
#: The family each kind compiles in (one loop per family, the kind a run-time value within it): 0 no group part
#: (xi alone), 1 the closed forms (so3, so4), 2 the matrix algorithms (dense, lowrank).
FAMILIES = {0: 0, 1: 1, 4: 1, 2: 2, 3: 2}
MODES = {"none": 0, "gamma": 1, "g": 2}
CHARTS = {"exp": 0, "cayley": 1, None: 0}
#: Fedorov–Kozlov models from this n on run the low-rank kind (below, dense m×m work is as cheap).
LOWRANK_MIN_N = 8
#: First capacity of the per-(trajectory, event) crossing storage (the wrapper re-runs with more if needed).
EVENT_CAP = 16


#: Options of every compiled function of the kernel; :func:`_jit` adds the on-disk cache.
_JIT_OPTIONS = {"nogil": True, "error_model": "numpy"}


def sources_stamp(paths) -> bytes:
    """sha256 over the contents of ``paths`` (in the given order): the freshness stamp of the kernel's cache."""
    digest = hashlib.sha256()
    for path in paths:
        digest.update(Path(path).read_bytes())
    return digest.digest()


_PACKAGE = Path(__file__).resolve().parents[2]
#: The Python side of the kernel package: no compiled code (a change there does not make the cache stale).
_PYTHON_ONLY = ("__init__.py", "wrapper.py", "warm.py")
#: Every source file whose code is compiled into the kernel's functions.
KERNEL_SOURCES = tuple(sorted([*(p for p in (_PACKAGE / "integrators" / "kernel").glob("*.py")
                                 if p.name not in _PYTHON_ONLY),
                               _PACKAGE / "integrators" / "control.py", *(_PACKAGE / "groups").glob("*.py")]))
_STAMP = sources_stamp(KERNEL_SOURCES)


#: The kernel as the installation compiled it (:mod:`.warm`, run by the build: ``build_backend/``), beside this
#: file; read before numba's own cache. It holds a function only for the numba version, CPU and kernel sources
#: it was compiled with (numba's index key and :data:`_STAMP`): anything else finds nothing there and compiles.
PRECOMPILED_DIR = Path(__file__).resolve().with_name("_precompiled")
#: ``write``: the kernel's functions are read from and written to :data:`PRECOMPILED_DIR` only (the build's
#: precompile step); ``off``: it is not read (a measurement of the compilation itself); unset: read first.
PRECOMPILED_ENV = "LIESUSLOV_PRECOMPILED"


class _KernelCacheFile:
    """The index and data files of one kernel function: those of :data:`PRECOMPILED_DIR`, then numba's own
    (one :class:`~numba.core.caching.IndexDataCacheFile` each); a new compilation is written to numba's own
    place, or to :data:`PRECOMPILED_DIR` while the build precompiles (:data:`PRECOMPILED_ENV` ``write``)."""

    def __init__(self, cache_path: str, filename_base: str, source_stamp: bytes):
        setting = os.environ.get(PRECOMPILED_ENV, "")
        if setting not in ("", "write", "off"):
            raise ValueError(f"the environment variable {PRECOMPILED_ENV} must be 'write', 'off' or unset, got "
                             f"{setting!r}")
        precompiled = IndexDataCacheFile(cache_path=str(PRECOMPILED_DIR), filename_base=filename_base,
                                         source_stamp=source_stamp)
        own = IndexDataCacheFile(cache_path=cache_path, filename_base=filename_base, source_stamp=source_stamp)
        self._writing_precompiled = setting == "write"
        self._write = precompiled if self._writing_precompiled else own
        self._read = (precompiled,) if self._writing_precompiled else (own,) if setting == "off" else (precompiled, own)
        self._source_stamp = source_stamp

    def load(self, key):
        for files in self._read:
            data = files.load(key)
            if data is not None:
                return data
        return None

    def save(self, key, data) -> None:
        if self._writing_precompiled:
            PRECOMPILED_DIR.mkdir(exist_ok=True)
        self._write.save(key, data)

    def flush(self) -> None:
        self._write.flush()


class _KernelCache(FunctionCache):
    """numba's on-disk cache of one function, fresh only while *every* kernel source is unchanged, read first
    from the installation's precompiled kernel (:class:`_KernelCacheFile`).

    numba stamps a cached function with its own file's contents, but a compiled caller embeds its callees'
    code: after a change in a callee's file alone (``groups/so3.py`` under the loop of ``loop.py``), numba
    would load the caller compiled from the old callee. The stamp here covers :data:`KERNEL_SOURCES`.
    """

    def __init__(self, py_func):
        super().__init__(py_func)
        self._cache_file = _KernelCacheFile(self._cache_path, self._impl.filename_base, _STAMP)


def _jit(fn, entry: bool = False):
    """``fn`` compiled with :data:`_JIT_OPTIONS` and cached on disk under the kernel's stamp (:class:`_KernelCache`);
    also the scalar formulas of :mod:`control` and :mod:`liesuslov.groups`, compiled as they stand.

    Only an ``entry`` (:func:`_jit_entry`) can be called from Python: the others get neither the CPython nor
    the C wrapper, which numba would otherwise generate, optimise and compile for every function (unboxing each
    of up to 45 array arguments) although only compiled code calls them."""
    options = _JIT_OPTIONS if entry else {**_JIT_OPTIONS, "no_cpython_wrapper": True, "no_cfunc_wrapper": True}
    dispatcher = njit(**options)(fn)
    dispatcher._cache = _KernelCache(fn)
    return dispatcher


def _jit_entry(fn):
    """:func:`_jit` for a function Python calls (the loop): with numba's CPython wrapper."""
    return _jit(fn, entry=True)


@overload(control.ulp)
def _ulp_scalar(t, direction):
    """:func:`control.ulp` as it stands, for the compiled formulas that call it (underflow, step_floor,
    bracket_closed): numba resolves a call of a module-level Python function only through an overload."""
    return control.ulp


@overload(control.select, inline="always")
def _select_scalar(cond, a, b):
    """:func:`control.select` on scalars, as the compiled formulas below call it.

    Two returns, not ``a if cond else b``: inlined twice into one function, the conditional expression's
    merged variable gets the same name twice (numba's NumbaIRAssumptionWarning "not in scope")."""
    if isinstance(cond, types.Boolean):
        def impl(cond, a, b):
            if cond:
                return a
            return b

        return impl
    return None


def _jit_inline(fn):
    """``fn`` inlined into its callers at numba IR level (no compiled function, nor cache, of its own): the
    small functions of every stage, where a call that LLVM does not inline costs as much as the body."""
    return njit(inline="always", **_JIT_OPTIONS)(fn)


@intrinsic
def _view(typingctx, arr, offset, shape):
    """``arr``'s memory from the flat index ``offset`` on, as a C-contiguous array of ``shape`` (an int or a
    tuple of ints), *borrowed*: without the owner's meminfo, so that numba does not count references to it.

    Why: numba takes an atomic reference on the owner for every view made by indexing, slicing or reshape
    (reshape also calls a C helper), and every compiled function that calls another takes one for each of its
    array arguments, on entry and exit; on the 5×5 matrices of a dense stage these were ~30% of the step.
    A borrowed view (and every view of it, and every callee given it) is not counted. It must not outlive
    ``arr``: the kernel makes them of its scratch and arguments, inside one call.
    """
    if not (isinstance(arr, types.Array) and arr.layout == "C" and isinstance(offset, types.Integer)):
        return None
    if isinstance(shape, types.Integer):
        dim_types = (shape,)
    elif isinstance(shape, types.BaseTuple) and all(isinstance(t, types.Integer) for t in shape.types):
        dim_types = tuple(shape.types)
    else:
        return None
    ndim = len(dim_types)
    rettype = types.Array(arr.dtype, ndim, "C")

    def codegen(context, builder, sig, args):
        src = make_array(sig.args[0])(context, builder, args[0])
        raw = [args[2]] if isinstance(shape, types.Integer) else cgutils.unpack_tuple(builder, args[2], ndim)
        dims = [context.cast(builder, v, t, types.intp) for v, t in zip(raw, dim_types, strict=True)]
        strides = [None] * ndim
        step = src.itemsize
        for i in range(ndim - 1, -1, -1):
            strides[i] = step
            step = builder.mul(step, dims[i])
        data = builder.gep(src.data, [context.cast(builder, args[1], sig.args[1], types.intp)])
        out = make_array(rettype)(context, builder)
        populate_array(out, data=data, shape=dims, strides=strides, itemsize=src.itemsize, meminfo=None)
        return out._getvalue()

    return rettype(arr, offset, shape), codegen


@_jit_inline
def _borrow(arr):
    """``arr`` itself as a borrowed view (:func:`_view`): what the kernel passes to the group operations."""
    return _view(arr, 0, arr.shape)


_scale = _jit(control.scale)
_combine = _jit(control.combine)
_accept_factor = _jit(control.accept_factor)
_reject_factor = _jit(control.reject_factor)
_initial_step = _jit(control.initial_step)
_probe_step = _jit(control.probe_step)
_underflow = _jit(control.underflow)
_step_floor = _jit(control.step_floor)
_fixed_steps = _jit(control.fixed_steps)
_on_surface_at_start = _jit(control.on_surface_at_start)
_crossed = _jit(control.crossed)
_secant_point = _jit(control.secant_point)
_illinois_update = _jit(control.illinois_update)
_closest_end = _jit(control.closest_end)
_bracket_closed = _jit(control.bracket_closed)
_cayley_coefficients = _jit(groups._cayley_coefficients)
_dexp3_series = _jit(groups._dexp3_series)


# Layout of the packed integer parameters
(_I_K, _I_M, _I_Q, _I_MODE, _I_CHART, _I_KIND, _I_SKEW, _I_HASG, _I_S, _I_SS, _I_NE, _I_P, _I_FSAL, _I_NEWIN,
 _I_ADAPT, _I_MAXST, _I_REPROJ, _I_RENORM, _I_NB, _I_NF, _I_NW, _I_NEV, _I_ORDER, _I_RECORD, _I_R, _I_A,
 _I_DOM) = range(27)
_NHEAD = 27
_F_T0, _F_T1, _F_H, _F_RTOL, _F_ATOL, _F_EXPO, _F_DOMAIN = range(7)
_FHEAD = 7
