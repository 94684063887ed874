"""The §4 observers (Figs. 4.4–4.9): estimates up to a common rotation (and translation).

On a 100 Hz grid using each agent's newest estimate:

* per edge k (head h, tail t): ``|R̄_k|_I = |R̃_t^T R̃_h|_I`` with ``R̃_i = R_i R̂_i^T``,
  and the relative position error ``||p̃_h − p̃_t||`` with ``p̃_i = R̃_i p̂_i − p_i``
  (thesis (4.33));
* per agent, "up to a common frame": ``|R̃_i R̃_c^T|_I`` with R̃_c the chordal
  mean of the R̃_i (the nearest rotation to their average), and
  ``||p̃_i − mean_q p̃_q||``;
* ξ_k over time and every jump (time, edge, ξ before/after), from the heads.

The team's measure (convergence, zswarm sweep and study) is the mean over edges of
|R̄_k|_I and of the relative position error.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zswarm.families.contract import Basin, Batched, Command, Family, Recipe, Report
from zswarm.families.synergistic import HYBRID_PARAMS_4, design_arguments, design_command
from zswarm.families.tree_measures import BASIN_GRID_S, TreeStamps, TreeTicks
from zswarm.math.so3 import nearest_rotations
from zswarm.report import base
from zswarm.report import table as text
from zswarm.report.decoded import Recording, estimates_with_truth
from zswarm.report.series import final, settle_time
from zswarm.scenario import Scenario
from zswarm.util import files


@dataclass
class TreeMetrics:
    """§4 metrics on a common time grid (see the module docstring)."""

    t: np.ndarray  # (T,)
    rel_att: dict[int, np.ndarray]  # edge k -> |R̄_k|_I, (T,)
    rel_pos: dict[int, np.ndarray]  # edge k -> ||p̃_h − p̃_t||, (T,)
    att_common: dict[int, np.ndarray]  # agent -> |R̃_i R̃_c^T|_I
    pos_common: dict[int, np.ndarray]  # agent -> ||p̃_i − mean p̃||


def tree_metrics(sc: Scenario, rec: Recording, step: float = 0.01) -> TreeMetrics | None:
    """Relative and common-frame errors of the §4 observers (None if some agent has no estimate)."""
    col = {i: k for k, i in enumerate(rec.truth_ids)}
    Rt: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    for i in sc.ids:
        t, R_hat, p_hat, R, p = estimates_with_truth(rec, rec.est.get(i, []), col[i])
        if not len(t):
            return None
        R_tilde = R @ R_hat.transpose(0, 2, 1)
        Rt[i] = (t, R_tilde, np.einsum("nij,nj->ni", R_tilde, p_hat) - p)
    t0 = max(v[0][0] for v in Rt.values())
    t1 = max(v[0][-1] for v in Rt.values())
    grid = np.arange(t0, t1 + 1e-9, step)
    idx = {i: np.searchsorted(v[0], grid, side="right") - 1 for i, v in Rt.items()}
    Rg = {i: Rt[i][1][idx[i]] for i in sc.ids}
    pg = {i: Rt[i][2][idx[i]] for i in sc.ids}
    rel_att, rel_pos = {}, {}
    for k, (h, tl) in enumerate(sc.oriented, start=1):
        Rbar = np.einsum("tji,tjk->tik", Rg[tl], Rg[h])
        rel_att[k] = np.sqrt(np.clip((3.0 - np.trace(Rbar, axis1=1, axis2=2)) / 4.0, 0.0, 1.0))
        rel_pos[k] = np.linalg.norm(pg[h] - pg[tl], axis=1)
    Rc = nearest_rotations(np.mean([Rg[i] for i in sc.ids], axis=0))
    pc = np.mean([pg[i] for i in sc.ids], axis=0)
    att_common, pos_common = {}, {}
    for i in sc.ids:
        E = np.einsum("tij,tkj->tik", Rg[i], Rc)
        att_common[i] = np.sqrt(np.clip((3.0 - np.trace(E, axis1=1, axis2=2)) / 4.0, 0.0, 1.0))
        pos_common[i] = np.linalg.norm(pg[i] - pc, axis=1)
    return TreeMetrics(grid, rel_att, rel_pos, att_common, pos_common)


def summary(sc: Scenario, rec: Recording, tm: TreeMetrics | None, agents: dict[str, Any], t_end: float) -> dict[str, Any]:
    """Per-edge relative errors, ξ and jumps; per-agent errors up to a common frame (in place)."""
    pose = "bearings" in sc.info.sensors  # §4.4 estimates positions too
    edges: dict[str, Any] = {}
    for k, (h, tl) in enumerate(sc.oriented, start=1):
        js = [j for j in rec.jumps if j[0] == k]
        xs = rec.edge_values.get("xi", {}).get(k, [])
        e: dict[str, Any] = {"head": h, "tail": tl, "xi_owner": h}
        if tm is not None:
            e["relative_attitude_error_final"] = final(tm.t, tm.rel_att[k], t_end)
            e["relative_attitude_error_max_after_10s"] = float(np.max(tm.rel_att[k][tm.t >= 10.0])) if np.any(tm.t >= 10.0) else None
            e["relative_attitude_error_settles_below_1e-2_at"] = settle_time(tm.t, tm.rel_att[k], 1e-2)
            if pose:
                e["relative_position_error_final"] = final(tm.t, tm.rel_pos[k], t_end)
        if getattr(sc.params, "Xi", ()):
            e["jumps"] = len(js)
            e["jumps_reported_by_head"] = int(rec.stats.get(("agent", h), {}).get("jumps", {}).get(str(k), len(js)))
            e["jump_log"] = [{"t": t, "xi_before": b, "xi_after": a} for _, t, b, a in js]
            e["xi_final"] = xs[-1][1] if xs else None
        edges[str(k)] = e
    out: dict[str, Any] = {
        "orientation": sc.oriented_from,
        "edges": edges,
        "errors_up_to": (
            "common frame: an agent's attitude_error_final is |R̃_i R̃_c^T|_I (R̃_i = R_i R̂_i^T, R̃_c their chordal mean)"
            + (", position_error_final is ||p̃_i − mean_q p̃_q|| with p̃_i = R̃_i p̂_i − p_i (thesis (4.33))" if pose else "")
            + "; the thesis' own measure is the per-edge |R̄_k|_I (edges.*.relative_attitude_error_final)"
        ),
    }
    if tm is not None:
        for i in sc.ids:
            agents[str(i)]["attitude_error_final"] = final(tm.t, tm.att_common[i], t_end)
            agents[str(i)]["position_error_final"] = final(tm.t, tm.pos_common[i], t_end) if pose else float("nan")
        out["mean_relative_attitude_error_final"] = float(np.mean([e["relative_attitude_error_final"] for e in edges.values()]))
        out["max_relative_attitude_error_final"] = float(np.max([e["relative_attitude_error_final"] for e in edges.values()]))
        if pose:
            out["mean_relative_position_error_final"] = float(np.mean([e["relative_position_error_final"] for e in edges.values()]))
            out["max_relative_position_error_final"] = float(np.max([e["relative_position_error_final"] for e in edges.values()]))
    if getattr(sc.params, "Xi", ()):
        out["jumps_total"] = len(rec.jumps)
    return out


def write_edges_csv(path: Path, sc: Scenario, tm: TreeMetrics, rec: Recording) -> None:
    """Per edge on the 100 Hz grid: |R̄_k|_I, relative position error, ξ_k (newest from the head)."""
    pose = "bearings" in sc.info.sensors
    with files.whole(path) as tmp, open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "edge", "head", "tail", "relative_attitude_error", "relative_position_error", "xi"])
        for k, (h, tl) in enumerate(sc.oriented, start=1):
            xs = rec.edge_values.get("xi", {}).get(k, [])
            xt = np.array([x[0] for x in xs])
            xv = np.array([x[1] for x in xs])
            idx = np.searchsorted(xt, tm.t, side="right") - 1 if len(xs) else None
            for n, t in enumerate(tm.t):
                xi = "" if idx is None or idx[n] < 0 else f"{xv[idx[n]]:.6e}"
                rp = f"{tm.rel_pos[k][n]:.6e}" if pose else ""
                w.writerow([f"{t:.3f}", k, h, tl, f"{tm.rel_att[k][n]:.6e}", rp, xi])


def plot_tree(out: Path, sc: Scenario, tm: TreeMetrics, rec: Recording) -> None:
    """The §4 figures: |R̄_k|_I per edge (Figs. 4.4/4.6), ξ_k (4.5/4.7), position errors (4.8/4.9)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    pose = "bearings" in sc.info.sensors

    def figure(series: dict[int, np.ndarray], ylabel: str, name: str, title: str, per_edge: bool) -> None:
        """Top: one curve per edge or agent; bottom, log scale: the same per edge, or the agents' average."""
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
        if per_edge:
            for k, (h, tl) in enumerate(sc.oriented, start=1):
                for ax in (ax1, ax2):
                    ax.plot(tm.t, series[k], lw=1, label=f"edge {k} ({h}→{tl})")
            ax2.set_ylabel(ylabel + " (log)")
        else:
            for i in sc.ids:
                ax1.plot(tm.t, series[i], lw=1, label=f"agent {i}")
            ax2.plot(tm.t, np.mean([series[i] for i in sc.ids], axis=0), "k", lw=1.2)
            ax2.set_ylabel("average over agents (log)")
        ax2.set_yscale("log")
        ax1.set_ylabel(ylabel)
        ax2.set_xlabel("t (s)")
        ax1.set_title(f"{sc.name}: {title}")
        ax1.legend(fontsize=7, ncol=2 if per_edge else 3)
        for ax in (ax1, ax2):
            ax.grid(True, alpha=0.3)
        fig.tight_layout()
        files.save_png(fig, out / f"{name}.png")
        plt.close(fig)

    figure(tm.rel_att, r"$|\bar R_k|_I$", "relative_attitude_error", "relative attitude error per edge", True)
    figure(tm.att_common, r"$|\tilde R_i \tilde R_c^T|_I$", "attitude_error", "attitude error up to a common rotation", False)
    if pose:
        figure(tm.rel_pos, r"$\|\tilde p_h-\tilde p_t\|$", "relative_position_error", "relative position error per edge", True)
        figure(tm.pos_common, r"$\|\tilde p_i-\mathrm{mean}\,\tilde p\|$", "position_error", "position error up to a common translation", False)
    if rec.edge_values.get("xi"):
        base.plot_xi(out, rec, f"{sc.name}: hybrid variables (x: jumps)", ncol=4)


def metrics(sc: Scenario, rec: Recording) -> TreeMetrics | None:
    return tree_metrics(sc, rec)


def _pose(sc: Scenario) -> bool:
    return "bearings" in sc.info.sensors  # §4.4 estimates positions too


def headline(sc: Scenario, agents: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    """The means over the agents of their errors up to a common frame (set by :func:`summary`)."""
    return base.headline(sc, agents, extra) | {"mean_over": "agents (up to a common frame)"}


def series(sc: Scenario, errs: dict[int, np.ndarray], tm: TreeMetrics | None, duration: float) -> base.Series:
    """The mean over edges of |R̄_k|_I and of the relative position error, on the 0.1 s grid
    (without metrics, when some agent published no estimate: the leader–follower measure)."""
    if tm is None:
        return base.series(sc, errs, None, duration)
    return base.edges_on_grid(tm.t, tm.rel_att, tm.rel_pos if _pose(sc) else {}, duration, np.mean)


def convergence(sc: Scenario, errs: dict[int, np.ndarray], tm: TreeMetrics | None, duration: float, thresholds: tuple[float, float]) -> dict[str, Any]:
    t, att, pos = series(sc, errs, tm, duration)
    measure = "mean over edges of |R̄_k|_I and relative position error" if tm is not None else "mean over followers"
    return base.convergence_of(t, att, pos, measure, thresholds)


def finals(summary: dict[str, Any]) -> tuple[float | None, float | None]:
    return summary["mean_relative_attitude_error_final"], summary.get("mean_relative_position_error_final")


def series_from_files(folder: Path, sc: Scenario, duration: float) -> base.Series:
    t, rel_att, rel_pos = base.read_edges_csv(folder / "edges.csv", len(sc.oriented))
    return base.edges_on_grid(t, rel_att, rel_pos if _pose(sc) else {}, duration, np.mean)


def write(out_dir: Path, sc: Scenario, rec: Recording, tm: TreeMetrics | None) -> None:
    if tm is not None:
        write_edges_csv(out_dir / "edges.csv", sc, tm, rec)


def plot(out: Path, sc: Scenario, errs: dict[int, np.ndarray], tm: TreeMetrics | None, rec: Recording) -> None:
    if tm is None:
        base.plot_errors(out, sc, errs, rec)
    else:
        plot_tree(out, sc, tm, rec)


def table_lines(summary: dict[str, Any]) -> list[str]:
    lines = text.agent_rows(summary)
    lines.append("(agent errors are up to a common frame; see summary.json errors_up_to)")
    lines.append(f"{'edge':>5} {'head->tail':<10} {'|R̄_k|_I':>10} {'rel.pos':>10} {'jumps':>6} {'ξ final':>9}")
    for k, e in summary["edges"].items():
        xi = e.get("xi_final")
        lines.append(
            f"{k:>5} {str(e['head']) + '->' + str(e['tail']):<10} {text.e(e.get('relative_attitude_error_final')):>10} "
            f"{text.e(e.get('relative_position_error_final')):>10} {e.get('jumps', '-'):>6} {'-' if xi is None else f'{xi:.4f}':>9}"
        )
    return lines + [text.mean_line(summary, "agents")]


def basin_start(sc: Scenario) -> list[tuple[str, Any]]:
    """A basin draw randomises every agent's initial estimate R̂_i(0)."""
    return [(f"agents[{n}].estimate.R", a.estimate["R"]) for n, a in enumerate(sc.agents)]


def basin_series(sc: Scenario, rec: Recording) -> tuple[np.ndarray, np.ndarray]:
    """max_k |R̄_k|_I on the 100 Hz grid."""
    tm = tree_metrics(sc, rec, BASIN_GRID_S)
    if tm is None:
        raise RuntimeError("some agent published no estimate")
    return tm.t, np.max(np.array(list(tm.rel_att.values())), axis=0)


WORLD = {"step": 0.001, "sensor_rate": 200.0, "formation": {"axis": [0, 0, 1], "rate": "pi/6"}}  # a rotating formation (§4.5)

RECIPES = {
    "relative-attitude": Recipe(
        "thesis-4.5-continuous5",
        "§4: continuous relative-attitude observer (4.3) + (4.8) on a tree, rotating formation",
        "tree",
        {"name": "relative_attitude_continuous", "gains": {"k_R": 1.1}, "params": {"A": [5, 8.57, 12]}},
        WORLD,
        duration=30.0,
        estimate=("R",),
    ),
    "relative-attitude-hybrid": Recipe(
        "thesis-4.5-hybrid5",
        "§4: hybrid relative-attitude observer (4.25)-(4.26) on a tree, rotating formation",
        "tree",
        {"name": "relative_attitude_hybrid", "gains": {"k_R": 1.1, "k_xi": 3.5}, "params": HYBRID_PARAMS_4},
        WORLD,
        duration=30.0,
        estimate=("R", "xi"),
    ),
    "relative-pose-hybrid": Recipe(
        "thesis-4.5-hybrid-pose5",
        "§4: hybrid pose observer (4.25)-(4.26) + (4.30)-(4.31) on a tree, rotating formation",
        "tree",
        {"name": "relative_pose_hybrid", "gains": {"k_R": 1.1, "k_xi": 3.5, "k_p": 1.0}, "params": HYBRID_PARAMS_4},
        WORLD,
        duration=60.0,
        estimate=("p", "R", "xi"),
    ),
}

# zswarm design-hybrid: Prop. 4.2's design of the synergistic potential (the §4 and §5 hybrid schemes share it).
DESIGN_COMMAND = Command(
    "design-hybrid",
    "Prop. 4.2: u, Δ*, and the bounds on γ and δ for A and Ξ; checks Condition 4.1",
    "Thesis Prop. 4.2 (§4.3.2.3): from the eigenvalues of A and the set Ξ, compute u, Δ*, "
    "the bounds γ < 4Δ*/π² and δ < (4Δ*/π² − γ) ξ_L²/2, and check Condition 4.1 at the undesired critical "
    "points.  Without --gamma/--delta, both are taken at 95 % of their bounds (the thesis' choice).",
    design_arguments,
    design_command,
    examples=("zswarm design-hybrid --A 5,8.57,12 --xi 0.08pi", "zswarm design-hybrid --A 5,8.57,12 --xi 0.5,0.9pi --json"),
)

FAMILY = Family(
    report=Report(metrics=metrics, summary=summary, headline=headline, series=series, finals=finals, convergence=convergence, series_from_files=series_from_files, write=write, plot=plot, table_lines=table_lines),
    basin=Basin(basin_start, basin_series, verdict="synchronized", measure="max_k |R̄_k|_I", grid_s=BASIN_GRID_S),
    batched=Batched("prescribed", ticks=TreeTicks, stamps=TreeStamps),
    recipes=RECIPES,
    commands=(DESIGN_COMMAND,),
)
