"""The kernel's shared pieces: the jit decorators, the codes of kinds, modes and charts, the formulas of
:mod:`~liesuslov.integrators.control` and :mod:`liesuslov.groups` compiled as they stand."""

from __future__ import annotations

from numba import njit

from ... import groups
from .. import control

KINDS = {None: 0, "so3": 1, "dense": 2, "lowrank": 3, "so4": 4}
#: The family each kind compiles in (one loop per family, the kind a run-time value within it): 1 the closed
#: forms (so3, so4, and no group part), 2 the matrix algorithms (dense, lowrank).
FAMILIES = {0: 1, 1: 1, 4: 1, 2: 2, 3: 2}
MODES = {"none": 0, "gamma": 1, "g": 2}
CHARTS = {"exp": 0, "cayley": 1, None: 0}
#: Fedorov–Kozlov models from this n on run the low-rank kind (below, dense m×m work is as cheap).
LOWRANK_MIN_N = 8
#: First capacity of the per-(trajectory, event) crossing storage (the wrapper re-runs with more if needed).
EVENT_CAP = 16


#: Options of every compiled function of the kernel (the kind implementations of :mod:`.group` too).
_JIT_OPTIONS = {"cache": True, "nogil": True, "error_model": "numpy"}


def _jit(fn):
    """``fn`` compiled with :data:`_JIT_OPTIONS`; also the scalar formulas of :mod:`control` and
    :mod:`liesuslov.groups`, compiled as they stand."""
    return njit(**_JIT_OPTIONS)(fn)


_scale = _jit(control.scale)
_combine = _jit(control.combine)
_accept_factor = _jit(control.accept_factor)
_reject_factor = _jit(control.reject_factor)
_initial_step = _jit(control.initial_step)
_probe_step = _jit(control.probe_step)
_cayley_coefficients = _jit(groups._cayley_coefficients)
_dexp3_series = _jit(groups._dexp3_series)


# Layout of the packed integer parameters
(_I_K, _I_M, _I_Q, _I_MODE, _I_CHART, _I_KIND, _I_SKEW, _I_HASG, _I_S, _I_SS, _I_NE, _I_P, _I_FSAL, _I_NEWIN,
 _I_ADAPT, _I_MAXST, _I_REPROJ, _I_RENORM, _I_NB, _I_NF, _I_NW, _I_NEV, _I_ORDER, _I_RECORD, _I_R, _I_A) = range(26)
_NHEAD = 26
_F_T0, _F_T1, _F_H, _F_RTOL, _F_ATOL, _F_EXPO = range(6)
_FHEAD = 6
