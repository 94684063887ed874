"""Results of a run from its recording: errors.csv, summary.json, plots.

Errors are those of the thesis figures: attitude error ``|R_i R̂_i^T|_I`` and
position error ``||p_i − p̂_i||``, evaluated at each estimate's world time
against the truth at that same time (the truth sample before it, propagated
with the true ω over the < 1/sensor_rate gap: error O(ω̇ Δt²) ≈ 3e-5 rad).
"final" is the mean over the last second of the run.
"""

from __future__ import annotations

import csv
import json
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from zswarm import so3, wire
from zswarm.record import ALIVE_CHANNEL, read, unpack
from zswarm.scenario import Scenario


@dataclass
class Recording:
    """What the report needs, decoded from a recording."""

    truth_t: np.ndarray
    truth_ids: list[int]
    truth_R: np.ndarray  # (T, n, 3, 3)
    truth_p: np.ndarray  # (T, n, 3)
    truth_w: np.ndarray  # (T, n, 3)
    est: dict[int, list[tuple[float, np.ndarray, np.ndarray]]]
    stats: dict[tuple[str, int], dict[str, Any]]
    alive_events: list[dict[str, Any]]
    start: dict[str, Any] | None
    stop_seen: bool
    counts: dict[str, int] = field(default_factory=dict)
    malformed: int = 0


def load_recording(path: Path) -> Recording:
    truth: list[dict[str, Any]] = []
    est: dict[int, list[tuple[float, np.ndarray, np.ndarray]]] = defaultdict(list)
    stats: dict[tuple[str, int], dict[str, Any]] = {}
    alive: list[dict[str, Any]] = []
    start = None
    stop_seen = False
    counts: dict[str, int] = defaultdict(int)
    malformed = 0
    for topic, payload, _t in read(path):
        counts[topic.split("/")[0]] += 1
        if topic == ALIVE_CHANNEL:
            alive.append(unpack(payload))
            continue
        kind = topic.split("/")[0]
        if kind not in ("truth", "est", "stats", "ctl"):
            continue
        try:
            m = wire.decode(payload)
        except wire.MessageError:
            malformed += 1
            continue
        if m["type"] == "truth" and kind == "truth":
            truth.append(m)
        elif m["type"] == "est" and kind == "est":
            est[m["src"]].append((m["t"], m["R_hat"], m["p_hat"]))
        elif m["type"] == "stats" and kind == "stats":
            role = m["role"]
            prev = stats.get((role, m["src"]))
            # Keep the final stats if any, else the newest.
            if prev is None or not prev.get("final") or m["counters"].get("final"):
                stats[(role, m["src"])] = {**m["counters"], "t": m["t"]}
        elif m["type"] == "start":
            start = m
        elif m["type"] == "stop":
            stop_seen = True
    if not truth:
        raise ValueError(f"{path}: the recording holds no ground truth")
    truth.sort(key=lambda m: m["t"])
    ids = truth[0]["ids"]
    return Recording(
        truth_t=np.array([m["t"] for m in truth]),
        truth_ids=ids,
        truth_R=np.array([m["R"] for m in truth]),
        truth_p=np.array([m["p"] for m in truth]),
        truth_w=np.array([m["w"] for m in truth]),
        est={i: sorted(v, key=lambda e: e[0]) for i, v in est.items()},
        stats=stats,
        alive_events=alive,
        start=start,
        stop_seen=stop_seen,
        counts=dict(counts),
        malformed=malformed,
    )


def errors(rec: Recording) -> dict[int, np.ndarray]:
    """Per agent an array of rows ``(t, attitude_error, position_error)``."""
    out: dict[int, np.ndarray] = {}
    col = {i: k for k, i in enumerate(rec.truth_ids)}
    for i, samples in rec.est.items():
        if i not in col:
            continue
        a = col[i]
        rows = []
        for t, R_hat, p_hat in samples:
            k = int(np.searchsorted(rec.truth_t, t, side="right")) - 1
            if k < 0:
                continue
            R = rec.truth_R[k, a] @ so3.exp((t - rec.truth_t[k]) * rec.truth_w[k, a])
            rows.append((t, so3.attitude_norm(R @ R_hat.T), float(np.linalg.norm(rec.truth_p[k, a] - p_hat))))
        out[i] = np.array(rows).reshape(-1, 3)
    return out


def final_mean(rows: np.ndarray, t_end: float, col: int, window: float = 1.0) -> float:
    sel = rows[rows[:, 0] >= t_end - window]
    return float(np.mean(sel[:, col])) if len(sel) else float("nan")


def summarize(
    sc: Scenario,
    rec: Recording,
    errs: dict[int, np.ndarray],
    engine: str,
    duration: float,
    time_scale: float,
    seed: int,
    exit_codes: dict[str, int | None] | None = None,
) -> dict[str, Any]:
    """The summary.json content (see README, "Results folder")."""
    t_end = duration
    agents: dict[str, Any] = {}
    links: dict[str, dict[str, Any]] = {}
    sent: dict[str, int] = {}
    for (_role, _src), st in rec.stats.items():
        for link, n in st.get("sent", {}).items():
            sent[link] = n
    for a in sc.agents:
        st = rec.stats.get(("agent", a.id), {})
        rows = errs.get(a.id, np.zeros((0, 3)))
        # Alive at the end: it stopped cleanly (its final counters were recorded,
        # which a killed process never sends) and, when known, exited with 0.
        alive = bool(st.get("final"))
        if exit_codes is not None and f"agent-{a.id}" in exit_codes:
            alive = alive and exit_codes[f"agent-{a.id}"] == 0
        agents[str(a.id)] = {
            "role": a.role,
            "alive_at_end": alive,
            "attitude_error_final": final_mean(rows, t_end, 1),
            "position_error_final": final_mean(rows, t_end, 2),
            "last_estimate_t": float(rows[-1, 0]) if len(rows) else None,
            "steps": int(st.get("steps", 0)),
            "step_rate_hz": float(st.get("step_rate_hz", 0.0)),
            "configured_rate_hz": a.clock.rate,
            "missed_deadlines": int(st.get("missed_deadlines", 0)),
            "compute_mean_us": float(st.get("compute_mean_us", 0.0)),
            "malformed_received": int(st.get("malformed", 0)),
        }
        for link, c in st.get("links", {}).items():
            links[link] = {"sent": sent.get(link, 0), **c}
    for link, n in sent.items():
        links.setdefault(link, {"sent": n, "delivered": 0, "dropped": n, "reordered": 0})
    followers = [agents[str(a.id)] for a in sc.agents if a.role == "follower"]
    return {
        "scenario": sc.name,
        "algorithm": sc.algorithm,
        "engine": engine,
        "duration_s": duration,
        "time_scale": time_scale,
        "seed": seed,
        "completed": rec.stop_seen,
        "agents": agents,
        "links": dict(sorted(links.items())),
        "mean_attitude_error_final": float(np.nanmean([f["attitude_error_final"] for f in followers])) if followers else 0.0,
        "mean_position_error_final": float(np.nanmean([f["position_error_final"] for f in followers])) if followers else 0.0,
        "mean_over": "followers",
        "final_window_s": 1.0,
        "world": rec.stats.get(("world", 0), {}),
        "recorded_messages": rec.counts,
        "malformed_in_recording": rec.malformed,
    }


def write_errors_csv(path: Path, errs: dict[int, np.ndarray]) -> None:
    rows = [(t, i, ea, ep) for i, e in errs.items() for t, ea, ep in e]
    rows.sort()
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "agent", "attitude_error", "position_error"])
        for t, i, ea, ep in rows:
            w.writerow([f"{t:.6f}", i, f"{ea:.6e}", f"{ep:.6e}"])


def plot(out: Path, sc: Scenario, errs: dict[int, np.ndarray]) -> None:
    """Individual and average error norms, like thesis figures 3.4–3.7."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    followers = [a.id for a in sc.agents if a.role == "follower" and a.id in errs and len(errs[a.id])]
    for col, name, label in ((1, "attitude_error", r"$|R_i\hat R_i^T|_I$"), (2, "position_error", r"$\|p_i-\hat p_i\|$")):
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
        grid = None
        for i in followers:
            e = errs[i]
            ax1.plot(e[:, 0], e[:, col], lw=1, label=f"agent {i}")
            if grid is None:
                grid = e[:, 0]
        if grid is not None:
            avg = np.mean([np.interp(grid, errs[i][:, 0], errs[i][:, col]) for i in followers], axis=0)
            ax2.plot(grid, avg, "k", lw=1.2)
        ax1.set_ylabel(label)
        ax1.set_title(f"{sc.name}: individual {name.replace('_', ' ')}s")
        ax1.legend(fontsize=7, ncol=3)
        ax2.set_ylabel("average over followers")
        ax2.set_xlabel("t (s)")
        for ax in (ax1, ax2):
            ax.grid(True, alpha=0.3)
        fig.tight_layout()
        fig.savefig(out / f"{name}.png", dpi=110)
        plt.close(fig)


def make_report(
    out_dir: Path,
    sc: Scenario,
    engine: str,
    duration: float,
    time_scale: float,
    seed: int,
    exit_codes: dict[str, int | None] | None = None,
    plots: bool = True,
) -> dict[str, Any]:
    """Read ``out_dir/recording.mcap``; write errors.csv, summary.json and plots; return the summary."""
    rec = load_recording(out_dir / "recording.mcap")
    errs = errors(rec)
    summary = summarize(sc, rec, errs, engine, duration, time_scale, seed, exit_codes)
    write_errors_csv(out_dir / "errors.csv", errs)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    if plots:
        plot(out_dir / "plots", sc, errs)
    return summary


def table(summary: dict[str, Any]) -> str:
    """The per-agent summary table printed at the end of a run."""
    lines = [
        f"{summary['scenario']} ({summary['algorithm']}, engine={summary['engine']}, {summary['duration_s']:g} s, seed {summary['seed']})",
        f"{'agent':>5} {'role':<8} {'alive':<5} {'att.err':>10} {'pos.err':>10} {'steps':>6} {'rate Hz':>8} {'missed':>6}",
    ]
    for i, a in summary["agents"].items():
        lines.append(
            f"{i:>5} {a['role']:<8} {'yes' if a['alive_at_end'] else 'NO':<5} {a['attitude_error_final']:>10.2e} "
            f"{a['position_error_final']:>10.2e} {a['steps']:>6} {a['step_rate_hz']:>8.2f} {a['missed_deadlines']:>6}"
        )
    drops = sum(v.get("dropped", 0) for v in summary["links"].values())
    lines.append(
        f"mean over followers (last 1 s): attitude {summary['mean_attitude_error_final']:.2e}, "
        f"position {summary['mean_position_error_final']:.2e}; links: {len(summary['links'])}, dropped messages: {drops}"
    )
    return "\n".join(lines)
