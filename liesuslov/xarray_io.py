"""Solutions and ensembles as ``xarray.Dataset`` (optional extra ``liesuslov[xarray]``).

From there ``ds.to_netcdf(path)`` or ``ds.to_zarr(path)`` writes them for the tools researchers
already use. xarray is imported on the first call only.

Dimensions: ``time`` (with the output times as its coordinate), the batch axes ``batch_0``,
``batch_1``, ... (none for a single trajectory), and the components: ``xi_component`` (k, reduced
coordinates in D), ``omega_component`` (d, the algebra basis), ``gamma_component`` (n),
``g_row``/``g_column`` (m, m). ``Omega`` as matrices is not stored (it is ``so(n).hat(omega)``).
``status`` is a variable over the batch dims (a 0-d variable when the solver reports one status), and so is
each per-trajectory statistic (``t_stop``, ``failure``, ``trajectory_nfev``, ...: ``stats`` entries of the
batch's shape). Event records, one per event function ``j``, are variables over their own dimension
``event{j}_crossing``: ``event{j}_t``, ``event{j}_index`` (flat batch index), ``event{j}_omega``
(``omega_component``), ``event{j}_Gamma``, ``event{j}_g``. The attributes hold ``algebra_name``, ``n``,
``message`` and the other ``stats`` as a JSON string (netCDF attributes must be plain numbers and strings;
a non-finite number is written ``null``, as strict JSON has no NaN).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

__all__ = ["solution_to_xarray"]

_COMPONENTS = {"xi": ("xi_component",), "omega": ("omega_component",), "Gamma": ("gamma_component",),
               "g": ("g_row", "g_column")}


def _import_xarray():
    try:
        import xarray
    except ImportError as exc:
        raise ImportError("to_xarray needs xarray: pip install 'liesuslov[xarray]'") from exc
    return xarray


def _plain(x: Any) -> Any:
    """``x`` as plain JSON data: numpy scalars and arrays as numbers and lists, non-finite floats as None."""
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, np.generic):
        return _plain(x.item())
    if isinstance(x, float):
        return x if np.isfinite(x) else None
    if x is None or isinstance(x, (bool, int, str)):
        return x
    return str(x)


def solution_to_xarray(sol) -> Any:
    """A :class:`~liesuslov.Solution` (or :class:`~liesuslov.Ensemble`) as an ``xarray.Dataset``.

    Parameters
    ----------
    sol : Solution or Ensemble
        Anything with ``t`` (N,), ``omega`` (N, ..., d) and optionally ``xi``, ``Gamma``, ``g``,
        ``status``, ``stats``, ``message``, ``n``, ``algebra_name``.

    Returns
    -------
    xarray.Dataset
        Variables ``xi``, ``omega``, ``Gamma``, ``g`` (those present) with dims
        ``("time", "batch_0", ..., components...)``; ``status`` and the per-trajectory statistics with the
        batch dims; the event records over ``event{j}_crossing`` (module docstring).

    Raises
    ------
    ImportError
        If xarray is not installed (``pip install 'liesuslov[xarray]'``).
    """
    xr = _import_xarray()
    omega = np.asarray(sol.omega)
    batch_ndim = omega.ndim - 2
    batch_dims = tuple(f"batch_{i}" for i in range(batch_ndim))
    data_vars = {}
    for name, comps in _COMPONENTS.items():
        a = getattr(sol, name, None)
        if a is None:
            continue
        a = np.asarray(a)
        data_vars[name] = (("time",) + batch_dims + comps, a)
    status = np.asarray(getattr(sol, "status", 0))
    status_dims = batch_dims if status.ndim == batch_ndim and status.ndim else ()
    data_vars["status"] = (status_dims, status)
    stats = dict(getattr(sol, "stats", {}))
    for key, value in list(stats.items()):
        # per trajectory: a variable over the batch dims (a list in the JSON attribute would lose the dims)
        if isinstance(value, np.ndarray) and value.shape == status.shape and key not in data_vars:
            data_vars[key] = (status_dims, stats.pop(key))
    for j, rec in enumerate(getattr(sol, "events", None) or []):
        along = f"event{j}_crossing"
        for name, comps in (("t", ()), ("index", ()), ("omega", ("omega_component",)),
                            ("Gamma", ("gamma_component",)), ("g", ("g_row", "g_column"))):
            a = getattr(rec, name, None)
            if a is not None:
                data_vars[f"event{j}_{name}"] = ((along,) + comps, np.asarray(a))
    attrs = {"algebra_name": str(getattr(sol, "algebra_name", "")), "n": -1 if sol.n is None else int(sol.n),
             "message": str(getattr(sol, "message", "")),
             "stats": json.dumps(_plain(stats), allow_nan=False)}
    return xr.Dataset(data_vars, coords={"time": np.asarray(sol.t, dtype=float)}, attrs=attrs)
