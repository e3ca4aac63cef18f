"""What an integration returns: arrays with the time axis first, statistics, status."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .problem import SUCCESS_MESSAGE

__all__ = ["Solution"]

_ARRAYS = ("t", "xi", "omega", "Gamma", "g")
_STAT = "__stats__"  # file keys of the per-trajectory statistics (arrays)
_EVENT = "__event"  # file keys of the event records: __event{j}__{field}
_EVENT_FIELDS = ("t", "index", "omega", "Gamma", "g")


@dataclass
class Solution:
    """The result of :func:`liesuslov.integrate`.

    Arrays put the time axis first, then the batch axes: ``sol.Gamma[k]`` is the state at ``sol.t[k]``.

    Attributes
    ----------
    t : ndarray, shape (N,)
    xi : ndarray, shape (N, ..., k)
        Reduced coordinates of Omega in the constraint subspace's basis (what was integrated).
    omega : ndarray, shape (N, ..., d)
        Coordinates of Omega in the algebra basis.
    Gamma : ndarray, shape (N, ..., n), or None
        The vertical in body coordinates, when the scene has it.
    g : ndarray, shape (N, ..., n, n), or None
        The attitude (in the algebra's matrix representation), when reconstructed.
    stats : dict
        ``nfev``, ``steps`` (accepted), ``rejected`` summed over the trajectories, and per trajectory
        ``trajectory_nfev``, ``trajectory_steps``, ``trajectory_rejected``, ``t_stop`` and ``failure`` (...: 0, or
        the code of why it failed, a key of :data:`~.problem.FAILURES`); ``method``,
        ``chart``, ``form``, ``backend`` (``"numba"`` or ``"numpy"``), ``backend_reason``, ``kernel``,
        ``state_dim``, ``batch``, ``wall_time``.
    status : ndarray of int, shape (...)
        Per trajectory: 0 reached the end of t_span, 1 stopped by a terminal event, -1 failed (the time is
        ``stats["t_stop"]``, the reason in ``stats["failure"]`` and, for the first, in ``message``). Every output
        after a trajectory stopped is NaN.
    message : str
    events : list of EventRecord
        One record per event function passed to ``integrate`` (empty without events).
    n : int or None
        Matrix size of the representation (n for so(n)); used by :attr:`Omega`.
    """

    t: np.ndarray
    xi: np.ndarray
    omega: np.ndarray
    Gamma: np.ndarray | None = None
    g: np.ndarray | None = None
    stats: dict = field(default_factory=dict)
    status: np.ndarray | int = 0
    message: str = SUCCESS_MESSAGE
    n: int | None = None
    algebra_name: str = ""
    events: list = field(default_factory=list)
    _dense: object = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.status = np.asarray(self.status, dtype=np.int64)

    @property
    def success(self) -> bool:
        """True iff no trajectory failed (every status >= 0)."""
        return bool(np.all(self.status >= 0))

    def at(self, t) -> Solution:
        """The state at times ``t`` (M,) inside t_span, as a Solution (``integrate(..., dense_output=True)``).

        From the method's continuous extension in the chart, ``g = g_k phi(Theta(theta))`` and
        ``Gamma = phi(-Theta(theta)) Gamma_k``: g in SO(n) and |Gamma| = 1 to rounding, the constraints exact,
        with the accuracy of the steps; NaN after a trajectory stopped. The steps are those of the original
        run (the solve is repeated with ``t`` as output times: a trajectory's steps do not depend on them).
        A pickled Solution keeps its dense output when its problem pickles (a system of module-level callables,
        events that pickle); a saved one (npz, xarray) keeps its arrays only.

        Raises
        ------
        ValueError
            Without ``dense_output=True``, or for a time outside t_span.
        """
        if self._dense is None:
            raise ValueError("sol.at(t) needs the Solution of integrate(..., dense_output=True) (one read by "
                             "Solution.load keeps its arrays only, not the dense output)")
        if self._dense is False:
            raise ValueError("sol.at(t): this Solution was pickled or copied while its problem does not pickle (a "
                             "lambda potential or event?): the copy keeps the arrays, not the dense output; call "
                             "at() on the Solution integrate returned (or integrate again)")
        return self._dense(t)

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        if state["_dense"]:  # the replay (the problem: model, initial data, events) goes along if it pickles
            import pickle

            try:
                pickle.dumps(state["_dense"])
            except Exception:  # noqa: BLE001 - a lambda potential or event: the arrays still pickle
                state["_dense"] = False  # (and at() says why it has no dense output)
        return state

    @property
    def Omega(self) -> np.ndarray | None:
        """Omega as skew matrices (N, ..., n, n) on so(n); None on other algebras."""
        if not self.algebra_name.startswith("so(") or self.n is None:
            return None
        from ..algebra import so

        Omega = so(self.n).hat(self.omega)
        gone = np.isnan(self.omega).any(axis=-1)  # after a stop: NaN on the diagonal too
        if gone.any():
            Omega[gone] = np.nan
        return Omega

    def __repr__(self) -> str:
        shape = self.omega.shape
        parts = [f"t: {self.t.shape}", f"omega: {shape}"]
        if self.Gamma is not None:
            parts.append(f"Gamma: {self.Gamma.shape}")
        if self.g is not None:
            parts.append(f"g: {self.g.shape}")
        return f"Solution(success={self.success}, {', '.join(parts)}, message={self.message!r})"

    # ------------------------------------------------------------------ persistence
    def save(self, path) -> Path:
        """Write every array, the events, the stats and the status to a ``.npz`` file (lossless round trip;
        not the dense output)."""
        path = Path(path)
        arrays = {name: getattr(self, name) for name in _ARRAYS if getattr(self, name) is not None}
        stats = {}
        for key, value in self.stats.items():
            if isinstance(value, np.ndarray):  # per-trajectory statistics stay arrays
                arrays[f"{_STAT}{key}"] = value
            else:
                stats[key] = value
        for j, rec in enumerate(self.events):
            for field_name in _EVENT_FIELDS:
                value = getattr(rec, field_name)
                if value is not None:
                    arrays[f"{_EVENT}{j}__{field_name}"] = value
        meta = {"stats": stats, "status": self.status.tolist(), "message": self.message, "n": self.n,
                "algebra_name": self.algebra_name, "events": len(self.events)}
        np.savez(path, **arrays, __meta__=np.array(json.dumps(meta, default=_jsonable)))
        return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")

    @classmethod
    def load(cls, path) -> Solution:
        """Read a file written by :meth:`save` (a damaged or foreign file: ValueError naming it).

        The arrays, statistics and event records come back; a dense output does not (``at`` needs the
        Solution of ``integrate``, or one unpickled from it)."""
        from .._io import read_npz
        from .events import EventRecord

        with read_npz(Path(path), f"the file {str(path)!r}", "load a file written by Solution.save") as data:
            arrays = {name: data[name] for name in _ARRAYS if name in data.files}
            meta = json.loads(str(data["__meta__"]))
            stats = {**meta["stats"], **{k[len(_STAT):]: data[k] for k in data.files if k.startswith(_STAT)}}
            events = []
            for j in range(meta.get("events", 0)):
                fields = {f: data[f"{_EVENT}{j}__{f}"] if f"{_EVENT}{j}__{f}" in data.files else None
                          for f in _EVENT_FIELDS}
                events.append(EventRecord(**fields, n=meta["n"], algebra_name=meta["algebra_name"]))
            return cls(**arrays, stats=stats, status=np.asarray(meta["status"], dtype=np.int64),
                       message=meta["message"], n=meta["n"], algebra_name=meta["algebra_name"], events=events)

    def to_xarray(self):
        """An ``xarray.Dataset``: dims ``time``, ``batch_0``..., components (needs ``liesuslov[xarray]``)."""
        from ..xarray_io import solution_to_xarray

        return solution_to_xarray(self)


def _jsonable(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)
