"""``bearing_fit``: a report family of one's own (docs/tutorial-own-algorithm.md).

The bearing-only localization law drives every bearing residual to zero:
``e_ij = ‖P_{g_ij}(p̂_i − p̂_j)‖``, g_ij the true bearing from i to j.  This family
adds it to what the default (leader–follower) family reports: per edge j -> i on a
0.1 s grid, its value over the last second, the max over edges, and when that max
stays below 1 cm; a line of the end-of-run table; ``plots/bearing_fit.png``.

A family is a module that exports ``FAMILY``, a ``zswarm.families.contract.Family``; of its report
(``zswarm.families.contract.Report``) what it leaves out (here the headline errors, convergence,
series) is the leader–follower default of ``zswarm.report.base``.  An algorithm names it in
``SPEC.report``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zswarm.families.contract import Family, Report
from zswarm.report import base
from zswarm.report import table as text
from zswarm.report.series import final, held, max_over, settle_time

GRID_S = 0.1  # s
THRESHOLD_M = 0.01


@dataclass(frozen=True)
class Fit:
    t: np.ndarray
    residual: dict[tuple[int, int], np.ndarray]  # (j, i) -> e_ij on the grid (NaN before both estimates)


def metrics(sc: Any, rec: Any) -> Fit:
    t = np.arange(0.0, float(rec.truth_t[-1]) + 1e-9, GRID_S)
    col = {i: k for k, i in enumerate(rec.truth_ids)}
    P = held(rec.truth_t, rec.truth_p, t)  # (T, n, 3): the true positions
    p_hat = {}
    for i in sc.ids:
        est = rec.est.get(i, [])
        p_hat[i] = held(np.array([e[0] for e in est], dtype=float), np.array([e[2] for e in est], dtype=float).reshape(-1, 3), t)
    residual = {}
    for j, i in sc.edges:  # j -> i: i measures its bearing to j
        g = P[:, col[j]] - P[:, col[i]]
        g = g / np.linalg.norm(g, axis=1, keepdims=True)
        d = p_hat[i] - p_hat[j]
        residual[(j, i)] = np.linalg.norm(d - g * np.sum(g * d, axis=1, keepdims=True), axis=1)
    return Fit(t, residual)


def summary(sc: Any, rec: Any, m: Fit, agents: dict[str, Any], duration: float) -> dict[str, Any]:
    worst = max_over(m.residual)
    return {
        "bearing_fit": {
            "measure": "‖P_g (p̂_i − p̂_j)‖ per edge j->i, g the true bearing from i to j (m), 0.1 s grid",
            "edges": {f"{j}->{i}": final(m.t, v, duration) for (j, i), v in m.residual.items()},
            "max_final": final(m.t, worst, duration),
            "threshold_m": THRESHOLD_M,
            "max_below_threshold_from_s": settle_time(m.t, worst, THRESHOLD_M),
        }
    }


def table_lines(summary: dict[str, Any]) -> list[str]:
    f = summary["bearing_fit"]
    return base.table_lines(summary) + [
        f"bearing residual (max over edges): final {text.e(f['max_final'])} m, below {f['threshold_m']:g} m from {text.s(f['max_below_threshold_from_s'])} s"
    ]


def plot(out: Path, sc: Any, errs: dict[int, np.ndarray], m: Fit, rec: Any) -> None:
    base.plot_errors(out, sc, errs, rec)  # the default figures, then this family's
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    for (j, i), v in m.residual.items():
        ax.semilogy(m.t, np.maximum(v, 1e-9), lw=0.8, label=f"{j}→{i}")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("‖P_g (p̂_i − p̂_j)‖ (m)")
    ax.set_title(f"{sc.name}: bearing residual per edge")
    ax.legend(fontsize=6, ncol=4)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(out / "bearing_fit.png", dpi=100)
    plt.close(fig)


FAMILY = Family(report=Report(metrics=metrics, summary=summary, table_lines=table_lines, plot=plot))
