"""Results of the attitude synchronization laws (thesis Chapter 5, Figs. 5.3–5.12).

Everything is judged on the truth, not on what the agents believe: on a
100 Hz grid of the world's truth samples,

* per edge k (head h, tail t): ``|R̄_k|_I`` with ``R̄_k = R_t^T R_h`` (§5.2;
  Figs. 5.3/5.8), and ξ_k as its head reports it (Figs. 5.5/5.10);
* per agent: ``‖ω_i‖`` (Figs. 5.4/5.9); the torque the plant applied (the
  held command, after the link) and the one the agent computed; for the
  velocity-free law ``|Q̃_i|_I = |Q_i^T R_i|_I`` (Q_i from the agent, R_i the
  truth; Figs. 5.6/5.11) and ζ_i (Figs. 5.7/5.12).

"Synchronized" is the measure of READING-NOTES: ``max_k |R̄_k|_I``; its
settle time below a threshold is the first time after which it stays below.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zswarm.families.contract import Basin, Batched, Family, Recipe, Report, Sweep
from zswarm.families.measure import FINAL_WINDOW_S, Context, Result, Truth, coarse_grid, rounded
from zswarm.families.synergistic import HYBRID_PARAMS_5
from zswarm.report import base
from zswarm.report import table as text
from zswarm.report.decoded import Recording
from zswarm.report.series import final_of_grid as _final
from zswarm.report.series import held as _held
from zswarm.report.series import leave_time, settle_time
from zswarm.report.series import norm_I as _norm_I
from zswarm.scenario import Scenario
from zswarm.util import files

GRID_S = 0.01
BASIN_GRID_S = GRID_S  # basin_series' grid (the batched engine measures on it too)
SYNC_THRESHOLDS = (0.1, 0.01)  # READING-NOTES' figures: below 0.1 from t ≈ 58.5 s, below 0.01 from ≈ 102 s (hybrid)


@dataclass
class SyncMetrics:
    t: np.ndarray  # (T,) grid
    rel_att: dict[int, np.ndarray]  # edge k -> |R̄_k|_I
    omega: dict[int, np.ndarray]  # agent -> ‖ω_i‖
    tau_applied: dict[int, np.ndarray]  # agent -> ‖τ_i‖ as applied by the plant (NaN if not recorded)
    tau_computed: dict[int, np.ndarray]  # agent -> ‖τ_i‖ as computed (NaN before the first)
    q_tilde: dict[int, np.ndarray]  # agent -> |Q̃_i|_I (velocity-free law only)
    zeta: dict[int, np.ndarray]  # agent -> ζ_i (velocity-free law only)

    @property
    def max_rel(self) -> np.ndarray:
        return np.max(np.array(list(self.rel_att.values())), axis=0)


def sync_metrics(sc: Scenario, rec: Recording, step: float = GRID_S) -> SyncMetrics:
    T = rec.truth_t
    grid = np.round(np.arange(T[0], T[-1] + 1e-9, step), 9)
    k = np.clip(np.searchsorted(T, grid + 1e-9, side="right") - 1, 0, len(T) - 1)
    col = {i: a for a, i in enumerate(rec.truth_ids)}
    R = rec.truth_R[k]
    rel = {}
    for e, (h, tl) in enumerate(sc.oriented, start=1):
        rel[e] = _norm_I(np.einsum("nji,njk->nik", R[:, col[tl]], R[:, col[h]]))
    omega = {i: np.linalg.norm(rec.truth_w[k, col[i]], axis=1) for i in sc.ids}
    tau_a = {i: (np.linalg.norm(rec.truth_tau[k, col[i]], axis=1) if rec.truth_tau is not None else np.full(len(grid), np.nan)) for i in sc.ids}
    tau_c, qt, zeta = {}, {}, {}
    for i in sc.ids:
        ex = rec.extra.get(i, [])
        with_tau = [(t, d["tau"]) for t, d in ex if "tau" in d]
        tau_c[i] = (
            _held(np.array([t for t, _ in with_tau]), np.linalg.norm(np.array([v for _, v in with_tau]), axis=1), grid) if with_tau else np.full(len(grid), np.nan)
        )
        with_q = [(t, d["Q"], d.get("zeta", np.nan)) for t, d in ex if "Q" in d]
        if with_q:
            tq = np.array([t for t, _, _ in with_q])
            kq = np.clip(np.searchsorted(T, tq + 1e-9, side="right") - 1, 0, len(T) - 1)
            Qs = np.array([q for _, q, _ in with_q]).reshape(-1, 3, 3)
            qn = _norm_I(np.einsum("nji,njk->nik", Qs, rec.truth_R[kq, col[i]]))
            qt[i] = _held(tq, qn, grid)
            zeta[i] = _held(tq, np.array([float(z) for _, _, z in with_q]), grid)
    return SyncMetrics(grid, rel, omega, tau_a, tau_c, qt, zeta)


def summary(sc: Scenario, rec: Recording, m: SyncMetrics, agents: dict[str, Any], duration: float) -> dict[str, Any]:
    """The Chapter 5 part of summary.json (per edge, per agent in place, the synchronization block)."""
    hybrid = bool(getattr(sc.params, "Xi", ()))  # ξ_k: the hybrid law (a jump set Ξ)
    edges: dict[str, Any] = {}
    for k, (h, tl) in enumerate(sc.oriented, start=1):
        v = m.rel_att[k]
        e: dict[str, Any] = {
            "head": h,
            "tail": tl,
            "relative_attitude_error_final": _final(m.t, v),
            "settles_below_0.1_at": settle_time(m.t, v, 0.1),
            "settles_below_0.01_at": settle_time(m.t, v, 0.01),
        }
        if hybrid:
            js = [j for j in rec.jumps if j[0] == k]
            xs = rec.edge_values.get("xi", {}).get(k, [])
            e.update(xi_owner=h, jumps=len(js), jump_log=[{"t": t, "xi_before": b, "xi_after": a} for _, t, b, a in js], xi_final=xs[-1][1] if xs else None)
        edges[str(k)] = e
    for i in sc.ids:
        a = agents[str(i)]
        a["angular_velocity_final"] = _final(m.t, m.omega[i])
        a["angular_velocity_peak"] = float(np.nanmax(m.omega[i]))
        a["torque_peak_applied"] = float(np.nanmax(m.tau_applied[i])) if np.any(np.isfinite(m.tau_applied[i])) else None
        a["torque_peak_computed"] = float(np.nanmax(m.tau_computed[i])) if np.any(np.isfinite(m.tau_computed[i])) else None
        a["torque_final"] = _final(m.t, m.tau_applied[i]) if np.any(np.isfinite(m.tau_applied[i])) else None
        if i in m.q_tilde:
            js = [j for j in rec.agent_jumps if j[0] == i]
            a["Q_tilde_final"] = _final(m.t, m.q_tilde[i])
            a["Q_tilde_max_after_5s"] = float(np.nanmax(m.q_tilde[i][m.t >= 5.0])) if np.any(m.t >= 5.0) else None
            a["zeta_final"] = _final(m.t, m.zeta[i])
            a["zeta_jumps"] = len(js)
            a["zeta_jump_log"] = [{"t": t, "zeta_before": b, "zeta_after": af} for _, t, b, af in js]
        # The attitude/position error columns of the observers mean nothing here.
        a["attitude_error_final"] = a["position_error_final"] = a["position_error_direct_final"] = float("nan")
    mx = m.max_rel
    world = rec.stats.get(("world", 0), {})
    out: dict[str, Any] = {
        "orientation": sc.oriented_from,
        "edges": edges,
        "synchronization": {
            "measure": "max over edges of |R̄_k|_I, R̄_k = R_tail^T R_head, from the truth (100 Hz grid)",
            "initial": float(mx[0]),
            "final": _final(m.t, mx),
            "leaves_start_at": leave_time(m.t, mx),
            "settles_below_0.1_at": settle_time(m.t, mx, 0.1),
            "settles_below_0.01_at": settle_time(m.t, mx, 0.01),
            "synchronized": bool(_final(m.t, mx) < 0.01),
        },
        "commands": {
            "policy": world.get("command_policy", f"{sc.commands.policy} after {sc.commands.max_age:g} s"),
            "per_agent": world.get("commands", {}),
            "malformed": int(world.get("commands_malformed", 0)),
        },
        "max_relative_attitude_error_final": float(np.max([e["relative_attitude_error_final"] for e in edges.values()])),
        "mean_relative_attitude_error_final": float(np.mean([e["relative_attitude_error_final"] for e in edges.values()])),
        "errors_up_to": "Chapter 5 control: errors are the relative attitudes |R̄_k|_I of the truth (edges.*, synchronization)",
    }
    if hybrid:
        out["jumps_total"] = len(rec.jumps)
    if m.q_tilde:
        out["zeta_jumps_total"] = len(rec.agent_jumps)
    return out


def convergence(sc: Scenario, errs: dict[int, np.ndarray], m: SyncMetrics, duration: float, thresholds: tuple[float, float]) -> dict[str, Any]:
    """summary.json "convergence" (what ``zswarm sweep`` tabulates): the settle times of max_k |R̄_k|_I."""
    mx = m.max_rel
    return {
        "measure": "max over edges of |R̄_k|_I (truth)",
        "grid_s": GRID_S,
        "attitude_threshold": thresholds[0],
        "attitude_s": settle_time(m.t, mx, thresholds[0]),
        "attitude_0.1_s": settle_time(m.t, mx, 0.1),
    }


def write_edges_csv(path: Path, sc: Scenario, m: SyncMetrics, rec: Recording) -> None:
    """Per edge on the grid: |R̄_k|_I and ξ_k (columns as the observers' edges.csv)."""
    with files.whole(path) as tmp, open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "edge", "head", "tail", "relative_attitude_error", "relative_position_error", "xi"])
        for k, (h, tl) in enumerate(sc.oriented, start=1):
            xs = rec.edge_values.get("xi", {}).get(k, [])
            xv = _held(np.array([x[0] for x in xs]), np.array([x[1] for x in xs]), m.t) if xs else np.full(len(m.t), np.nan)
            for n, t in enumerate(m.t):
                w.writerow([f"{t:.3f}", k, h, tl, f"{m.rel_att[k][n]:.6e}", "", "" if not np.isfinite(xv[n]) else f"{xv[n]:.6e}"])


def write_agents_csv(path: Path, sc: Scenario, m: SyncMetrics) -> None:
    """Per agent on the grid: ‖ω_i‖, ‖τ_i‖ applied and computed, |Q̃_i|_I and ζ_i (velocity-free)."""
    with files.whole(path) as tmp, open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "agent", "angular_velocity", "torque_applied", "torque_computed", "Q_tilde", "zeta"])
        for i in sc.ids:
            q = m.q_tilde.get(i)
            z = m.zeta.get(i)
            for n, t in enumerate(m.t):
                vals = [m.omega[i][n], m.tau_applied[i][n], m.tau_computed[i][n], q[n] if q is not None else np.nan, z[n] if z is not None else np.nan]
                w.writerow([f"{t:.3f}", i] + ["" if not np.isfinite(v) else f"{v:.6e}" for v in vals])


def plot(out: Path, sc: Scenario, errs: dict[int, np.ndarray], m: SyncMetrics, rec: Recording) -> None:
    """Figs. 5.3–5.7 (5.8–5.12 with noise): |R̄_k|_I, ‖ω_i‖, ξ_k, |Q̃_i|_I, ζ_i, and the torques."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)

    def fig2(series: dict[int, np.ndarray], label: str, ylabel: str, name: str, title: str, log: bool = True) -> None:
        fig, axes = plt.subplots(2 if log else 1, 1, figsize=(7, 6 if log else 3.5), sharex=True, squeeze=False)
        for key, v in series.items():
            for ax in axes[:, 0]:
                ax.plot(m.t, v, lw=1, label=label.format(key))
        axes[0, 0].set_ylabel(ylabel)
        if log:
            axes[1, 0].set_yscale("log")
            axes[1, 0].set_ylabel(ylabel + " (log)")
        axes[-1, 0].set_xlabel("t (s)")
        axes[0, 0].set_title(f"{sc.name}: {title}")
        axes[0, 0].legend(fontsize=7, ncol=4)
        for ax in axes[:, 0]:
            ax.grid(True, alpha=0.3)
        fig.tight_layout()
        files.save_png(fig, out / f"{name}.png")
        plt.close(fig)

    fig2({k: m.rel_att[k] for k in m.rel_att}, "edge {}", r"$|\bar R_k|_I$", "relative_attitude_error", "relative attitude per edge (Fig. 5.3)")
    fig2(m.omega, "agent {}", r"$\|\omega_i\|$ (rad/s)", "angular_velocity", "angular velocity per agent (Fig. 5.4)")
    fig2(m.tau_applied, "agent {}", r"$\|\tau_i\|$ applied (N m)", "torque", "torque held by the plant per agent")
    if rec.edge_values.get("xi"):
        base.plot_xi(out, rec, f"{sc.name}: hybrid variables ξ_k (Fig. 5.5; x: jumps)", ncol=6)
    if m.q_tilde:
        fig2(m.q_tilde, "agent {}", r"$|\tilde Q_i|_I$", "Q_tilde", "auxiliary attitude error per agent (Fig. 5.6)")
        fig2(m.zeta, "ζ_{}", r"$\zeta_i$ (rad)", "zeta", "hybrid variables ζ_i (Fig. 5.7)", log=False)


def table_lines(summary: dict[str, Any]) -> list[str]:
    """The Chapter 5 lines of the table printed at the end of a run."""
    lines = [f"{'agent':>5} {'alive':<5} {'|ω| final':>10} {'|ω| peak':>9} {'τ peak':>8} {'steps':>6} {'rate Hz':>8} {'missed':>6}" + ("  |Q̃| final  ζ jumps" if any("Q_tilde_final" in a for a in summary["agents"].values()) else "")]
    for i, a in summary["agents"].items():
        tail = f"  {text.e(a.get('Q_tilde_final')):>10} {a.get('zeta_jumps', 0):>8}" if "Q_tilde_final" in a else ""
        lines.append(
            f"{i:>5} {'yes' if a['alive_at_end'] else 'NO':<5} {text.e(a.get('angular_velocity_final')):>10} {a.get('angular_velocity_peak', float('nan')):>9.3f} "
            f"{a.get('torque_peak_applied') or float('nan'):>8.3f} {a['steps']:>6} {a['step_rate_hz']:>8.2f} {a['missed_deadlines']:>6}{tail}"
        )
    lines.append(f"{'edge':>5} {'head->tail':<10} {'|R̄_k|_I':>10} {'<0.1 from':>10} {'<0.01 from':>11} {'jumps':>6} {'ξ final':>9}")
    for k, e in summary["edges"].items():
        xi = e.get("xi_final")
        lines.append(
            f"{k:>5} {str(e['head']) + '->' + str(e['tail']):<10} {text.e(e['relative_attitude_error_final']):>10} {text.s(e['settles_below_0.1_at']):>10} "
            f"{text.s(e['settles_below_0.01_at']):>11} {e.get('jumps', '-'):>6} {'-' if xi is None else f'{xi:.4f}':>9}"
        )
    sy = summary["synchronization"]
    cmd_links = {k: v for k, v in summary["links"].items() if k.endswith("->world")}
    sent = sum(int(v.get("sent", 0)) for v in cmd_links.values())
    dropped = sum(int(v.get("dropped", 0)) for v in cmd_links.values())
    expired = sum(int(v.get("expired", 0)) for v in summary["commands"]["per_agent"].values())
    lines.append(
        f"max_k |R̄_k|_I: {text.e(sy['initial'])} at start, left it at {text.s(sy['leaves_start_at'])} s, below 0.1 from {text.s(sy['settles_below_0.1_at'])} s, "
        f"below 0.01 from {text.s(sy['settles_below_0.01_at'])} s, final {text.e(sy['final'])}"
        + (f"; jumps: {summary['jumps_total']}" if "jumps_total" in summary else "")
        + (f", ζ jumps: {summary['zeta_jumps_total']}" if "zeta_jumps_total" in summary else "")
    )
    lines.append(
        f"commands: {'>= ' if any(v.get('sent_is_lower_bound') for v in cmd_links.values()) else ''}{sent} sent, {dropped} lost, {expired} expired ({summary['commands']['policy']}), {summary['commands']['malformed']} malformed"
    )
    return lines


def metrics(sc: Scenario, rec: Recording) -> SyncMetrics:
    return sync_metrics(sc, rec)


def headline(sc: Scenario, agents: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    """The mean over edges of the truth's final |R̄_k|_I (agents have no estimate error here)."""
    return base.headline(sc, agents, extra) | {"mean_attitude_error_final": extra["mean_relative_attitude_error_final"], "mean_over": "edges: |R̄_k|_I of the truth"}


def series(sc: Scenario, errs: dict[int, np.ndarray], m: SyncMetrics, duration: float) -> base.Series:
    """max over edges of the truth's |R̄_k|_I, on the 0.1 s grid (a fault's re-convergence, zswarm sweep)."""
    return base.edges_on_grid(m.t, m.rel_att, {}, duration, np.max)


def series_from_files(folder: Path, sc: Scenario, duration: float) -> base.Series:
    t, rel_att, _ = base.read_edges_csv(folder / "edges.csv", len(sc.oriented))
    return base.edges_on_grid(t, rel_att, {}, duration, np.max)


def write(out_dir: Path, sc: Scenario, rec: Recording, m: SyncMetrics) -> None:
    write_edges_csv(out_dir / "edges.csv", sc, m, rec)
    write_agents_csv(out_dir / "agents.csv", sc, m)


def basin_start(sc: Scenario) -> list[tuple[str, Any]]:
    """A basin draw randomises every agent's attitude R_i(0) (and the velocity-free law's Q_i(0))."""
    vf = "Q" in sc.info.initial  # the velocity-free law starts from Q_i(0) too
    out: list[tuple[str, Any]] = []
    for n, a in enumerate(sc.agents):
        out.append((f"agents[{n}].R", a.R))
        if vf:
            out.append((f"agents[{n}].estimate.Q", a.estimate["Q"]))
    return out


def basin_series(sc: Scenario, rec: Recording) -> tuple[np.ndarray, np.ndarray]:
    """max_k |R̄_k|_I of the truth on the 100 Hz grid."""
    m = sync_metrics(sc, rec)
    return m.t, m.max_rel


# --------------------------------------------------------------------------- the batched engine and zswarm sweep


class TruthEdges:
    """Each draw's truth measured as :func:`sync_metrics` measures a recording: per edge
    |R̄_k|_I = sqrt(tr(I − R_t^T R_h)/4) at the samples of the basin grid (their max: the basin
    measure); for a sweep's rows the edges' final (the mean over the last second, edge by
    edge, then over the edges) and their max on the 0.1 s grid as edges.csv holds it."""

    def __init__(self, ctx: Context) -> None:
        sc, M = ctx.sc, ctx.M
        col = {i: a for a, i in enumerate(sc.ids)}
        self.M, self.n, self.grid_s, self.rows = M, len(sc.ids), ctx.grid_s, ctx.rows
        edges = list(sc.oriented)
        self.h_idx = np.array([col[h] for h, _ in edges], dtype=int)
        self.t_idx = np.array([col[t] for _, t in edges], dtype=int)
        self.every = max(1, round(ctx.grid_s * sc.sensor_rate))
        # The grid as sync_metrics builds it on a recording (np.round(np.arange(...), 9)), known ahead.
        self.grid_all = np.round(np.arange(0.0, (ctx.n_samples - 1) // self.every * self.every * ctx.sample_dt + 1e-9, ctx.grid_s), 9)
        self.coarse_t = coarse_grid(ctx.duration)
        self.coarse_at = np.clip(np.searchsorted(self.grid_all, self.coarse_t, side="right") - 1, 0, len(self.grid_all) - 1) if len(self.grid_all) else np.zeros(0, dtype=int)
        self.coarse_set = set(self.coarse_at.tolist()) if ctx.rows else set()
        self.final_from = self.grid_all[-1] - FINAL_WINDOW_S if ctx.rows and len(self.grid_all) else np.inf
        self.grid_t: list[float] = []
        self.grid_v: list[np.ndarray] = []
        self.coarse_v: dict[int, np.ndarray] = {}
        self.final_v: list[np.ndarray] = []

    def sample(self, k: int, t: float, truth: Truth) -> None:
        if k % self.every or not len(self.h_idx):
            return
        R = truth.R
        # tr R̄_k = tr(R_t^T R_h) = Σ_ji (R_t)_ji (R_h)_ji, without forming R̄_k (a third of the cost;
        # the report's trace of the product differs by round-off, ~1e-15)
        tr = np.einsum("mnji,mnji->mn", R[:, self.t_idx], R[:, self.h_idx])
        rel = np.sqrt(np.clip((3.0 - tr) * 0.25, 0.0, 1.0))  # (M, edges)
        g = len(self.grid_t)
        self.grid_t.append(t)
        self.grid_v.append(rel.max(axis=1))
        if self.grid_all[g] >= self.final_from:
            self.final_v.append(rel)
        if g in self.coarse_set:
            self.coarse_v[g] = rounded(rel, "%.6e").max(axis=1)

    def result(self, res: Result) -> Result:
        M = self.M
        res.t = np.round(np.arange(0.0, self.grid_t[-1] + 1e-9, self.grid_s), 9) if self.grid_t else np.zeros(0)
        assert len(res.t) == len(self.grid_t) and np.array_equal(res.t, self.grid_all[: len(res.t)])
        res.max_rel = np.array(self.grid_v).T if self.grid_v else np.zeros((M, 0))
        if self.rows and self.grid_t:
            fin = np.array(self.final_v)  # (window, M, edges)
            t_fin = self.grid_all[self.grid_all >= self.final_from]
            edge_final = np.array([[_final(t_fin, fin[:, m, e]) for e in range(fin.shape[2])] for m in range(M)])  # the report's final, edge by edge
            res.final_att = edge_final.mean(axis=1)
            res.t_coarse = self.coarse_t
            res.att_coarse = np.array([self.coarse_v[g] for g in self.coarse_at]).T
        return res


def _settle_01(t: np.ndarray, att: np.ndarray) -> float | None:
    return settle_time(t, att, SYNC_THRESHOLDS[0])


SWEEP = Sweep(
    columns=("conv_attitude_01_s",),  # max_k |R̄_k|_I below 0.1 from (s): the thesis' first threshold
    from_run=lambda folder, summary, sc, t, att: {"conv_attitude_01_s": _settle_01(t, att)},
    from_batch=lambda res, n, sc: {"conv_attitude_01_s": _settle_01(res.t_coarse, res.att_coarse[n])},
    figures=(
        ("final_attitude_error", "final mean |R̄_k|_I", True),
        ("jumps", "jumps of ξ (count)", False),
        ("conv_attitude_01_s", "max_k |R̄_k|_I below 0.1 from (s)", False),
        ("conv_attitude_s", "max_k |R̄_k|_I below 0.01 from (s)", False),
    ),
)

WORLD = {"step": 0.001, "sensor_rate": 200.0, "plant": "rigid_body"}

RECIPES = {
    "attitude-sync": Recipe(
        "thesis-5.6-continuous7",
        "§5: continuous attitude synchronization (5.24) of rigid bodies on a tree",
        "tree",
        {"name": "attitude_sync_continuous", "gains": {"k_R": 0.4, "k_omega": 0.1}, "params": {"A": [5, 8.57, 12]}},
        WORLD,
        duration=150.0,
    ),
    "attitude-sync-hybrid": Recipe(
        "thesis-5.6-hybrid7",
        "§5: hybrid attitude synchronization (5.19), (5.21), (5.7) of rigid bodies on a tree",
        "tree",
        {"name": "attitude_sync_hybrid", "gains": {"k_R": 0.4, "k_omega": 0.1, "k_xi": 20}, "params": HYBRID_PARAMS_5},
        WORLD,
        duration=150.0,
        estimate=("xi",),
    ),
    "attitude-sync-velocity-free": Recipe(
        "thesis-5.6-velocity-free7",
        "§5: velocity-free attitude synchronization (5.20)-(5.23), (5.7), (5.12) of rigid bodies on a tree",
        "tree",
        {
            "name": "attitude_sync_velocity_free",
            "gains": {"k_R": 0.4, "k_xi": 20, "k_Q": 30, "k_Qt": 3, "k_zeta": 20},
            "params": HYBRID_PARAMS_5 | {"delta_Q": 0.3848, "Pi": ["0.9*pi"]},
        },
        WORLD,
        duration=150.0,
        estimate=("xi", "Q", "zeta"),
    ),
}

FAMILY = Family(
    report=Report(metrics=metrics, summary=summary, headline=headline, series=series, convergence=convergence, series_from_files=series_from_files, write=write, plot=plot, table_lines=table_lines),
    sweep=SWEEP,
    basin=Basin(basin_start, basin_series, verdict="synchronized", measure="max_k |R̄_k|_I", grid_s=BASIN_GRID_S),
    batched=Batched("rigid_body", truth=TruthEdges),
    recipes=RECIPES,
)
