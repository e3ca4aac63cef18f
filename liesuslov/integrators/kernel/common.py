"""The kernel's shared pieces: the jit decorators, the codes of kinds, modes and charts, the formulas of
:mod:`~liesuslov.integrators.control` and :mod:`liesuslov.groups` compiled as they stand."""

from __future__ import annotations

from numba import njit

from ... import groups
from .. import control

KINDS = {None: 0, "so3": 1, "dense": 2, "lowrank": 3, "so4": 4}
MODES = {"none": 0, "gamma": 1, "g": 2}
CHARTS = {"exp": 0, "cayley": 1, None: 0}
#: Fedorov–Kozlov models from this n on run the low-rank kind (below, dense m×m work is as cheap).
LOWRANK_MIN_N = 8
#: First capacity of the per-(trajectory, event) crossing storage (the wrapper re-runs with more if needed).
EVENT_CAP = 16


def _jit(fn):
    if njit is None:
        return fn
    return njit(cache=True, nogil=True, error_model="numpy")(fn)


def _share(fn):
    """A scalar formula of :mod:`control` or :mod:`liesuslov.groups`, compiled as it stands."""
    if njit is None:
        return fn
    return njit(cache=True, nogil=True, error_model="numpy")(fn)


_scale = _share(control.scale)
_combine = _share(control.combine)
_accept_factor = _share(control.accept_factor)
_reject_factor = _share(control.reject_factor)
_initial_step = _share(control.initial_step)
_probe_step = _share(control.probe_step)
_cayley_coefficients = _share(groups._cayley_coefficients)
_dexp3_series = _share(groups._dexp3_series)


# Layout of the packed integer parameters
(_I_K, _I_M, _I_Q, _I_MODE, _I_CHART, _I_KIND, _I_SKEW, _I_HASG, _I_S, _I_SS, _I_NE, _I_P, _I_FSAL, _I_NEWIN,
 _I_ADAPT, _I_MAXST, _I_REPROJ, _I_RENORM, _I_NB, _I_NF, _I_NW, _I_NEV, _I_ORDER, _I_RECORD, _I_R, _I_A,
 _I_NT) = range(27)
_NHEAD = 27
_F_T0, _F_T1, _F_H, _F_RTOL, _F_ATOL, _F_EXPO = range(6)
_FHEAD = 6
