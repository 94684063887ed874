"""The text of the table printed at the end of a run: the lines every family shares.

A family's ``table_lines(summary)`` gives the lines between the title and the footer
(:func:`zswarm.results.pipeline.table`); these are the pieces it builds them from.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def e(x: float | None) -> str:
    """A number in the table: ``1.23e-04``, or ``n/a``."""
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.2e}"


def s(x: float | None) -> str:
    """A time in the table: ``12.3``, or ``never``."""
    return "never" if x is None else f"{x:.1f}"


def title(summary: dict[str, Any]) -> str:
    d, seed = summary["duration_s"], summary["seed"]
    when = "duration unknown" if d is None else f"{d:g} s"
    return f"{summary['scenario']} ({summary['algorithm']}, engine={summary['engine']}, {when}, seed {'unknown' if seed is None else seed})"


def agent_rows(summary: dict[str, Any]) -> list[str]:
    """One row per agent: role, alive, final errors, steps, rate, missed ticks."""
    lines = [f"{'agent':>5} {'role':<8} {'alive':<5} {'att.err':>10} {'pos.err':>10} {'steps':>6} {'rate Hz':>8} {'missed':>6}"]
    for i, a in summary["agents"].items():
        lines.append(
            f"{i:>5} {a['role']:<8} {'yes' if a['alive_at_end'] else 'NO':<5} {e(a['attitude_error_final']):>10} "
            f"{e(a['position_error_final']):>10} {a['steps']:>6} {a['step_rate_hz']:>8.2f} {a['missed_deadlines']:>6}"
        )
    return lines


def mean_line(summary: dict[str, Any], who: str) -> str:
    """The means of the last second over ``who``, and the links' dropped messages."""
    drops = sum(v.get("dropped", 0) for v in summary["links"].values())
    return (
        f"mean over {who} (last 1 s): attitude {e(summary['mean_attitude_error_final'])}, "
        f"position {e(summary['mean_position_error_final'])}; links: {len(summary['links'])}, dropped messages: {drops}"
    )


def footer_lines(summary: dict[str, Any]) -> list[str]:
    """What the table says under its rows: the run's CPU, whether it completed and kept up."""
    ov = summary.get("overload") or {}
    cpu = summary.get("cpu") or {}
    lines = []
    if cpu.get("run_wall_s"):
        lines.append(
            f"cpu: every process together {100 * cpu['run_share_of_cores']:.0f} % of the {cpu['cores']} cores over the run "
            f"({cpu['run_cpu_total_s']:.1f} s in {cpu['run_wall_s']:.1f} s; per process in processes.json)"
        )
    fates = [f"agent {i}: {a['fate']}" for i, a in (summary.get("agents") or {}).items() if a.get("fate", "finished") != "finished"]
    if fates:  # how the processes ended, from their exit status (the launcher's)
        lines.append("ended: " + "; ".join(fates) + ("" if all(a.get("fate") != "finished; final stats not recorded" for a in summary["agents"].values()) else " (their counts are from their last recorded stats)"))
    lower = [k for k, v in (summary.get("links") or {}).items() if v.get("sent_is_lower_bound")]
    if lower:  # a sender killed: what it sent after its last recorded stats is not counted
        lines.append(f"sent counts are lower bounds on links {', '.join(lower)} (a sender was killed: its last counts were not recorded)")
    lower_rx = [k for k, v in (summary.get("links") or {}).items() if v.get("delivered_is_lower_bound")]
    if lower_rx:  # a receiver killed: what it received after its last recorded stats is not counted
        lines.append(f"delivered counts are lower bounds on links {', '.join(lower_rx)} (a receiver was killed: its last counts were not recorded)")
    if summary.get("problems"):
        lines.append("NOT COMPLETED: " + "; ".join(summary["problems"]))
    if ov.get("late"):
        lines.append(f"LATE SENSOR DATA: {'; '.join(ov['late'])}: these agents published at less than their rate (they caught up at the next tick)")
    if not ov.get("overloaded"):
        return lines
    return lines + [
        f"OVERLOADED: {'; '.join(ov['reasons'])}: this machine did not keep up, so the "
        "agents stepped on older data than configured and these errors may not be the algorithm's alone; compare with "
        "zswarm sim, or run with --time-scale 0.5 or fewer processes per core"
    ]
