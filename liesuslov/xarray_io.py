"""Solutions and ensembles as ``xarray.Dataset`` (optional extra ``liesuslov[xarray]``).

From there ``ds.to_netcdf(path)`` or ``ds.to_zarr(path)`` writes them for the tools researchers
already use. xarray is imported on the first call only.

Dimensions: ``time`` (with the output times as its coordinate), the batch axes ``batch_0``,
``batch_1``, ... (none for a single trajectory), and the components: ``xi_component`` (k, reduced
coordinates in D), ``omega_component`` (d, the algebra basis), ``gamma_component`` (n),
``g_row``/``g_column`` (m, m). ``Omega`` as matrices is not stored (it is ``so(n).hat(omega)``).
``status`` is a variable over the batch dims (a 0-d variable when the solver reports one status).
The attributes hold ``algebra_name``, ``n``, ``message`` and ``stats`` as a JSON string (netCDF
attributes must be plain numbers and strings).
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
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
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
        ``("time", "batch_0", ..., components...)`` and ``status`` with the batch dims.

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
    data_vars["status"] = (batch_dims if status.ndim == batch_ndim and status.ndim else (), status)
    attrs = {"algebra_name": str(getattr(sol, "algebra_name", "")), "n": -1 if sol.n is None else int(sol.n),
             "message": str(getattr(sol, "message", "")),
             "stats": json.dumps(getattr(sol, "stats", {}), default=_plain)}
    return xr.Dataset(data_vars, coords={"time": np.asarray(sol.t, dtype=float)}, attrs=attrs)
