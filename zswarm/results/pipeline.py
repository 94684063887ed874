"""The generic report pipeline: a recording -> errors.csv, summary.json, the family's files, plots, the table.

Everything that depends on the kind of algorithm is its report family's (``SPEC.report``,
:mod:`zswarm.report.family`): its metrics, its keys of summary.json, its convergence
measure, its CSVs, plots and lines of the table.  What is here holds for every run:
the per-agent estimate errors (:func:`zswarm.report.decoded.errors`), the processes'
counters, the links, whether the recording is complete, whether the run kept up and
completed.  "final" is the mean over the last second of the run.
"""

from __future__ import annotations

import collections
import contextlib
import csv
import json
import math
from collections import defaultdict
from collections.abc import Collection, Generator, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from zswarm.families import contract as family
from zswarm.recording.layout import write_layout
from zswarm.recording.mcap_io import recording_entries
from zswarm.report import fault_costs as faults
from zswarm.report import table as text
from zswarm.report.base import THRESHOLDS
from zswarm.report.decoded import Recording, errors, load_recording, truth_gaps
from zswarm.report.series import final
from zswarm.scenario import Scenario
from zswarm.util import files


def final_mean(rows: np.ndarray, t_end: float, col: int, window: float = 1.0) -> float:
    """The mean of column ``col`` of an agent's error rows over the last ``window`` of the run."""
    return final(rows[:, 0], rows[:, col], t_end, window)


# A run that cannot keep up is flagged (summary.json "overload", a line under the
# table) when an agent missed more than this share of its ticks or the world
# skipped more than this share of its samples.  Each agent's steps end at its
# newest measurement and a late tick catches up on the sensor history, so a few
# missed ticks cost nothing measurable (§3.2 filtered: 0–0.2 % missed on a quiet
# machine, 0.1–0.6 % with one core busy, final errors within 2 % of sim); what
# grows with load is the age of every message.  The issue measured 6–12 % missed
# and errors a thousand times sim's with one core busy before those fixes.  2 %
# is its "a few %", clear of the figures of a run that keeps up.
OVERLOAD_PCT = 2.0


def overload(
    agents: Mapping[str, Mapping[str, Any]],
    world: Mapping[str, Any],
    threshold_pct: float = OVERLOAD_PCT,
    watch_idle: Collection[str] = (),
    links: Mapping[str, Mapping[str, Any]] | None = None,
    sensor_period_s: float | None = None,
) -> dict[str, Any]:
    """Did the run keep up?  Per agent the share of its scheduled ticks that it missed
    (missed / (ticks run + missed)), the world's share of skipped samples, in %, and
    why it is flagged (no reasons: it kept up).

    ``watch_idle``: the agents whose idle ticks (no sensor packet newer than the last step)
    can only mean sensor packets that came late (:func:`idle_means_late`).  Their share of idle
    ticks is reported (``agents_idle_pct``) and, over the threshold, named in ``late`` (not a
    reason the run is overloaded).  On a machine short of CPU the agents keep their schedule
    while the world's packets queue behind them: the CI run of 2026-12-06 had agent 1 of §3.2
    at 94.8 Hz (5 % of its ticks idle), 0 missed ticks, and nothing said why.  Such a run
    publishes at less than its rate, but its agents catch up on every packet at the next tick
    (steps end at measurements), so its errors are still the algorithm's: quiet runs with 0.5-3 %
    of idle ticks end within 2 % of sim's errors (2026-12-06).

    Where the lateness came from is measured, and named with it (``late_evidence``): the world's
    own samples taken more than one sensor period after they were due (``taken_late``, the
    real-time loop's lateness on a machine short of CPU) and the sensor packets' latency
    (``links``: arrival at the agent minus the sample's time, so the world's lateness, the
    router's and the agent's Zenoh thread's together).  A tick is idle only when the packets due
    in its window all came more than a sensor period late, so idle ticks over the threshold
    (over 2 % of ticks, thus over 1 % of the packets at two packets a tick) need the 99th
    percentile latency of that agent's packets over one sensor period: ``late_explained``.
    Measured 2026-12-07 on §3.2 with a core kept busy and the machine's other core loaded: the
    world took 3.0 % of its samples late (worst 43 ms), the packets' p99 latency 25-112 ms
    against p50 2 ms, and the agents found no packet at 4.6-7.6 % of their ticks, with 0.2-2.7 %
    missed: the packets queue behind processes the machine does not run in time."""
    missed: dict[str, float] = {}
    idle: dict[str, float] = {}
    for i, a in agents.items():
        m = int(a.get("missed_deadlines", 0))
        n_idle = int(a.get("idle_ticks", 0))
        ran = int(a.get("steps", 0)) + n_idle
        missed[i] = round(100.0 * m / (ran + m), 3) if ran + m > 0 else 0.0
        if i in watch_idle:
            idle[i] = round(100.0 * n_idle / (ran + m), 3) if ran + m > 0 else 0.0
    reasons: list[str] = []
    over = [i for i, pct in missed.items() if pct > threshold_pct]
    if over:
        worst = max(over, key=lambda i: missed[i])
        reasons.append(f"{len(over)} of {len(missed)} agents missed more than {threshold_pct:g} % of their ticks (worst: agent {worst}, {missed[worst]:.1f} %)")
    late: list[str] = []
    samples, late_samples = int(world.get("samples", 0)), int(world.get("late", 0))
    taken_late_pct = round(100.0 * int(world.get("taken_late", 0)) / samples, 3) if samples else 0.0
    evidence: dict[str, Any] = {"world_taken_late_pct": taken_late_pct, "world_max_lateness_ms": round(1e3 * float(world.get("max_lateness_s", 0.0)), 3)}
    starved = [i for i, pct in idle.items() if pct > threshold_pct]
    explained = True
    if starved:
        worst = max(starved, key=lambda i: idle[i])
        p99 = {i: (links or {}).get(f"world->{i}", {}).get("latency_p99_ms") for i in starved}
        evidence["sensor_latency_p99_ms"] = p99
        period_ms = 1e3 * sensor_period_s if sensor_period_s else None
        explained = period_ms is not None and all(v is not None and v > period_ms for v in p99.values())
        lat = [v for v in p99.values() if v is not None]
        late.append(
            f"{len(starved)} of {len(missed)} agents found no new sensor packet at more than {threshold_pct:g} % of their ticks "
            f"(worst: agent {worst}, {idle[worst]:.1f} %): the world took {taken_late_pct:g} % of its samples more than a sensor period late "
            f"(worst {evidence['world_max_lateness_ms']:.0f} ms)"
            + (f" and the sensor packets' 99th percentile latency reached {max(lat):.0f} ms" if lat else "")
            + ("" if explained else ", which does not account for these idle ticks")
        )
    world_pct = 100.0 * late_samples / (samples + late_samples) if samples + late_samples > 0 else 0.0
    if world_pct > threshold_pct:
        reasons.append(f"the world skipped {world_pct:.1f} % of its samples")
    return {
        "overloaded": bool(reasons),
        "threshold_pct": threshold_pct,
        "agents_missed_pct": missed,
        "agents_idle_pct": idle,
        "world_skipped_pct": round(world_pct, 3),
        "reasons": reasons,
        "late": late,
        "late_explained": explained,
        "late_evidence": evidence,
    }


def idle_means_late(sc: Scenario) -> list[str]:
    """The agents of ``sc`` for which a tick without a new sensor packet means the packets came
    late: no fault in the run, a lossless undelayed sensor link, a tick schedule without jitter,
    and at least two sensor samples per tick (so the newest packet at a tick is at most one
    sample period, half a tick, older than the tick when it arrives in time)."""
    if sc.faults:
        return []
    return [
        str(a.id)
        for a in sc.agents
        if a.clock.jitter == 0 and sc.sensor_rate >= 2 * a.clock.rate and not sc.link_spec(f"world->{a.id}").active
    ]


def world_ran_to_end(world: Mapping[str, Any], exit_codes: Mapping[str, int | None] | None) -> bool:
    """Whether the world published until the run's end: its final stats are recorded and it
    exited 0 where its exit status is known.  Only then can an agent's tick without a new
    sensor packet mean a late packet (:func:`idle_means_late`): after a world's death every
    tick is one (a §3.3 run whose world was SIGKILLed at 2 s of 8 read "the world's packets
    came late", 66.7 % of agent 1's ticks)."""
    return bool(world.get("final")) and (exit_codes or {}).get("world", 0) == 0


def summarize(
    sc: Scenario,
    rec: Recording,
    errs: dict[int, np.ndarray],
    engine: str,
    duration: float,
    time_scale: float,
    seed: int,
    exit_codes: dict[str, int | None] | None = None,
    m: Any = None,
    thresholds: tuple[float, float] = THRESHOLDS,
    not_recorded: Sequence[str] = (),
) -> dict[str, Any]:
    """The summary.json content (see README, "Results folder"); ``m``: the family's metrics
    of this recording (``family.of(sc).metrics(sc, rec)``, as :func:`make_report` computes
    them once; None is a family's "no metrics", e.g. §4 with an agent that sent nothing)."""
    t_end = duration
    agents: dict[str, Any] = {}
    links: dict[str, dict[str, Any]] = {}
    # What each link's sender sent, over every incarnation of it (a process restarted counts
    # from 0 again; its receivers' counts span both): the sum, and per incarnation when more
    # than one sent on the link.  From the newest stats alone, a restarted agent's link read
    # "sent 2228, delivered 3312".
    sent: dict[str, int] = {}
    by_inc: dict[str, dict[int, int]] = defaultdict(dict)
    # A sender whose every incarnation sent its final stats (a clean exit) counted all it sent;
    # one killed (a SIGKILL, a kill fault) counted up to its last stats, up to a second before
    # its death: its "sent" is a lower bound (a restarted agent's link read 3444 delivered of
    # 3349 sent).
    whole: dict[tuple[str, int], bool] = {}
    # What each link's receiver counted, per incarnation of it: a restarted receiver counts from
    # 0 again, so the newest stats alone held its newest process's share (a §3.3 run with agent 3
    # killed at 2 s and restarted at 3 s of 7 read link 1->3 as 339 delivered of 698 sent, 0
    # dropped).  The counts are summed; the latency percentiles are the newest process's.
    received: dict[str, dict[int, Mapping[str, Any]]] = defaultdict(dict)
    for (role, src, inc), st in (rec.stats_by_inc or {(r, i, 0): st for (r, i), st in rec.stats.items()}).items():
        whole[(role, src)] = whole.get((role, src), True) and bool(st.get("final"))
        for link, n in st.get("sent", {}).items():
            by_inc[link][inc] = int(n)
        for link, c in st.get("links", {}).items():
            received[link][inc] = c
    for link, incs in by_inc.items():
        sent[link] = sum(incs.values())
    for a in sc.agents:
        st = rec.stats.get(("agent", a.id), {})
        rows = errs.get(a.id, np.zeros((0, 4)))
        # Alive at the end: from its exit status where the launcher knew it (an agent that
        # exited 0 finished, whether or not a dead recorder got its final stats), else from
        # its final counters being recorded (which a killed process never sends).
        fate = _fate(bool(st.get("final")), exit_codes, newest_process(exit_codes, f"agent-{a.id}"))
        alive = fate.startswith("finished") if fate is not None else bool(st.get("final"))
        agents[str(a.id)] = {
            "role": a.role,
            "alive_at_end": alive,
            "attitude_error_final": final_mean(rows, t_end, 1),
            "position_error_final": final_mean(rows, t_end, 2),
            "position_error_direct_final": final_mean(rows, t_end, 3),
            "last_estimate_t": float(rows[-1, 0]) if len(rows) else None,
            "steps": int(st.get("steps", 0)),
            "step_rate_hz": float(st.get("step_rate_hz", 0.0)),
            "configured_rate_hz": a.clock.rate,
            "missed_deadlines": int(st.get("missed_deadlines", 0)),
            "idle_ticks": int(st.get("idle_ticks", 0)),
            "catch_up_steps": int(st.get("catch_up_steps", 0)),
            "compute_mean_us": float(st.get("compute_mean_us", 0.0)),
            "malformed_received": int(st.get("malformed", 0)),
            "step_failures": int(st.get("step_failures", 0)),
            "inbox_overflow": int(st.get("inbox_overflow", 0)),
            "stale_terms": int(sum(st.get("stale_terms", {}).values())),
        }
        if fate is not None:
            agents[str(a.id)]["fate"] = fate
        if "parts" in st:  # each part's achieved rate on the agent's clock
            agents[str(a.id)]["parts"] = st["parts"]
        for link, c in st.get("links", {}).items():
            links[link] = {"sent": sent.get(link, 0), **c, **_received_over_incarnations(received.get(link, {}))}
            if not whole.get(("agent", a.id), False):  # said only where it holds, as sent_is_lower_bound
                links[link]["delivered_is_lower_bound"] = True
    world = rec.stats.get(("world", 0), {})
    for link, c in world.get("links", {}).items():  # the command links i->world, counted at the world
        links[link] = {"sent": sent.get(link, 0), **c, **_received_over_incarnations(received.get(link, {}))}
        if not whole.get(("world", 0), False):
            links[link]["delivered_is_lower_bound"] = True
    for link, n in sent.items():
        links.setdefault(link, {"sent": n, "delivered": 0, "dropped": n, "reordered": 0})
        if len(by_inc[link]) > 1:
            links[link]["sent_by_incarnation"] = {str(i): k for i, k in sorted(by_inc[link].items())}
    for link, c in links.items():
        src = link.split("->")[0]
        sender = ("world", 0) if src == "world" else ("agent", int(src)) if src.isdigit() else None
        if sender is None or not whole.get(sender, False):  # said only where it holds, as sent_by_incarnation
            c["sent_is_lower_bound"] = True
    fam = family.of(sc)
    extra = fam.summary(sc, rec, m, agents, duration)
    recording = recording_section(sc, rec, duration, not_recorded)
    problems = run_problems(sc, rec, agents, recording, duration, exit_codes)
    return extra | {
        "scenario": sc.name,
        "algorithm": sc.algorithm,
        "report_family": fam.name,
        "engine": engine,
        "duration_s": duration,
        "time_scale": time_scale,
        "seed": seed,
        "completed": not problems,
        "problems": problems,
        "agents": agents,
        "links": dict(sorted(links.items())),
        **fam.headline(sc, agents, extra),
        "final_window_s": 1.0,
        "convergence": fam.convergence(sc, errs, m, duration, thresholds),
        "stale_policy": {"policy": sc.stale.policy, "max_age_s": sc.stale.max_age},
        "world": world,
        "overload": overload(
            agents, world, watch_idle=idle_means_late(sc) if world_ran_to_end(world, exit_codes) else (), links=links, sensor_period_s=1.0 / sc.sensor_rate
        ),
        "recorded_messages": rec.counts,
        "recording": recording,
        "malformed_in_recording": rec.malformed,
    } | ({"warnings": list(sc.warnings) + extra.get("warnings", [])} if sc.warnings or extra.get("warnings") else {})


def _received_over_incarnations(by_inc: Mapping[int, Mapping[str, Any]]) -> dict[str, Any]:
    """A link's receiver counts summed over the receiver's incarnations (each counted from 0),
    and per incarnation when there was more than one; nothing when there was one."""
    if len(by_inc) < 2:
        return {}
    keys = ("delivered", "dropped", "reordered")
    out: dict[str, Any] = {k: sum(int(c.get(k, 0)) for c in by_inc.values()) for k in keys}
    out["delivered_by_incarnation"] = {str(i): int(c.get("delivered", 0)) for i, c in sorted(by_inc.items())}
    return out


def newest_process(exit_codes: Mapping[str, int | None] | None, name: str) -> str:
    """The launcher's name of the newest process of ``name`` (``agent-3``): ``name`` itself while
    it runs to the end, else the killed one of the highest number (``agent-3~killed2``: the
    launcher renames a process a ``kill`` fault ends, zswarm/engines/launch.py FaultRunner)."""
    if exit_codes is None or name in exit_codes:
        return name
    killed = [(int(k.rsplit("~killed", 1)[1]), k) for k in exit_codes if k.startswith(f"{name}~killed") and k.rsplit("~killed", 1)[1].isdigit()]
    return max(killed)[1] if killed else name


def _fate(final: bool, exit_codes: Mapping[str, int | None] | None, name: str) -> str | None:
    """How a process ended, from its exit status (known to the launcher; None without it)."""
    if exit_codes is None or name not in exit_codes:
        return None
    code = exit_codes[name]
    if code == 0:
        return "finished" if final else "finished; final stats not recorded"
    if code is None:
        return "did not exit (killed at the end)"
    return f"killed by signal {-code}" if code < 0 else f"exited with {code}"


ROUTER_RECONNECT_S = 3.0  # a router fault's hole may last this long past its end (reconnection, catching up)

# An agent that failed more than this share of its steps did not run the algorithm: the run
# is not completed (gains of 1e12 failed 271 of 301 steps and the run read as completed).
MAX_FAILED_STEPS_SHARE = 0.5


def run_problems(
    sc: Scenario, rec: Recording, agents: Mapping[str, Mapping[str, Any]], recording: Mapping[str, Any], duration: float, exit_codes: Mapping[str, int | None] | None
) -> list[str]:
    """Why the run is not ``completed`` (summary.json ``problems``; empty: completed): a
    damaged recording file, the world's stop missing from the recording, a recording that
    ends short of the run or has a hole in its middle, the world or the recorder not exiting
    cleanly, an agent that failed most of its steps."""
    out = [f"the recording is damaged: {x}" for x in rec.lost]
    if not rec.stop_seen:
        out.append("the world's stop is not in the recording (the run was stopped early, or its recording was cut)")
    if recording.get("cut_short"):
        out.append(f"the recording ends at t = {recording['ends_at_s']:.2f} s of {duration:g}")
    # A hole in the middle (a recorder stopped or starved for a while, a damaged chunk) loses
    # data as an end cut short does: the truth, estimates and edges of that span are not there.
    gaps = recording.get("truth_gaps") or {}
    # The router down on purpose (a ``router`` fault) leaves a hole of its own, the scenario's:
    # not a problem of the run (the clients reconnect within ~0.5-1.5 s of its return).
    planned = [(f.at - 0.1, f.end + ROUTER_RECONNECT_S) for f in sc.faults if f.kind == "router"]
    holes = [
        (a, b) for a, b in gaps.get("spans", []) if not (recording.get("cut_short") and b >= duration) and not any(lo <= a and b <= hi for lo, hi in planned)
    ]
    if holes:
        spans = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in holes[:3]) + (" ..." if len(holes) > 3 else "")
        short = {k: v for k, v in sorted((recording.get("missing") or {}).items(), key=lambda kv: -kv[1])[:3]}
        what = f"; {recording.get('missing_total', 0)} messages missing (most: " + ", ".join(f"{k} {v}" for k, v in short.items()) + ")" if short else ""
        out.append(f"the recording has {len(holes)} hole{'s' if len(holes) > 1 else ''} (no truth for longer than {gaps.get('bound_s')} s): {spans}{what}")
    for name in ("world", "recorder"):
        code = (exit_codes or {}).get(name, 0)
        if code != 0:
            out.append(f"the {name} exited with {code}" if code is not None else f"the {name} did not exit")
    for i, a in agents.items():
        tried = a["steps"] + a["step_failures"]  # "steps" counts the ones that succeeded
        if a["step_failures"] > MAX_FAILED_STEPS_SHARE * tried:
            out.append(f"agent {i} failed {a['step_failures']} of its {tried} steps")
    return out


def recording_section(sc: Scenario, rec: Recording, duration: float, not_recorded: Sequence[str] = ()) -> dict[str, Any]:
    """summary.json ``recording``: :func:`completeness`, where the truth has gaps (no error
    computed there), where the recording ends, and what was stamped outside the run."""
    out = completeness(sc, rec, not_recorded)
    gaps = truth_gaps(rec, duration)
    end = float(rec.truth_t[-1]) if len(rec.truth_t) else None
    out["truth_gaps"] = gaps
    out["ends_at_s"] = end
    # Cut short: the last truth sample is more than the gap bound before the run's end.
    # The processes' counts then stop where the recording stopped too: not exact.
    out["cut_short"] = bool(end is not None and gaps["bound_s"] is not None and duration - end > gaps["bound_s"])
    if out["cut_short"]:
        # Counted against the processes' last recorded stats (once a second), so "missing" and
        # "surplus" cover the time before the end only: past it, everything is missing.
        out["exact"] = False
        out["missing_after_s"] = end
    out["outside_run"] = dict(rec.outside_run)
    out["damaged"] = list(rec.lost)
    return out


def completeness(sc: Scenario, rec: Recording, not_recorded: Sequence[str] = ()) -> dict[str, Any]:
    """What the recording lacks of what the processes published, per channel.

    Each process counts what it publishes and says so in its stats: the world
    its samples (one ``truth`` and one ``sense/<i>`` each), an agent its steps
    (one ``est/<i>`` each) and its messages per out-edge and to the world, and
    every process its stats messages (their sequence numbers).  The final
    stats, sent on a clean exit, make the count exact; a process that did not
    exit cleanly leaves a lower bound (``exact``: false).  Channels in
    ``not_recorded`` (a lean recording) are left out on purpose.
    """
    expected: dict[str, int] = {}
    exact = True
    world = rec.stats.get(("world", 0))
    if world is None:
        exact = False
    else:
        exact = exact and bool(world.get("final"))
        expected["truth"] = int(world.get("samples", 0))
        for link, n in world.get("sent", {}).items():
            expected[f"sense/{link.split('->')[1]}"] = int(n)
    for a in sc.agents:
        # Every incarnation of the agent (a restarted one starts its counts again): the sum.
        incs = [st for (r, i, _), st in rec.stats_by_inc.items() if r == "agent" and i == a.id] or ([rec.stats[("agent", a.id)]] if ("agent", a.id) in rec.stats else [])
        if not incs:
            exact = False
            continue
        exact = exact and all(bool(st.get("final")) for st in incs)
        expected[f"est/{a.id}"] = sum(int(st.get("steps", 0)) for st in incs)
        for st in incs:
            for link, n in st.get("sent", {}).items():
                src, dst = link.split("->")
                k = f"cmd/{src}" if dst == "world" else f"edge/{src}/{dst}"
                expected[k] = expected.get(k, 0) + int(n)
    for (role, src, _inc), st in rec.stats_by_inc.items() or {(r, s, 0): st for (r, s), st in rec.stats.items()}.items():
        k = f"stats/{role}/{src}"
        expected[k] = expected.get(k, 0) + int(st.get("seq", -1)) + 1
    left_out = {p.rstrip("/") for p in not_recorded}  # channel kinds: "sense", "edge", "cmd"
    expected = {k: v for k, v in expected.items() if k.split("/", 1)[0] not in left_out}
    missing = {k: n - rec.streams.get(k, 0) for k, n in sorted(expected.items()) if n > rec.streams.get(k, 0)}
    surplus = {k: rec.streams.get(k, 0) - n for k, n in sorted(expected.items()) if rec.streams.get(k, 0) > n}
    return {
        "published": sum(expected.values()),
        "recorded": sum(min(rec.streams.get(k, 0), n) for k, n in expected.items()),
        "missing_total": sum(missing.values()),
        "missing": missing,
        "surplus": surplus,
        "exact": exact,
        "not_recorded": list(not_recorded),
    }


def write_errors_csv(path: Path, errs: dict[int, np.ndarray]) -> None:
    """``t, agent, attitude_error`` (|R̃_i|_I), ``position_error`` (‖p̃_i‖, the thesis'),
    ``position_error_direct`` (‖p_i − p̂_i‖)."""
    rows = [(t, i, ea, ep, ed) for i, e in errs.items() for t, ea, ep, ed in e]
    rows.sort()
    with files.whole(path) as tmp, open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "agent", "attitude_error", "position_error", "position_error_direct"])
        for t, i, ea, ep, ed in rows:
            w.writerow([f"{t:.6f}", i, f"{ea:.6e}", f"{ep:.6e}", f"{ed:.6e}"])


class ReportParts(NamedTuple):
    """What :func:`make_report` read and computed on the way to the summary."""

    summary: dict[str, Any]
    rec: Recording
    errors: dict[int, np.ndarray]
    metrics: Any  # the family's (family.metrics)


def make_report_parts(
    out_dir: Path,
    sc: Scenario,
    engine: str,
    duration: float | None,
    time_scale: float | None,
    seed: int | None,
    exit_codes: dict[str, int | None] | None = None,
    plots: bool = True,
    thresholds: tuple[float, float] = THRESHOLDS,
    messages: Iterable[tuple[str, bytes, int]] | None = None,
    not_recorded: Sequence[str] = (),
    keep: Mapping[str, Any] | None = None,
) -> ReportParts:
    """Read ``out_dir/recording.mcap`` (or ``messages``, an in-memory recording);
    write errors.csv, summary.json, the family's CSVs and the plots; return the summary with
    the recording, errors and metrics it was computed from (zswarm study takes its series
    from them instead of reading the run again).  ``not_recorded``: channel prefixes the
    recorder left out on purpose (``sense``, ``edge``, ``cmd``: lean).  ``keep``: entries of an
    earlier summary.json that only the launcher knew (``zswarm report`` keeps them)."""
    entries = recording_entries(out_dir, sc) if messages is None else messages
    try:
        rec = load_recording(entries, envelopes=bool(sc.faults), duration=duration, source=str(out_dir / "recording.mcap"))
    except Exception:
        if isinstance(entries, Generator):  # the transcode's pass (mcap_io.transcoded): recording.mcap written all the same
            with contextlib.suppress(Exception):  # the report's error is the one to tell
                collections.deque(entries, maxlen=0)
        raise
    finally:
        if isinstance(entries, Generator):
            entries.close()  # after a KeyboardInterrupt: the partial copy removed now, the raw file kept
    known = duration is not None
    if duration is None:
        # Not known (zswarm report of a folder that does not tell it): the recording's last truth
        # sample is taken as the run's end for the errors and measures, and summary.json says
        # null (the scenario's duration, used before, was a guess: 40 s for a run of 3).
        duration = float(rec.truth_t[-1])
    errs = errors(rec)
    fam = family.of(sc)
    m = fam.metrics(sc, rec)
    summary = summarize(sc, rec, errs, engine, duration, time_scale, seed, exit_codes, m, thresholds, not_recorded)
    if sc.faults:
        t_grid, att, _pos = fam.series(sc, errs, m, duration)
        summary["faults"] = faults.summary(sc, rec, engine, t_grid, att, summary["convergence"]["measure"] + " (attitude)")
    if not known:
        summary["duration_s"] = None
    summary.update(keep or {})
    write_errors_csv(out_dir / "errors.csv", errs)
    fam.write(out_dir, sc, rec, m)
    write_summary(out_dir / "summary.json", summary)
    if (out_dir / "recording.mcap").exists():  # the Foxglove layout of its channels beside it
        extent = max((math.hypot(*a.p) for a in sc.agents), default=1.0)
        write_layout(out_dir / "recording.mcap", out_dir / "foxglove-layout.json", extent, sc.name)
    if plots:
        fam.plot(out_dir / "plots", sc, errs, m, rec)
    return ReportParts(summary, rec, errs, m)


def make_report(*args: Any, **kwargs: Any) -> dict[str, Any]:
    """:func:`make_report_parts`' summary (the same arguments)."""
    return make_report_parts(*args, **kwargs).summary


def strict_json(obj: Any) -> Any:
    """``obj`` with every non-finite float as None: summary.json is strict JSON (a literal
    NaN, which Python's json writes by default, is not JSON and other readers reject it)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: strict_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict_json(v) for v in obj]
    if isinstance(obj, np.generic):
        return strict_json(obj.item())
    return obj


def write_summary(path: Path, summary: Mapping[str, Any]) -> None:
    """Write ``summary`` to ``path`` as strict JSON, whole or not at all: into a temporary file
    beside it, then renamed over it (a full disk left a 0-byte summary.json).  OSError
    (disk full, read-only folder) is the caller's to report."""
    files.write_text(path, json.dumps(strict_json(summary), indent=2, allow_nan=False) + "\n")


def table(summary: dict[str, Any]) -> str:
    """The summary table printed at the end of a run: its title, its family's lines, the footer."""
    # (a summary.json older than report_family: the defaults every family falls back on)
    fam = family.resolve(summary["report_family"]) if "report_family" in summary else family.Family()
    return "\n".join([text.title(summary), *fam.table_lines(summary), *text.footer_lines(summary)])
