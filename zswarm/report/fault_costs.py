"""What each fault of a run cost (summary.json ``faults``) and the timeline on the plots.

Per fault (``[[faults]]``, zswarm/scenario/__init__.py):

* ``token``: when the affected process's liveliness token went and came back, as the
  recorder saw it (world time; after the fault's start and after its end);
* ``detected_by``: when each in-neighbour marked the agent lost and back (its own stats,
  ``neighbor_events``: the agents' detection);
* ``lost``: messages that never reached the recorder around the fault, counted from the
  gaps in their sequence numbers, per stream (an incarnation at a time: a restarted
  process numbers from 0 again);
* ``steps_missed``: for an agent that was dead or stopped, the steps it did not take;
* ``reconvergence``: the team's error measure (summary ``convergence.measure``) against its
  level before the fault — its largest value over the second before — and the first time
  after the fault's end from which it stays at or below that level.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from zswarm.transport import keys

if TYPE_CHECKING:
    from zswarm.report.decoded import Recording
    from zswarm.scenario import Fault, Scenario

PRE_WINDOW_S = 1.0  # the level before a fault: the error's largest value over this window
LOSS_MARGIN_S = 1.0  # gaps counted for a fault: those that end within [at, end + this]


def world_time(rec: Recording, event: dict[str, Any]) -> float | None:
    """The world time of a liveliness event: sim stamps events in world time (``log_t``, ns);
    a run in Unix time, converted with the start's epoch and time scale."""
    log_t = event.get("log_t")
    start = rec.start
    if start is not None and start.get("time_scale", 0.0) > 0:
        t_wall = event.get("t_wall", None if log_t is None else log_t / 1e9)
        return None if t_wall is None else (t_wall - start["epoch"]) * start["time_scale"]
    return None if log_t is None else log_t / 1e9


def _token(rec: Recording, who: tuple[str, int], f: Fault) -> dict[str, Any]:
    """When the token of ``who`` (role, id) went (first loss at or after the fault's start) and
    came back; a token with the run secret's tag when it had one (keys.parse_alive)."""
    lost = back = None
    for e in rec.alive_events:
        if keys.parse_alive(str(e.get("key", ""))) != who:
            continue
        t = world_time(rec, e)
        if t is None:
            continue
        if lost is None and not e.get("alive") and t >= f.at - 0.05:
            lost = t
        elif lost is not None and back is None and e.get("alive") and t >= lost:
            back = t
    out: dict[str, Any] = {"lost_at": lost, "lost_after_s": None if lost is None else round(lost - f.at, 4)}
    out["back_at"] = back
    if back is not None and math.isfinite(f.end):
        out["back_after_end_s"] = round(back - f.end, 4)
    return out


def _lost(rec: Recording, f: Fault) -> dict[str, int]:
    """Messages missing from the recording around the fault, per stream, from sequence gaps."""
    lo, hi = f.at, (f.end if math.isfinite(f.end) else f.at) + LOSS_MARGIN_S
    out: dict[str, int] = {}
    for stream, env in rec.envelopes.items():
        last: dict[int, tuple[float, int]] = {}  # inc -> (t, seq) of the newest so far
        n = 0
        for t, inc, seq in sorted(env, key=lambda e: (e[1], e[2])):
            prev = last.get(inc)
            if prev is not None and seq > prev[1] + 1 and lo <= t and prev[0] <= hi:
                n += seq - prev[1] - 1
            last[inc] = (t, seq)
        if n:
            out[stream] = n
    return dict(sorted(out.items()))


def reconvergence(t: np.ndarray, err: np.ndarray, f: Fault) -> dict[str, Any]:
    """The error's level before the fault and when, after its end, it is back to stay."""
    before = (t >= f.at - PRE_WINDOW_S) & (t <= f.at)
    ok = before & np.isfinite(err)
    if not ok.any() or not math.isfinite(f.end):
        return {"level": None, "reconverged_at": None, "reconvergence_s": None}
    level = float(np.max(err[ok]))
    after = t >= f.end
    bad = np.nonzero(after & ~(err <= level))[0]
    idx = np.nonzero(after)[0]
    if not len(idx):
        at = None
    elif not len(bad):
        at = float(t[idx[0]])
    elif bad[-1] + 1 < len(t):
        at = float(t[bad[-1] + 1])
    else:
        at = None  # not back at the end of the run
    peak = float(np.nanmax(err[(t >= f.at)])) if np.any(t >= f.at) else None
    return {"level": level, "peak_after": peak, "reconverged_at": at, "reconvergence_s": None if at is None else round(at - f.end, 4)}


def summary(sc: Scenario, rec: Recording, engine: str, t: np.ndarray, err: np.ndarray, measure: str) -> list[dict[str, Any]]:
    """summary.json ``faults``: one entry per fault, in time order (see the module docstring)."""
    out = []
    for f in sc.faults:
        d: dict[str, Any] = {"kind": f.kind, "what": f.describe(), "at": f.at, "end": f.end if math.isfinite(f.end) else None}
        if f.agent is not None:
            d["agent"] = f.agent
        if f.link is not None:
            d["link"] = f.link
        if engine == "sim" and f.kind == "router":
            d["applied"] = False
            d["note"] = "sim has no router: this fault needs zswarm run"
            out.append(d)
            continue
        d["applied"] = True
        if f.agent is not None:
            d["token"] = _token(rec, ("agent", f.agent), f)
            detected: dict[str, Any] = {}
            for a in sc.agents:
                if f.agent not in a.neighbors:
                    continue
                evs = [e for st in _incarnations(rec, a.id) for e in st.get("neighbor_events", []) if e[0] == f.agent]
                lost = next((e[1] for e in evs if not e[2] and e[1] >= f.at - 0.05), None)
                back = next((e[1] for e in evs if e[2] and lost is not None and e[1] >= lost), None)
                detected[str(a.id)] = {
                    "lost_after_s": None if lost is None else round(lost - f.at, 4),
                    "back_after_end_s": None if back is None or not math.isfinite(f.end) else round(back - f.end, 4),
                }
            d["detected_by"] = detected
            rate = sc.agent(f.agent).clock.rate
            end = min(f.end, float(rec.truth_t[-1])) if len(rec.truth_t) else f.end
            taken = sum(1 for e in rec.est.get(f.agent, []) if f.at < e[0] < end)
            d["steps_missed"] = max(0, round((end - f.at) * rate) - taken)
        d["lost"] = _lost(rec, f)
        d["lost_total"] = sum(d["lost"].values())
        d["reconvergence"] = {"measure": measure, **reconvergence(t, err, f)}
        out.append(d)
    return out


def _incarnations(rec: Recording, agent: int) -> list[dict[str, Any]]:
    return [st for (r, i, _), st in sorted(rec.stats_by_inc.items()) if r == "agent" and i == agent]


def mark(ax: Any, sc: Scenario, rec: Recording | None = None) -> None:
    """The faults on an error plot: a shaded span from each fault's start to its end (a red
    line for a kill that is never undone), and the liveliness changes as ticks on top."""
    for f in sc.faults:
        color = {"kill": "tab:red", "stop": "tab:orange", "router": "tab:purple", "cut": "tab:gray"}[f.kind]
        if math.isfinite(f.end) and f.end > f.at:
            ax.axvspan(f.at, f.end, color=color, alpha=0.15, lw=0)
        ax.axvline(f.at, color=color, lw=0.8, ls="--")
    if rec is not None and sc.faults:
        for e in rec.alive_events:
            t = world_time(rec, e)
            if t is not None and t >= 0 and "/agent/" in e.get("key", ""):
                ax.plot([t], [1.0], marker="v" if not e.get("alive") else "^", color="k", ms=4, transform=ax.get_xaxis_transform(), clip_on=False)
