"""The figures: work-precision per scene, batch throughput, cost per step against n (matplotlib, Agg).

Each function draws and returns the figure; :mod:`.files` writes it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .metrics import scaling_key


def _figure(figsize: tuple[float, float]):
    """(pyplot, figure, axes) on the Agg backend: the benchmark only writes files, it never opens windows."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=figsize)
    return plt, fig, ax


def have_matplotlib() -> bool:
    """Whether matplotlib can be imported (the plots are skipped without it)."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def plot_scene(scene_key: str, title: str, rows: list[dict], levels: Sequence[float]):
    """Error at t1 against wall time of every route of one scene (log-log)."""
    plt, fig, ax = _figure((9.5, 5.5))
    routes: dict[str, list] = {}
    for r in rows:
        if r["scene"] == scene_key and r["status"] == "ok" and np.isfinite(r["error"]) and r["error"] > 0:
            routes.setdefault(r["route"], []).append(r)
    colors = plt.get_cmap("tab10")
    lie_methods = sorted({r["method"] for rs in routes.values() for r in rs if r["library"] == "liesuslov"})
    scipy_marks = {"RK45": "s", "DOP853": "D", "Radau": "^"}
    for route, rs in sorted(routes.items()):
        rs = sorted(rs, key=lambda r: -r["setting"])
        t = [r["wall_time"] for r in rs]
        e = [r["error"] for r in rs]
        if rs[0]["library"] == "scipy":
            ax.loglog(t, e, "--", color="black", marker=scipy_marks.get(rs[0]["method"], "x"), ms=5, lw=1.2,
                      label=route)
        else:
            c = colors(lie_methods.index(rs[0]["method"]) % 10)
            ls_ = ":" if rs[0]["chart"] == "cayley" else "-"
            ax.loglog(t, e, ls_, color=c, marker="o", ms=3, lw=1.2, label=route)
    for lv in levels:
        ax.axhline(lv, color="0.85", lw=0.6, zorder=0)
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel("error at t1 (max abs)")
    ax.set_title(title)
    ax.legend(fontsize=6.5, ncol=2, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    return fig


def plot_throughput(rows: list[dict]):
    """ns per trajectory-step against the batch size."""
    _, fig, ax = _figure((6, 4))
    for n in sorted({r["n"] for r in rows}):
        rs = [r for r in rows if r["n"] == n and r["status"] == "ok"]
        ax.loglog([r["batch"] for r in rs], [r["ns_per_traj_step"] for r in rs], "o-", label=f"n = {n}")
    ax.axhline(1000.0, color="0.6", ls="--", lw=0.8, label="1 µs")
    ax.set_xlabel("batch size")
    ax.set_ylabel("ns per trajectory-step")
    ax.set_title("RKMK4 with reconstruction: batch throughput")
    ax.legend()
    fig.tight_layout()
    return fig


def plot_scaling(rows: list[dict], fits: dict):
    """µs per step against n, per backend and chart, with the fitted exponents."""
    _, fig, ax = _figure((6.5, 4.5))
    for key in dict.fromkeys(scaling_key(r) for r in rows):
        rs = [r for r in rows if scaling_key(r) == key and r.get("status") == "ok"]
        if not rs:
            continue
        label = key + (f" (∝ n^{fits[key]['exponent']:.2f})" if key in fits else "")
        ax.loglog([r["n"] for r in rs], [r["us_per_step"] for r in rs], "o-", label=label)
    ok = [r for r in rows if r.get("status") == "ok"]
    if ok:
        n0, t0 = ok[0]["n"], ok[0]["us_per_step"]
        ns = np.array(sorted({r["n"] for r in ok}), dtype=float)
        ax.loglog(ns, t0 * (ns / n0) ** 2, color="0.6", ls="--", lw=0.8, label="∝ n²")
    ax.set_xlabel("n")
    ax.set_ylabel("µs per step")
    ax.set_title("RKMK4 + reconstruction, Fedorov–Kozlov D")
    ax.legend()
    fig.tight_layout()
    return fig
