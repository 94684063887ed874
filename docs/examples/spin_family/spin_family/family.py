"""``spin``: an experiment family of one's own — the team's angular speed.

The Chapter 5 laws bring rigid bodies to a common attitude at rest (ω_i → 0).  This family
reports what zswarm's ``sync`` family reports and adds the team's angular speed
``s(t) = mean_i ‖ω_i(t)‖`` (rad/s, body frame, of the truth) on a 100 Hz grid:

* report: a ``spin`` block in summary.json (its value at the start, its final value — the
  mean over the last second — and when it stays below 0.01 rad/s), a line of the end-of-run
  table, ``plots/spin.png``;
* ``zswarm sweep``: a column ``spin_final`` and a figure panel of it;
* ``zswarm basin``: a draw is *still* when s stays below the threshold;
* the batched engine: s of every draw at once (:class:`SpinMeasure`), beside the ``sync``
  family's own measures (which fill the generic sweep columns);
* ``zswarm generate spin-hybrid``: the §5.6 scenario's law and world on N bodies;
* ``zswarm spin-info RESULTS``: the spin block of a results folder.

Registered in pyproject.toml (entry points ``zswarm.families`` and ``zswarm.algorithms``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from zswarm.families import sync
from zswarm.families.contract import Basin, Batched, Command, Family, Recipe, Sweep
from zswarm.families.measure import Context, Result, Truth
from zswarm.families.synergistic import HYBRID_PARAMS_5
from zswarm.report.series import final_of_grid, settle_time

STILL = 0.01  # rad/s: "at rest"


def speed(sc: Any, m: sync.SyncMetrics) -> np.ndarray:
    """s(t) = mean_i ‖ω_i(t)‖ on the sync family's grid."""
    return np.mean([m.omega[i] for i in sc.ids], axis=0)


# --------------------------------------------------------------------------- the report


def summary(sc: Any, rec: Any, m: sync.SyncMetrics, agents: dict[str, Any], duration: float) -> dict[str, Any]:
    s = speed(sc, m)
    return sync.summary(sc, rec, m, agents, duration) | {"spin": {"initial": float(s[0]), "final": final_of_grid(m.t, s), "below_0.01_from_s": settle_time(m.t, s, STILL)}}


def table_lines(summary: dict[str, Any]) -> list[str]:
    sp = summary["spin"]
    since = "never" if sp["below_0.01_from_s"] is None else f"{sp['below_0.01_from_s']:.2f} s"
    return [*sync.table_lines(summary), f"spin: mean_i ‖ω_i‖ {sp['initial']:.3g} rad/s at start, final {sp['final']:.3g} rad/s, below {STILL:g} from {since}"]


def plot(out: Path, sc: Any, errs: Any, m: sync.SyncMetrics, rec: Any) -> None:
    sync.plot(out, sc, errs, m, rec)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.semilogy(m.t, np.maximum(speed(sc, m), 1e-12))
    ax.axhline(STILL, color="r", lw=0.8)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("mean_i ‖ω_i‖ (rad/s)")
    ax.set_title(f"{sc.name}: the team's angular speed")
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "spin.png", dpi=100)
    plt.close(fig)


# --------------------------------------------------------------------------- the batched engine, sweep and basin


class SpinMeasure:
    """s of every draw at the samples of the basin grid (the basin measure), its final for a
    sweep's rows (``Result.extra["spin_final"]``), beside the sync family's own measure."""

    def __init__(self, ctx: Context) -> None:
        self.edges = sync.TruthEdges(ctx)  # the generic columns: max_k |R̄_k|_I, its finals
        self.every = self.edges.every  # the samples on the basin grid
        self.t: list[float] = []
        self.s: list[np.ndarray] = []

    def sample(self, k: int, t: float, truth: Truth) -> None:
        self.edges.sample(k, t, truth)
        if k % self.every == 0:
            self.t.append(t)
            self.s.append(np.mean(np.linalg.norm(truth.omega, axis=-1), axis=1))  # (M,)

    def result(self, res: Result) -> Result:
        res = self.edges.result(res)
        t, s = np.round(np.array(self.t), 9), np.array(self.s).T  # (M, T)
        res.t, res.max_rel = t, s  # the basin judges s
        res.extra["spin_final"] = np.array([final_of_grid(t, row) for row in s])
        return res


def basin_series(sc: Any, rec: Any) -> tuple[np.ndarray, np.ndarray]:
    m = sync.sync_metrics(sc, rec)
    return m.t, speed(sc, m)


SWEEP = Sweep(
    columns=("spin_final",),
    from_run=lambda folder, s, sc, t, att: {"spin_final": s["spin"]["final"]},
    from_batch=lambda res, n, sc: {"spin_final": float(res.extra["spin_final"][n])},
    figures=(
        ("final_attitude_error", "final mean |R̄_k|_I", True),
        ("spin_final", "final mean_i ‖ω_i‖ (rad/s)", True),
        ("conv_attitude_s", "max_k |R̄_k|_I below 0.01 from (s)", False),
        ("jumps", "jumps of ξ (count)", False),
    ),
)


# --------------------------------------------------------------------------- generate and a command of its own


def spin_info_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("results", type=Path, help="a results folder of a spin run")


def spin_info(args: argparse.Namespace) -> int:
    s = json.loads((args.results / "summary.json").read_text())
    if "spin" not in s:
        print(f"{args.results}: not a run of the spin family (its family: {s.get('report_family')})")
        return 1
    print(json.dumps(s["spin"]))
    return 0


FAMILY = Family(
    report=dataclasses.replace(sync.FAMILY.report, summary=summary, table_lines=table_lines, plot=plot),
    sweep=SWEEP,
    basin=Basin(sync.basin_start, basin_series, verdict="still", measure="mean_i ‖ω_i‖", grid_s=sync.BASIN_GRID_S),
    batched=Batched("rigid_body", truth=SpinMeasure),
    recipes={
        "spin-hybrid": Recipe(
            "thesis-5.6-hybrid7",
            "the §5.6 hybrid law (5.19), (5.21), (5.7) on N rigid bodies, reported with their angular speed",
            "tree",
            {"name": "spin_sync", "gains": {"k_R": 0.4, "k_omega": 0.1, "k_xi": 20}, "params": HYBRID_PARAMS_5},
            {"step": 0.001, "sensor_rate": 200.0, "plant": "rigid_body"},
            duration=150.0,
            estimate=("xi",),
        )
    },
    commands=(Command("spin-info", "print the spin block of a results folder", "Prints summary.json's spin block of a run of the spin family.", spin_info_arguments, spin_info),),
)
