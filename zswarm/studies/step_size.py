"""Convergence study: a scenario at its own rates against the same scenario at fine rates.

The continuous-time observers are what the thesis proves things about; a
discrete, asynchronous implementation should approach them as its steps
shrink.  :func:`refine` gives the same scenario with every agent at
``agent_rate`` (1 kHz) and sensors at ``sensor_rate`` (2 kHz, truth step
halved to 0.5 ms); :func:`compare` puts the times to thresholds and the
final errors of the two side by side.  A default-rate run that converges
*faster* than the fine one, or ends far below it, is integrating something
other than the equations.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from zswarm import report, results
from zswarm.families import contract as family
from zswarm.scenario import Scenario


def refine(sc: Scenario, agent_rate: float = 1000.0, sensor_rate: float = 2000.0) -> Scenario:
    """The same scenario with every agent ticking at ``agent_rate`` and sensors at ``sensor_rate``;
    parts with rates of their own (De Carli's 200/100/50 Hz) speed up with the agent's clock."""
    scale = agent_rate / max(a.clock.rate for a in sc.agents)
    agents = tuple(dataclasses.replace(a, clock=msgspec.structs.replace(a.clock, rate=agent_rate)) for a in sc.agents)
    return dataclasses.replace(sc, agents=agents, sensor_rate=sensor_rate, step=min(sc.step, 1.0 / sensor_rate), part_rate_scale=sc.part_rate_scale * scale)


@dataclass(frozen=True)
class Series:
    """The team's errors the study compares (its report family's series) and the final ones."""

    t: np.ndarray
    att: np.ndarray
    pos: np.ndarray
    final_att: float
    final_pos: float | None


def run(sc: Scenario, out_dir: Path) -> Series:
    """``zswarm sim`` of ``sc`` in memory (no recording file); its mean error series."""
    from zswarm.engines.sim import LEAN_SKIP, simulate

    out_dir.mkdir(parents=True, exist_ok=True)
    msgs = simulate(sc, out_dir, sc.duration, sc.seed, lean=True, record=False)
    assert isinstance(msgs, list)
    parts = results.make_report_parts(out_dir, sc, "sim", sc.duration, 0.0, sc.seed, plots=False, messages=msgs, not_recorded=LEAN_SKIP)
    fam = family.of(sc)
    t, att, pos = fam.series(sc, parts.errors, parts.metrics, sc.duration)
    fa, fp = fam.finals(parts.summary)
    return Series(t, att, pos, float(fa), None if fp is None or not np.isfinite(pos).any() else float(fp))


ATT_THRESHOLDS = (1e-1, 1e-2, 1e-3)
POS_THRESHOLDS = (1.0, 0.1)


def escape_time(s: Series, level: float = 0.9) -> float:
    """When the mean attitude error first falls below ``level``: the start of convergence
    for a scenario that starts on an unstable equilibrium (its escape is set by round-off
    and asynchrony, not by the equations)."""
    below = np.nonzero(s.att < level)[0]
    return float(s.t[below[0]]) if len(below) else float("nan")


def reference(fine: Series, from_escape: bool = False) -> dict[str, Any]:
    """What :func:`compare` reads of the fine run: ``{times, final_att, final_pos}``, ``times`` the
    rows ``{key, thr, t}`` of each threshold ``thr`` of the series ``key`` ("att", "pos") that it
    reaches after its start and at least 1 s before its end, at ``t`` (from the escape when
    ``from_escape``).  Plain numbers: a reference kept in a file (JSON) compares as the run."""
    t0 = escape_time(fine) if from_escape else 0.0
    end = float(fine.t[-1])
    times: list[dict[str, Any]] = []
    for key, thrs in (("att", ATT_THRESHOLDS), ("pos", POS_THRESHOLDS)):
        fs = getattr(fine, key)
        if not np.isfinite(fs).any():
            continue
        for thr in thrs:
            tf = report.convergence_time(fine.t, fs, thr)
            if tf is None or tf > end - 1.0 or tf == 0.0:
                continue
            times.append({"key": key, "thr": thr, "t": tf - t0})
    return {"times": times, "final_att": fine.final_att, "final_pos": fine.final_pos}


def compare(default: Series, fine: Series | dict[str, Any], from_escape: bool = False) -> list[dict[str, Any]]:
    """Rows ``{what, default, fine}``: times to each threshold the fine run reaches at least
    1 s before its end (from the escape when ``from_escape``), then the final errors.  ``fine``
    is the run or its :func:`reference`."""
    ref = reference(fine, from_escape) if isinstance(fine, Series) else fine
    t0d = escape_time(default) if from_escape else 0.0
    rows: list[dict[str, Any]] = []
    for r in ref["times"]:
        td = report.convergence_time(default.t, getattr(default, r["key"]), r["thr"])
        rows.append({"what": f"{r['key']} < {r['thr']:g} (s)", "default": None if td is None else td - t0d, "fine": r["t"]})
    rows.append({"what": "final attitude", "default": default.final_att, "fine": ref["final_att"]})
    if ref["final_pos"] is not None and default.final_pos is not None:
        rows.append({"what": "final position", "default": default.final_pos, "fine": ref["final_pos"]})
    return rows
