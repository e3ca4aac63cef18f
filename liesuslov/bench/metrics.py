"""What is computed from a run: errors against the reference, structure defects and integral drifts,
the time a route needs to reach an error level, the ratio table and the fitted growth exponent."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from .config import GOAL_RATIO
from .scenes import BenchScene


def max_abs(a, b) -> float:
    """Largest absolute componentwise difference of two arrays."""
    return float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))))


@dataclass
class Reference:
    """The reference state at t1 of a scene, how far its independent determinations disagree, and how."""

    omega: np.ndarray
    Gamma: np.ndarray | None
    g: np.ndarray | None
    extra: dict
    uncertainty: float
    details: dict


def run_metrics(scene: BenchScene, ref: Reference, omega, Gamma, g) -> dict:
    """Errors at t1 against the reference, structure defects and integral drifts over the trajectory."""
    nan = float("nan")
    row: dict = {"err_Omega": max_abs(omega[-1], ref.omega), "err_Gamma": nan, "err_g": nan, "err_pendulum": nan}
    if Gamma is not None and ref.Gamma is not None:
        row["err_Gamma"] = max_abs(Gamma[-1], ref.Gamma)
    if g is not None and ref.g is not None:
        row["err_g"] = max_abs(g[-1], ref.g)
    if ref.extra and scene.extra is not None and g is not None:
        got = scene.extra(omega[-1], None if Gamma is None else Gamma[-1], g[-1])
        row["err_pendulum"] = max(max_abs(got[k], ref.extra[k]) for k in ref.extra)
    errs = [row[k] for k in ("err_Omega", "err_Gamma", "err_g", "err_pendulum") if np.isfinite(row[k])]
    row["error"] = max(errs) if errs else nan
    if g is not None:
        m = g.shape[-1]
        row["orth_defect"] = float(np.max(np.abs(np.swapaxes(g, -1, -2) @ g - np.eye(m))))
    else:
        row["orth_defect"] = nan
    row["sphere_defect"] = (float(np.max(np.abs(np.linalg.norm(Gamma, axis=-1) - 1.0)))
                            if Gamma is not None else nan)
    A = np.asarray(scene.system.covectors, dtype=float)
    row["constraint_defect"] = float(np.max(np.abs(omega @ A.T), initial=0.0)) if A.size else 0.0
    drifts = {}
    for name, F in scene.integrals.items():
        vals = np.asarray(F(omega, Gamma), dtype=float)
        drifts[name] = float(np.max(np.abs(vals - vals[0])))
    row["drift_energy"] = drifts.get("energy", nan)
    others = [v for k, v in drifts.items() if k != "energy"]
    row["drift_integrals"] = max(others) if others else nan
    row["drifts"] = ";".join(f"{k}={v:.3e}" for k, v in drifts.items())
    return row


def nan_row() -> dict:
    """The metric columns of a failed run: NaN everywhere."""
    nan = float("nan")
    return {k: nan for k in ("err_Omega", "err_Gamma", "err_g", "err_pendulum", "error", "orth_defect",
                             "sphere_defect", "constraint_defect", "drift_energy", "drift_integrals")} | {"drifts": ""}


def time_to_reach(points: Iterable[tuple[float, float]], level: float) -> float:
    """Time a route needs to reach ``error <= level``, from its sweep ``[(error, time), ...]``.

    Along consecutive sweep points whose errors straddle ``level``, ``log time`` is interpolated
    linearly in ``log error``; a point already at or below ``level`` counts with its own time.
    The smallest candidate is returned; ``inf`` when no point reaches ``level``.

    Parameters
    ----------
    points : iterable of (error, time)
        In sweep order (coarse to fine); non-finite entries are skipped.
    level : float
    """
    pts = [(float(e), float(t)) for e, t in points if np.isfinite(e) and np.isfinite(t) and t > 0]
    best = math.inf
    for e, t in pts:
        if e <= level:
            best = min(best, t)
    for (e1, t1), (e2, t2) in zip(pts[:-1], pts[1:], strict=True):
        if e1 > 0 and e2 > 0 and (e1 - level) * (e2 - level) < 0:
            f = (math.log(level) - math.log(e1)) / (math.log(e2) - math.log(e1))
            best = min(best, math.exp(math.log(t1) + f * (math.log(t2) - math.log(t1))))
    return best


def _fastest(rows: list[dict], level: float) -> tuple[float, str]:
    """(time, route) of the route among ``rows`` that reaches ``level`` first (``inf``, "" when none does)."""
    routes: dict[str, list] = {}
    for r in rows:
        if r["status"] == "ok":
            routes.setdefault(r["route"], []).append(r)
    best, name = math.inf, ""
    for route, rs in routes.items():
        rs = sorted(rs, key=lambda r: -r["setting"])  # coarse to fine: decreasing h or rtol
        t = time_to_reach([(r["error"], r["wall_time"]) for r in rs], level)
        if t < best:
            best, name = t, route
    return best, name


def ratio_table(rows: list[dict], scenes: Sequence[str], levels: Sequence[float], refs: dict) -> list[dict]:
    """Per scene and level: the fastest route of each library, their ratio, and the ratio to scipy's DOP853."""
    out = []
    for s in scenes:
        srows = [r for r in rows if r["scene"] == s]
        unc = refs[s]["uncertainty"]
        for level in levels:
            lt, lr = _fastest([r for r in srows if r["library"] == "liesuslov"], level)
            st, sr = _fastest([r for r in srows if r["library"] == "scipy"], level)
            dt, _ = _fastest([r for r in srows if r["route"] == "scipy DOP853"], level)
            # adaptive against adaptive: liesuslov's rtol sweeps only (no route whose step was chosen for the scene)
            at, ar = _fastest([r for r in srows if r["library"] == "liesuslov" and r["setting_kind"] == "rtol"], level)
            ratio = lt / st if np.isfinite(lt) and np.isfinite(st) else float("nan")
            out.append({"scene": s, "level": level, "liesuslov_time": lt, "liesuslov_route": lr,
                        "scipy_time": st, "scipy_route": sr, "ratio": ratio, "dop853_time": dt,
                        "ratio_dop853": lt / dt if np.isfinite(lt) and np.isfinite(dt) else float("nan"),
                        "adaptive_route": ar,
                        "ratio_adaptive": at / dt if np.isfinite(at) and np.isfinite(dt) else float("nan"),
                        "goal_met": bool(np.isfinite(ratio) and ratio <= GOAL_RATIO),
                        "reliable": bool(level >= 10 * unc)})
    return out


def scaling_key(row: dict) -> str:
    """``"backend/chart"`` of an n-scaling row (the chart alone when the library's default backend ran)."""
    return f"{row['requested']}/{row['chart']}" if row.get("requested", "default") != "default" else row["chart"]


def fit_exponent(rows: list[dict]) -> dict:
    """Least-squares slope of log(us per step) against log n, per backend and chart.

    Over the three largest sizes that ran (the small ones measure the fixed cost per call, not the growth).
    """
    out = {}
    for key in dict.fromkeys(scaling_key(r) for r in rows):
        ok = sorted((r for r in rows if scaling_key(r) == key and r.get("status") == "ok"), key=lambda r: r["n"])
        use = ok[-3:]
        if len(use) >= 2:
            x = np.log([r["n"] for r in use])
            y = np.log([r["us_per_step"] for r in use])
            out[key] = {"exponent": float(np.polyfit(x, y, 1)[0]),
                        "sizes": f"{min(r['n'] for r in use)}..{max(r['n'] for r in use)}",
                        # the slope between the two largest sizes (the growth still rising there shows)
                        "last_slope": float((y[-1] - y[-2]) / (x[-1] - x[-2]))}
    return out
