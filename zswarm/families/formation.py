"""Metrics and plots of De Carli et al.'s Fig. 2 for a "sensing"-graph run (common_frame_formation).

On a 10 ms grid, from the truth and each robot's newest estimate at or before it:

(a) relative yaw, per sensing edge (i, j): ``‖ẑ_ψij − z_ψij‖`` (the chordal error e_ψij of
    (9), ẑ_ψij as the observer holds it, not renormalised);
(b) common-frame yaw, per robot, up to the common rotation α: ``|ẑ_i/|ẑ_i| · z̄_i · e^{−ια} − 1|``
    with ``e^{ια} ∝ Σ_i ẑ_i z̄_i/|ẑ_i|`` (the best common rotation; Theorem 2's limit has ẑ_i ∝ α z_i);
(c) common-frame position, per robot, up to the common rotation and translation:
    ``‖e_i − ē‖`` with ``e_i = p̂_i − R_z(α) p_i`` (Theorem 3: p̂_i → p̄ + R_αᵀ p_i, R_αᵀ = R_z(α));
(d) formation, per robot: ``‖(p_i − p̄) − R_z(−α)(p*_i − p̄*)‖`` (bars: means over the
    robots): (30) drives p_j − p_i to R_α(p*_j − p*_i) in the estimated frame.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zswarm.families.contract import Family, Recipe, Report, Sweep
from zswarm.report import base
from zswarm.report import table as text
from zswarm.report.decoded import Recording
from zswarm.report.series import final_of_grid as _final
from zswarm.report.series import held as _held
from zswarm.report.series import max_over as _max
from zswarm.report.series import settle_time
from zswarm.scenario import Scenario
from zswarm.util import files

GRID_S = 0.01
# Persistent excitation of edge (i, j) (Theorem 1, (10), Remark 2): ∫ |v_j,xy|² dt over a window
# must stay ≥ μ > 0.  Below this over the run's last 10 s we warn that (7)/(8) cannot converge
# there (1e-6 m²/s: a planar speed under ≈ 0.3 mm/s on average).
PE_WINDOW_S = 10.0
PE_MIN = 1e-6
THRESHOLDS = {"relative_yaw": 0.05, "yaw": 0.05, "position_m": 0.1, "formation_m": 0.1}


@dataclass
class FormationMetrics:
    t: np.ndarray
    rel_yaw: dict[tuple[int, int], np.ndarray]  # (i, j) -> (a)
    yaw: dict[int, np.ndarray]  # (b)
    position: dict[int, np.ndarray]  # (c)
    formation: dict[int, np.ndarray]  # (d)
    alpha: np.ndarray  # the common rotation (rad)
    excitation: dict[tuple[int, int], float]  # (i, j) -> ∫ |v_j,xy|² dt over the last PE_WINDOW_S


def _extra_series(rec: Any, i: int, key: str, grid: np.ndarray, width: int) -> np.ndarray:
    rows = [(t, x[key]) for t, x in rec.extra.get(i, []) if key in x]
    if not rows:
        return np.full((len(grid), width), np.nan)
    return _held(np.array([t for t, _ in rows]), np.array([np.asarray(v, dtype=float).reshape(width) for _, v in rows]), grid)


def formation_metrics(sc: Scenario, rec: Recording, step: float = GRID_S) -> FormationMetrics:
    t_end = float(rec.truth_t[-1])
    grid = np.arange(0.0, t_end + 1e-9, step)
    ids = list(rec.truth_ids)
    psi = np.arctan2(rec.truth_R[:, :, 1, 0], rec.truth_R[:, :, 0, 0])
    Psi = _held(rec.truth_t, psi, grid)  # (T, n)
    P = _held(rec.truth_t, rec.truth_p, grid)  # (T, n, 3)
    zc = np.stack([_extra_series(rec, i, "zc", grid, 2) for i in ids], axis=1)  # (T, n, 2)
    zz = zc[..., 0] + 1j * zc[..., 1]
    with np.errstate(invalid="ignore", divide="ignore"):  # before a robot's first estimate: NaN, left out below
        Z = zz / np.abs(zz)
    Y = Z * np.exp(-1j * Psi)  # ẑ_i z̄_i, unit
    s = np.nansum(Y, axis=1)
    alpha = np.angle(s)
    yaw = {i: np.abs(Y[:, n] * np.exp(-1j * alpha) - 1.0) for n, i in enumerate(ids)}
    rel: dict[tuple[int, int], np.ndarray] = {}
    for a in sc.agents:
        n = ids.index(a.id)
        for j in sc.sensed(a.id):
            z = _extra_series(rec, a.id, f"z_rel_{j}", grid, 2)
            d = Psi[:, ids.index(j)] - Psi[:, n]
            rel[(a.id, j)] = np.hypot(z[:, 0] - np.cos(d), z[:, 1] - np.sin(d))
    ph = np.stack([_held(np.array([e[0] for e in rec.est.get(i, [(0.0, None, np.full(3, np.nan))])]), np.array([e[2] for e in rec.est.get(i, [(0.0, None, np.full(3, np.nan))])]), grid) for i in ids], axis=1)
    c, sn = np.cos(alpha), np.sin(alpha)
    rp = np.stack([c[:, None] * P[..., 0] - sn[:, None] * P[..., 1], sn[:, None] * P[..., 0] + c[:, None] * P[..., 1], P[..., 2]], axis=-1)  # R_z(α) p
    e = ph - rp
    e = e - np.nanmean(e, axis=1, keepdims=True)
    position = {i: np.linalg.norm(e[:, n], axis=-1) for n, i in enumerate(ids)}
    pstar = np.array(getattr(sc.params, "p_star", None) or np.zeros((len(ids), 3)))
    pstar = pstar[[ [a.id for a in sc.agents].index(i) for i in ids]] - pstar.mean(axis=0)
    # R_z(−α)(p*_i − p̄*)
    ds = np.stack([c[:, None] * pstar[None, :, 0] + sn[:, None] * pstar[None, :, 1], -sn[:, None] * pstar[None, :, 0] + c[:, None] * pstar[None, :, 1], np.broadcast_to(pstar[None, :, 2], (len(grid), len(ids)))], axis=-1)
    f = (P - P.mean(axis=1, keepdims=True)) - ds
    formation = {i: np.linalg.norm(f[:, n], axis=-1) for n, i in enumerate(ids)}
    # planar speeds from the truth (finite differences of p at the truth's samples)
    tt = np.asarray(rec.truth_t, dtype=float)
    last = tt >= tt[-1] - PE_WINDOW_S
    vxy2 = np.zeros((max(len(tt) - 1, 0), len(ids)))
    if len(tt) > 1:
        dp = np.diff(rec.truth_p[:, :, :2], axis=0) / np.diff(tt)[:, None, None]
        vxy2 = np.sum(dp**2, axis=-1)
    w = np.diff(tt) * last[1:]
    exc = {(i, j): float(np.sum(w * vxy2[:, ids.index(j)])) for (i, j) in rel}
    return FormationMetrics(grid, rel, yaw, position, formation, alpha, exc)


def summary(sc: Scenario, rec: Recording, m: FormationMetrics, agents: dict[str, Any], duration: float) -> dict[str, Any]:
    """The De Carli part of summary.json: per edge (a), per robot (b)-(d) (in ``agents``), settle times."""
    edges = {
        f"{i}->{j}": {
            "bidirectional": i in sc.sensed(j),
            "relative_yaw_error_final": _final(m.t, v),
            "relative_yaw_error_max_last_10s": float(np.nanmax(v[m.t >= m.t[-1] - 10.0])),
            f"settles_below_{THRESHOLDS['relative_yaw']:g}_at": settle_time(m.t, v, THRESHOLDS["relative_yaw"]),
        }
        for (i, j), v in m.rel_yaw.items()
    }
    for i in m.yaw:
        a = agents[str(i)]
        a["yaw_error_final"] = _final(m.t, m.yaw[i])
        a["common_frame_position_error_final"] = _final(m.t, m.position[i])
        a["formation_error_final"] = _final(m.t, m.formation[i])
    settle = {
        "relative_yaw_max": settle_time(m.t, _max(m.rel_yaw), THRESHOLDS["relative_yaw"]),
        "yaw_max": settle_time(m.t, _max(m.yaw), THRESHOLDS["yaw"]),
        "position_max": settle_time(m.t, _max(m.position), THRESHOLDS["position_m"]),
        "formation_max": settle_time(m.t, _max(m.formation), THRESHOLDS["formation_m"]),
    }
    weak = [f"{i}->{j}" for (i, j), x in m.excitation.items() if x < PE_MIN]
    for (i, j), x in m.excitation.items():
        edges[f"{i}->{j}"]["excitation_last_10s"] = x
    warnings = [
        f"edge {e}: no persistent excitation over the last {PE_WINDOW_S:g} s (∫|v_j,xy|² dt < {PE_MIN:g} m²/s: robot {e.split('->')[1]} hardly moves in the plane), so (7)/(8) cannot converge on it (Theorem 1, Remark 2)"
        for e in weak
    ]
    return ({"warnings": warnings} if warnings else {}) | {
        "edges": edges,
        "formation": {
            "thresholds": THRESHOLDS,
            "settle_s": settle,  # the first time after which the max over edges / robots stays below
            "relative_yaw_error_max_final": _final(m.t, _max(m.rel_yaw)),
            "yaw_error_max_final": _final(m.t, _max(m.yaw)),
            "position_error_max_final_m": _final(m.t, _max(m.position)),
            "formation_error_max_final_m": _final(m.t, _max(m.formation)),
            "common_rotation_alpha_final_rad": float(m.alpha[-1]),
            # (13) keeps α constant once the yaw errors are small (Theorem 2's limit is set by
            # ẑ(0)); how far it wandered over the run's second half (once the yaw settled) says
            # whether the coupling is Hermitian in practice (message ages, copies of an
            # edge's estimate).  Right after the yaw settles, the transient's end moves α by 3e-3
            "common_rotation_alpha_drift_rad": _drift(m.t, m.alpha, None if settle["yaw_max"] is None else max(settle["yaw_max"], 0.5 * float(m.t[-1]))),
        },
    }


def _drift(t: np.ndarray, alpha: np.ndarray, t0: float | None) -> float | None:
    """max − min of the (unwrapped) common rotation from ``t0`` on; None before it settles."""
    if t0 is None:
        return None
    a = np.unwrap(alpha[t >= t0])
    return float(a.max() - a.min()) if a.size else None


def convergence(sc: Scenario, errs: dict[int, np.ndarray], m: FormationMetrics, duration: float, thresholds: tuple[float, float]) -> dict[str, Any]:
    """Settle times at the family's own THRESHOLDS (the run's attitude/position thresholds are the observers')."""
    s = {k: settle_time(m.t, _max(v), thr) for k, v, thr in (("yaw", m.yaw, THRESHOLDS["yaw"]), ("position", m.position, THRESHOLDS["position_m"]))}
    return {"attitude_below": THRESHOLDS["yaw"], "position_below": THRESHOLDS["position_m"], "attitude_converged_at": s["yaw"], "position_converged_at": s["position"], "over": "max over robots, up to the common rotation (and translation)"}


def write_csv(path: Path, m: FormationMetrics) -> None:
    keys = [f"rel_yaw_{i}_{j}" for i, j in m.rel_yaw] + [f"{what}_{i}" for what in ("yaw", "position", "formation") for i in m.yaw]
    cols = list(m.rel_yaw.values()) + [d[i] for d in (m.yaw, m.position, m.formation) for i in m.yaw]
    with files.whole(path) as tmp, tmp.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "alpha", *keys])
        for k in range(0, len(m.t), 10):  # 10 Hz rows
            w.writerow([f"{m.t[k]:.2f}", f"{m.alpha[k]:.6f}", *(f"{c[k]:.6e}" for c in cols)])


def plot_formation(out: Path, sc: Scenario, m: FormationMetrics) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True)
    panels = (
        (axes[0][0], m.rel_yaw, "(a) relative yaw ‖ẑ_ψij − z_ψij‖", lambda k: f"{k[0]}→{k[1]}"),
        (axes[0][1], m.yaw, "(b) yaw in the common frame (up to α)", str),
        (axes[1][0], m.position, "(c) position in the common frame (up to rotation, translation), m", str),
        (axes[1][1], m.formation, "(d) formation error, m", str),
    )
    for ax, series, title, label in panels:
        for k, v in series.items():
            ax.semilogy(m.t, np.maximum(v, 1e-6), lw=0.8, label=label(k))
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=6, ncol=2)
    for ax in axes[1]:
        ax.set_xlabel("t (s)")
    fig.suptitle(f"{sc.name}: De Carli et al. Fig. 2", fontsize=10)
    fig.tight_layout()
    files.save_png(fig, out / "formation.png")
    plt.close(fig)


def formation_lines(summary: dict[str, Any]) -> list[str]:
    f = summary.get("formation", {})
    pe = [w for w in summary.get("warnings", []) if "persistent excitation" in w]
    s = f.get("settle_s", {})

    def g(x: float | None) -> str:
        return "never" if x is None else f"{x:.2f} s"

    def e(x: float | None) -> str:
        return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.2e}"

    return [
        f"relative yaw (max over edges): final {e(f.get('relative_yaw_error_max_final'))}, below {THRESHOLDS['relative_yaw']:g} from {g(s.get('relative_yaw_max'))}",
        f"common-frame yaw (max over robots, up to α): final {e(f.get('yaw_error_max_final'))}, below {THRESHOLDS['yaw']:g} from {g(s.get('yaw_max'))}",
        f"common-frame position (up to rotation and translation): final {e(f.get('position_error_max_final_m'))} m, below {THRESHOLDS['position_m']:g} m from {g(s.get('position_max'))}",
        f"formation error (max over robots): final {e(f.get('formation_error_max_final_m'))} m, below {THRESHOLDS['formation_m']:g} m from {g(s.get('formation_max'))}",
    ] + [f"WARNING: {w}" for w in pe]


def metrics(sc: Scenario, rec: Recording) -> FormationMetrics:
    return formation_metrics(sc, rec)


def headline(sc: Scenario, agents: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    """The means over the robots of their errors as they stand (the formation block has them up to the common frame)."""
    return base.headline(sc, agents, extra) | {"mean_over": "robots: |R̂_i R_i^T|_I and |p̂_i − p_i| as they stand, without the common rotation (see formation)"}


def series(sc: Scenario, errs: dict[int, np.ndarray], m: FormationMetrics, duration: float) -> base.Series:
    """The max over robots of the common-frame yaw and position errors, up to the common rotation
    (and translation), on the 10 ms grid."""
    return m.t, _max(m.yaw), _max(m.position)


def finals(summary: dict[str, Any]) -> tuple[float | None, float | None]:
    f = summary["formation"]
    return f["yaw_error_max_final"], f["position_error_max_final_m"]


def series_from_files(folder: Path, sc: Scenario, duration: float) -> base.Series:
    """:func:`series` from formation.csv (its 10 Hz rows)."""
    with open(folder / "formation.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    t = np.array([float(r["t"]) for r in rows])
    out = []
    for prefix in ("yaw_", "position_"):
        cols = [c for c in rows[0] if c.startswith(prefix)] if rows else []
        out.append(_max({c: np.array([float(r[c]) for r in rows]) for c in cols}) if cols else np.full(len(t), np.nan))
    return t, out[0], out[1]


def write(out_dir: Path, sc: Scenario, rec: Recording, m: FormationMetrics) -> None:
    write_csv(out_dir / "formation.csv", m)


def plot(out: Path, sc: Scenario, errs: dict[int, np.ndarray], m: FormationMetrics, rec: Recording) -> None:
    """De Carli et al.'s Fig. 2, and each robot's errors as they stand."""
    plot_formation(out, sc, m)
    base.plot_errors(out, sc, errs, rec)


def table_lines(summary: dict[str, Any]) -> list[str]:
    lines = text.agent_rows(summary)
    lines.append("(att.err / pos.err as they stand; up to the common rotation and translation:)")
    lines += formation_lines(summary)
    parts: dict[str, list[float]] = {n: [] for a in summary["agents"].values() for n in a.get("parts", {})}
    for a in summary["agents"].values():
        for n, v in a.get("parts", {}).items():
            parts[n].append(v["rate_hz"])
    if parts:
        lines.append("part rates (Hz, min-max over robots): " + ", ".join(f"{n} {min(v):.1f}-{max(v):.1f}" for n, v in parts.items()))
    return lines + [text.mean_line(summary, "followers")]


# --------------------------------------------------------------------------- zswarm sweep and generate

SWEEP_PARTS = (("rel", "relative_yaw", "rel_yaw_"), ("yaw", "yaw", "yaw_"), ("pos", "position", "position_"), ("form", "formation", "formation_"))


def sweep_columns(folder: Path, s: dict[str, Any], sc: Scenario, t: np.ndarray, att: np.ndarray) -> dict[str, Any]:
    """Per stage — relative yaw (7)/(8), common-frame yaw (13), position (21), formation (30) —
    the max over edges/robots averaged over the last quarter of the run (a floor, less noisy
    than the last sample), its settle time, and the drift of the common rotation α."""
    f = s.get("formation")
    if f is None:
        return {}
    with open(folder / "formation.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    tt = np.array([float(r["t"]) for r in rows])
    late = tt >= 0.75 * tt[-1]
    out: dict[str, Any] = {}
    for short, key, prefix in SWEEP_PARTS:
        cols = [c for c in rows[0] if c.startswith(prefix)]
        m = np.array([[float(r[c]) for c in cols] for r in rows])
        m = np.where(np.isfinite(m), m, -np.inf)  # an edge not measured yet has no error
        mx = m.max(axis=1) if cols else np.full(len(tt), -np.inf)
        mx[~np.isfinite(mx)] = np.nan
        tail = mx[late & np.isfinite(mx)]
        out[f"{short}_late_max_mean"] = float(tail.mean()) if tail.size else None
        out[f"{short}_settle_s"] = f["settle_s"].get(f"{key}_max")
    out["alpha_drift_rad"] = f.get("common_rotation_alpha_drift_rad")
    return out


SWEEP = Sweep(
    columns=(*(c for short, _, _ in SWEEP_PARTS for c in (f"{short}_late_max_mean", f"{short}_settle_s")), "alpha_drift_rad"),
    from_run=sweep_columns,
    # Each stage's floor, so a figure shows which of the three observers and the controller suffers first.
    figures=(
        ("rel_late_max_mean", "relative yaw (7)/(8), max over edges", True),
        ("yaw_late_max_mean", "common-frame yaw (13), max over robots", True),
        ("pos_late_max_mean", "common-frame position (21), max (m)", True),
        ("form_late_max_mean", "formation error (30), max (m)", True),
    ),
)


def offsets(n: int) -> dict[str, Any]:
    """The formation (30) of n robots: offsets on a circle, heights alternating, as in §IV's figure."""
    r = 4.0 * max(1.0, n / 8)
    return {"p_star": [[round(r * math.cos(2 * math.pi * k / n), 4) + 0.0, round(r * math.sin(2 * math.pi * k / n), 4) + 0.0, float(k % 2)] for k in range(n)]}


RECIPES = {
    "formation": Recipe(
        "decarli-8-formation",
        "De Carli et al.: relative yaw (7)/(8), common-frame yaw (13) and position (21) observers, formation control (30)",
        "sensing",
        {"name": "common_frame_formation", "gains": {"k_pe": 20.0, "k_psi": 600.0, "k_z": 40.0, "k_p": 1.0, "k_c": 0.5, "nu_max": 1.0}},
        {"step": 0.001, "sensor_rate": 200.0, "plant": "kinematic"},
        rate=200.0,
        duration=40.0,
        params=offsets,
    ),
}

FAMILY = Family(
    report=Report(metrics=metrics, summary=summary, headline=headline, series=series, finals=finals, convergence=convergence, series_from_files=series_from_files, write=write, plot=plot, table_lines=table_lines),
    sweep=SWEEP,
    recipes=RECIPES,
)
