"""What a report family does unless it says otherwise: the leader–follower measures.

The error the convergence time is judged on is, at each point of a 0.1 s grid,
the mean over followers of each one's newest estimate error (agents tick on
their own clocks; NaN until every follower has an estimate); the headline
finals are the means over followers; the plots are the individual and average
error norms (thesis Figs. 3.4–3.7).  :class:`zswarm.families.contract.Family` takes each
report function a family leaves out from here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from zswarm.report import fault_costs as faults
from zswarm.report import table as text
from zswarm.report.decoded import Recording
from zswarm.report.series import nanmean, settle_time
from zswarm.scenario import Scenario
from zswarm.util import files

# Default thresholds of the convergence times (summary.json "convergence", zswarm sweep):
# |R̃|_I = sin(θ/2) below 1e-2 is θ < 1.15°; 0.1 m is 4 % of the §3.2 agents'
# typical 2.5 m spacing.  The §3.2 scenario crosses them at 11 s and 29 s (seed 1, sim).
THRESHOLDS = (1e-2, 0.1)
GRID_S = 0.1  # convergence is judged on this grid (newest estimate of each agent at each point)

Series = tuple[np.ndarray, np.ndarray, np.ndarray]  # (t, attitude, position) on a grid


def grid(duration: float) -> np.ndarray:
    return np.round(np.arange(0.0, duration + 1e-9, GRID_S), 6)


def metrics(sc: Scenario, rec: Recording) -> Any:
    return None


def summary(sc: Scenario, rec: Recording, m: Any, agents: dict[str, Any], duration: float) -> dict[str, Any]:
    return {}


def headline(sc: Scenario, agents: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    """summary.json's team figures: the means over followers of their final errors."""
    followers = [agents[str(a.id)] for a in sc.agents if a.role == "follower"]
    return {
        "mean_attitude_error_final": nanmean([f["attitude_error_final"] for f in followers]),
        "mean_position_error_final": nanmean([f["position_error_final"] for f in followers]),
        "mean_over": "followers",
    }


def series(sc: Scenario, errs: dict[int, np.ndarray], m: Any, duration: float) -> Series:
    """The mean over followers of each one's newest estimate error at each grid time."""
    t = grid(duration)
    cols_a, cols_p = [], []
    for a in sc.agents:
        if a.role != "follower":
            continue
        rows = errs.get(a.id, np.zeros((0, 4)))
        idx = np.searchsorted(rows[:, 0], t + 1e-9, side="right") - 1
        ok = idx >= 0
        ea, ep = np.full(len(t), np.nan), np.full(len(t), np.nan)
        ea[ok], ep[ok] = rows[idx[ok], 1], rows[idx[ok], 2]
        cols_a.append(ea)
        cols_p.append(ep)
    if not cols_a:
        return t, np.zeros(len(t)), np.zeros(len(t))
    return t, np.mean(cols_a, axis=0), np.mean(cols_p, axis=0)


def edges_on_grid(t_edges: np.ndarray, rel_att: dict[int, np.ndarray], rel_pos: dict[int, np.ndarray], duration: float, reduce: Any) -> Series:
    """Per-edge errors on their own grid ``t_edges`` brought to the 0.1 s grid (the newest value
    at or before each point) and reduced over the edges (``np.mean``, ``np.max``); position NaN
    without per-edge positions."""
    t = grid(duration)
    idx = np.clip(np.searchsorted(t_edges, t, side="right") - 1, 0, len(t_edges) - 1)
    att = reduce([v[idx] for v in rel_att.values()], axis=0)
    pos = np.mean([v[idx] for v in rel_pos.values()], axis=0) if rel_pos else np.full(len(t), np.nan)
    return t, att, pos


def read_edges_csv(path: Path, n_edges: int) -> tuple[np.ndarray, dict[int, np.ndarray], dict[int, np.ndarray]]:
    """``(t, |R̄_k|_I per edge, relative position error per edge)`` of an edges.csv."""
    d = np.genfromtxt(path, delimiter=",", names=True)
    edges = {k: d[d["edge"] == k] for k in range(1, n_edges + 1)}
    return edges[1]["t"], {k: e["relative_attitude_error"] for k, e in edges.items()}, {k: e["relative_position_error"] for k, e in edges.items()}


def convergence_of(t: np.ndarray, att: np.ndarray, pos: np.ndarray, measure: str, thresholds: tuple[float, float]) -> dict[str, Any]:
    """summary.json "convergence" from a family's series: the settle times below the thresholds."""
    out: dict[str, Any] = {
        "measure": measure,
        "grid_s": GRID_S,
        "attitude_threshold": thresholds[0],
        "attitude_s": settle_time(t, att, thresholds[0]),
    }
    if np.any(np.isfinite(pos)):
        out["position_threshold"] = thresholds[1]
        out["position_s"] = settle_time(t, pos, thresholds[1])
    return out


def convergence(sc: Scenario, errs: dict[int, np.ndarray], m: Any, duration: float, thresholds: tuple[float, float]) -> dict[str, Any]:
    t, att, pos = series(sc, errs, m, duration)
    return convergence_of(t, att, pos, "mean over followers", thresholds)


def finals(summary: dict[str, Any]) -> tuple[float | None, float | None]:
    """The team's final attitude and position errors in a summary (zswarm study)."""
    return summary["mean_attitude_error_final"], summary["mean_position_error_final"]


def series_from_files(folder: Path, sc: Scenario, duration: float) -> Series:
    """:func:`series` from a results folder's errors.csv (zswarm sweep)."""
    d = np.loadtxt(folder / "errors.csv", delimiter=",", skiprows=1, ndmin=2)
    errs = {int(i): d[d[:, 1] == i][:, [0, 2, 3]] for i in np.unique(d[:, 1])}
    return series(sc, errs, None, duration)


def write(out_dir: Path, sc: Scenario, rec: Recording, m: Any) -> None:
    """A family's own CSVs beside errors.csv (none here)."""


def plot(out: Path, sc: Scenario, errs: dict[int, np.ndarray], m: Any, rec: Recording | None = None) -> None:
    plot_errors(out, sc, errs, rec)


def table_lines(summary: dict[str, Any]) -> list[str]:
    return text.agent_rows(summary) + [text.mean_line(summary, "followers")]


def plot_errors(out: Path, sc: Scenario, errs: dict[int, np.ndarray], rec: Recording | None = None) -> None:
    """Individual and average error norms, like thesis figures 3.4–3.7; the faults and the
    agents' liveliness changes marked (faults.mark)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    followers = [a.id for a in sc.agents if a.role == "follower" and a.id in errs and len(errs[a.id])]
    for col, name, label in ((1, "attitude_error", r"$|R_i\hat R_i^T|_I$"), (2, "position_error", r"$\|\tilde p_i\|,\ \tilde p_i = p_i-\tilde R_i\hat p_i$")):
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
        t_grid = None
        for i in followers:
            e = errs[i]
            ax1.plot(e[:, 0], e[:, col], lw=1, label=f"agent {i}")
            if t_grid is None:
                t_grid = e[:, 0]
        if t_grid is not None:
            avg = np.mean([np.interp(t_grid, errs[i][:, 0], errs[i][:, col]) for i in followers], axis=0)
            ax2.plot(t_grid, avg, "k", lw=1.2)
        ax1.set_ylabel(label)
        ax1.set_title(f"{sc.name}: individual {name.replace('_', ' ')}s")
        ax1.legend(fontsize=7, ncol=3)
        ax2.set_ylabel("average over followers")
        ax2.set_xlabel("t (s)")
        for ax in (ax1, ax2):
            ax.grid(True, alpha=0.3)
            faults.mark(ax, sc, rec)
        fig.tight_layout()
        files.save_png(fig, out / f"{name}.png")
        plt.close(fig)


def plot_xi(out: Path, rec: Recording, title: str, ncol: int) -> None:
    """``xi.png``: ξ_k over time as each head reports it, its jumps marked (x)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    for k, xs in rec.edge_values.get("xi", {}).items():
        a = np.array(xs)
        ax.plot(a[:, 0], a[:, 1], lw=1, label=f"ξ_{k}")
    for _k, t, _b, after in rec.jumps:
        ax.plot([t], [after], "kx", ms=6)
    ax.set_xlabel("t (s)")
    ax.set_ylabel(r"$\xi_k$ (rad)")
    ax.set_title(title)
    ax.legend(fontsize=7, ncol=ncol)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    files.save_png(fig, out / "xi.png")
    plt.close(fig)
