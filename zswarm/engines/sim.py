"""``zswarm sim``: the very same World and AgentNode objects in one process.

A MemoryBus and a virtual clock: events (sensor samples, agent ticks) are
processed in time order, ties broken world first then by agent id, so a seed
gives bit-identical results.  Runs as fast as the CPU allows.
"""

from __future__ import annotations

import argparse
import heapq
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path

from zswarm.recording.capture import Recorder
from zswarm.scenario import Scenario, fault_actions
from zswarm.scenario.programs import agent_program, world_program
from zswarm.transport import keys, procutil, run_control
from zswarm.transport.bus import MemoryBus
from zswarm.util import files, plugins
from zswarm.util.files import RecordingError
from zswarm.util.progress import Progress

LEAN_SKIP = ("sense/", "edge/", "cmd/")
# Messages the recorder of a sim holds to write the viewer file after the run (Recorder's
# defer): 2e5 is §3.2's 8 agents for 40 s (≈ 4800 messages per world second), ~0.2 GB held.
# A longer run writes as it goes from there, as before.
DEFER_MESSAGES = 400_000


def fault_events(scenario: Scenario, kill: dict[int, float] | None = None) -> list[tuple[float, int, str, int]]:
    """The scenario's faults as ``sim`` carries them out, in time order: ``(t, order, action,
    agent)``.  A router fault has no meaning in one process (no router): left out (the
    report says so); a cut is the link emulation's (zswarm/scenario/links.py)."""
    ev = [(t, n, action, f.agent) for t, n, action, f in fault_actions(scenario.faults) if f.agent is not None]
    for i, tk in (kill or {}).items():
        ev.append((tk, -1, "legacy_kill", i))
    return sorted(ev)


def simulate(
    scenario: Scenario,
    out_dir: Path,
    duration: float,
    seed: int,
    run: str = "sim",
    progress: Callable[[float], None] | None = None,
    kill: dict[int, float] | None = None,
    lean: bool = False,
    record: bool = True,
    objects: bool = True,
    keep: list[tuple[str, bytes, int]] | None = None,
    times: dict[str, float] | None = None,
    rerun: str | None = None,
    stop: threading.Event | None = None,
) -> Path | list[tuple[str, bytes, int]]:
    """Run ``scenario`` for ``duration`` s of world time; return the recording path.

    ``kill`` maps agent ids to world times at which that agent stops (as if
    its process died): its token is withdrawn and it never ticks again.
    ``lean`` leaves the sensor and edge messages out of the recording (a
    quarter of the size; the report needs only truth, estimates and stats).
    ``record=False`` writes no file and returns the recorded messages
    (``(channel, payload, log_time_ns)``, what :func:`zswarm.recording.mcap_io.read` yields).
    ``objects``: the processes hand each other validated messages (``wire.Message``), as
    DESIGN.md's in-process engine does; False: bytes every receiver decodes, as over
    Zenoh (the same results, bit for bit: tests/component/test_sim_objects.py).
    ``keep`` (with ``record``): filled with the recorded messages when the recorder held
    them all to write the file after the run (up to DEFER_MESSAGES), so that the report
    need not read the file back; left empty otherwise.  ``times``: filled with the wall
    time of the run (``run_s``) and of writing the recording after it (``record_s``).
    ``rerun``: stream the run to the Rerun viewer at that URL as it is simulated.
    ``stop``: once set (looked at every second of world time), what was simulated is written
    and KeyboardInterrupt raised, as Ctrl-C does by itself.
    """
    t_start = time.perf_counter()
    bus = MemoryBus(objects=objects)
    t_now = [0.0]
    rec_path = out_dir / "recording.mcap"
    # Written under a temporary name and renamed once closed whole: a full disk left the file
    # cut at the disk's end under its final name (not one message readable), for a report or
    # a viewer to take as the run's recording.
    part = rec_path.with_name(rec_path.name + ".part")
    if rerun is not None:
        from zswarm.recording import rerun_view
    recorder = Recorder(
        bus,
        run,
        part if record else None,
        now_ns=lambda: int(round(t_now[0] * 1e9)),
        # What the run was, where a remade summary finds it even when the start message is lost
        # (zswarm report; the metadata is written before the first chunk).
        metadata={"engine": "sim", "scenario": scenario.name, "duration": repr(float(duration)), "seed": str(seed), "time_scale": "0.0"},
        skip=LEAN_SKIP if lean else (),
        scenario=scenario,
        defer=DEFER_MESSAGES if record else 0,
        rerun=None if rerun is None else rerun_view.live(scenario, run, rerun),
    )
    World, AgentNode = plugins.process_class("world"), plugins.process_class("agent")  # noqa: N806 - classes
    world = World(world_program(scenario, seed), bus, run, now=lambda: t_now[0])
    # Each agent on a session of its own: a kill closes it (its subscriptions and token go,
    # as with a killed process's Zenoh session); a restart is a new session and node.
    sessions = {i: bus.session() for i in scenario.ids}
    programs = {i: agent_program(scenario, i, seed) for i in scenario.ids}  # a restart runs the same program
    agents = {i: AgentNode(programs[i], sessions[i], run, now=lambda: t_now[0]) for i in scenario.ids}
    ctl_start = bus.publisher(keys.ctl(run, "start"))
    ctl_stop = bus.publisher(keys.ctl(run, "stop"))
    bus.declare_token(keys.alive(run, "world", 0))
    for i in agents:
        sessions[i].declare_token(keys.alive(run, "agent", i))
    ctl_start.put(run_control.encode_ctl("start", 0, 0, 0.0, epoch=0.0, time_scale=0.0, duration=duration, seed=seed, run=run))

    # (time, priority, id, generation): world samples have priority 0, agent ticks 1; a
    # restarted agent's ticks carry its new generation (its old ones are dropped).
    queue: list[tuple[float, int, int, int]] = [(world.next_time(), 0, 0, 0)]
    gen = dict.fromkeys(agents, 0)
    for i, a in agents.items():
        queue.append((a.clock.first_tick(0.0), 1, i, 0))
    heapq.heapify(queue)
    events = fault_events(scenario, kill)
    stopped: dict[int, float] = {}  # agent -> world time of its SIGCONT
    next_flush = 1.0
    next_stats = {i: 1.0 for i in agents}
    try:
        while queue:
            t, prio, who, g = heapq.heappop(queue)
            if t > duration + 1e-9:
                break
            while events and events[0][0] <= t:
                te, _, action, i = events.pop(0)
                t_now[0] = te
                if action in ("kill", "legacy_kill") and i in agents:
                    sessions[i].close()
                    if action == "legacy_kill":
                        agents[i].publish_stats(te)  # kill=: a last word (a fault's SIGKILL has none)
                    del agents[i]
                    stopped.pop(i, None)
                elif action == "restart":
                    gen[i] += 1
                    sessions[i] = bus.session()
                    a = agents[i] = AgentNode(programs[i], sessions[i], run, now=lambda: t_now[0], inc=gen[i])
                    sessions[i].declare_token(keys.alive(run, "agent", i))
                    heapq.heappush(queue, (a.clock.first_tick(te), 1, i, gen[i]))
                    next_stats[i] = te + 1.0
                elif action == "stop":
                    stopped[i] = te
                elif action == "cont":
                    stopped.pop(i, None)
            t_now[0] = t
            if prio == 0:
                world.sample()
                if world.k % max(1, round(scenario.sensor_rate)) == 0:
                    world.publish_stats(t)
                heapq.heappush(queue, (world.next_time(), 0, 0, 0))
            elif who in agents and g == gen[who]:
                a = agents[who]
                if who in stopped:
                    # SIGSTOPped: nothing runs; arrivals wait in its inbox.  The tick is taken at
                    # the SIGCONT, late, and catches up as a late tick of a real process does.
                    cont = next(te for te, _, act, j in events if act == "cont" and j == who)
                    a.missed += max(0, int((cont - t) * a.program.clock.rate))
                    heapq.heappush(queue, (cont, 1, who, g))
                    continue
                a.tick(t)
                if t >= next_stats[who]:
                    a.publish_stats(t)
                    next_stats[who] += 1.0
                tn, missed = a.clock.next_tick(t)
                a.missed += missed
                heapq.heappush(queue, (tn, 1, who, g))
            if t >= next_flush:
                recorder.flush()
                next_flush += 1.0
                if progress:
                    progress(t)
                if stop is not None and stop.is_set():
                    raise KeyboardInterrupt
    except BaseException as exc:
        # Ctrl-C (KeyboardInterrupt) or a failure: what was simulated up to here is written
        # (the recorder holds it until close), then the exception goes on; a recording that
        # could not be written (a full disk) is removed instead.
        if isinstance(exc, RecordingError):
            raise _not_written(exc, part, rec_path) from None
        _close_whole(recorder, part, rec_path)
        raise

    t_now[0] = duration
    ctl_stop.put(run_control.encode_ctl("stop", 0, 0, duration, reason="duration"))
    world.publish_stats(duration, final=True)
    for a in agents.values():
        a.publish_stats(duration, final=True)
    bus.declare_token(keys.alive(run, "recorder", 0))
    t_run = time.perf_counter()
    _close_whole(recorder, part, rec_path)
    bus.close()
    if keep is not None and record and recorder.complete:
        keep.extend(recorder.messages)
    if times is not None:
        times.update(run_s=t_run - t_start, record_s=time.perf_counter() - t_run)
    return rec_path if record else recorder.messages


def _close_whole(recorder: Recorder, part: Path, path: Path) -> None:
    """Close ``recorder`` (writing what it holds into ``part``) and rename ``part`` to ``path``;
    if the writing fails, ``part`` is removed and the error goes on (RecordingError, naming it)."""
    try:
        recorder.close()
    except RecordingError as exc:
        raise _not_written(exc, part, path) from None
    except BaseException:
        part.unlink(missing_ok=True)
        raise
    if part.exists():
        os.replace(part, path)


def _not_written(exc: RecordingError, part: Path, path: Path) -> RecordingError:
    """``part`` removed; the error told of ``path``, the file the user asked for."""
    part.unlink(missing_ok=True)
    return RecordingError(f"{str(exc).replace(str(part), str(path), 1)} (nothing of it is kept)")


# --------------------------------------------------------------------------- the command (zswarm.cli dispatches here)


def command(args: argparse.Namespace) -> int:

    from zswarm import results
    from zswarm.engines.launch import results_dir
    from zswarm.engines.sim import LEAN_SKIP, simulate

    from zswarm.engines import cost

    sc = procutil.load_args(args)
    cost.refuse_if_too_long(sc, args.topology, args.duration, args.allow_long)  # before anything is printed or made
    procutil.warn_notes(sc)
    duration = sc.duration if args.duration is None else args.duration
    procutil.check_faults_in_run(sc, duration, args.duration is not None)
    seed = sc.seed if args.seed is None else args.seed
    out = results_dir(args.out, sc.name)
    files.write_text(out / "scenario.toml", sc.text)  # whole or not at all
    bar = Progress(duration, "s of world time")

    def progress(t: float) -> None:
        bar.update(t)

    t0 = time.perf_counter()
    kept: list[tuple[str, bytes, int]] = []
    times: dict[str, float] = {}
    # Ctrl-C and SIGTERM set an event the loop looks at, rather than Ctrl-C's KeyboardInterrupt
    # landing wherever the main thread is: on CI (2026-12-07) a sim SIGINTed 1 s after its start
    # ran on for 60 s until SIGKILLed (the interrupt taken inside a library, it seems, and lost).
    stop = procutil.stop_on_signals()
    try:
        recorded = simulate(sc, out, duration, seed, progress=None if args.quiet else progress, lean=args.lean, record=not args.no_recording, keep=kept, times=times, rerun=args.rerun, stop=stop)
    finally:
        bar.close()  # the next line (the table, or "interrupted") on its own
    wall = time.perf_counter() - t0
    messages = recorded if isinstance(recorded, list) else (kept or None)
    summary = results.make_report(out, sc, "sim", duration, 0.0, seed, plots=not args.no_plots, messages=messages, not_recorded=LEAN_SKIP if args.lean else ())
    summary["wall_time_s"] = wall
    summary["wall_time_run_s"] = times["run_s"]
    summary["wall_time_recording_s"] = times["record_s"]
    summary["wall_time_report_s"] = time.perf_counter() - t0 - wall
    results.write_summary(out / "summary.json", summary)
    if not args.quiet:
        print(results.table(summary))
        print(
            f"simulated {duration:g} s in {times['run_s']:.1f} s of wall time ({duration / max(times['run_s'], 1e-9):.1f}x real time), "
            f"then the recording in {times['record_s']:.1f} s and the report in {summary['wall_time_report_s']:.1f} s; results: {out}"
        )
    return 0 if summary["completed"] else 1
