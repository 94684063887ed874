"""``zswarm record``: the recorder as a process of its own — it subscribes to a run, writes the
raw recording (zswarm.recording.capture.Recorder), waits for the processes' final stats, transcodes,
and writes the report when the run has stopped."""

from __future__ import annotations

import argparse
import time

from zswarm.transport import keys, procutil

# The recorder gives back what a catch-up freed (procutil.trim_heap) every 30 s.  A trim took
# 20-80 ms here on a heap of 85 MiB churned, with the soak saturating both cores: <= 0.3 % of
# the recorder's time; meanwhile samples wait in the kernel's socket buffer and Zenoh's FIFO.
TRIM_EVERY_S = 30.0
FINAL_STATS_WAIT_S = 8.0  # the recorder's wait for the processes' final stats after the run's stop


def command(args: argparse.Namespace) -> int:
    from zswarm import results
    from zswarm.engines.launch import results_dir
    from zswarm.recording.capture import Recorder
    from zswarm.recording.mcap_io import RAW_SUFFIX
    from zswarm.transport import run_control, wire
    from zswarm.transport.bus import ZenohBus
    from zswarm.util import files

    sc = procutil.load_or_exit(args.topology)
    conf = procutil.zenoh_conf(args, "recorder")
    log = procutil.setup_logging("recorder")
    run = keys.check_run_id(args.run_id)
    out = results_dir(args.out, sc.name)
    if not (out / "scenario.toml").exists():
        files.write_text(out / "scenario.toml", sc.text)  # whole or not at all
    start: dict[str, object] = {}
    with ZenohBus(conf) as bus:
        stop = procutil.stop_on_signals()
        # Without a live view the recorder copies payloads as they come (recording.raw.mcap);
        # the report below (or zswarm report) transcodes them into recording.mcap.
        path = out / ("recording" + (RAW_SUFFIX if args.live is None else ".mcap"))
        if args.rerun is not None:
            from zswarm.recording import rerun_view
        rec = Recorder(bus, run, path, metadata={"engine": "run", "scenario": sc.name, "run": run}, scenario=sc, live=args.live, raw=args.live is None, rerun=None if args.rerun is None else rerun_view.live(sc, run, args.rerun))

        def on_start(key: str, payload: bytes) -> None:
            if not start:
                try:
                    start.update(run_control.decode_ctl(payload, "start"))
                except wire.MessageError:
                    pass

        bus.subscribe(keys.ctl(run, "start"), on_start)
        procutil.warm_up()
        bus.declare_token(keys.alive(run, "recorder", 0))
        log.info("recording run %r into %s", run, path)
        if args.live is not None:
            log.info("live view on ws://%s:%d (Foxglove or Lichtblick: open connection, Foxglove WebSocket)", args.live[0], rec.live_port)
        procs = [("world", 0), *(("agent", i) for i in sc.ids)]
        try:
            next_flush = time.monotonic() + 0.5
            next_trim = time.monotonic() + TRIM_EVERY_S
            while not stop.is_set() and not rec.stopped.is_set():
                stop.wait(0.01)
                rec.poll()
                if time.monotonic() >= next_flush:
                    rec.flush()
                    next_flush += 0.5
                if time.monotonic() >= next_trim:
                    procutil.trim_heap()  # what a catch-up freed goes back (procutil.trim_heap)
                    next_trim += TRIM_EVERY_S
            if rec.stopped.is_set() and not stop.is_set():
                # The run ended: wait for the final stats of every process still up.  A fixed
                # second was not always enough on a loaded machine (an agent behind its
                # schedule stops later), and a missed one reads as an agent that died.
                # Bounded: `zswarm run` kills a process that has not stopped 6 s after the world.
                end = time.monotonic() + FINAL_STATS_WAIT_S
                while not stop.is_set() and time.monotonic() < end and rec.awaiting_finals(procs):
                    stop.wait(0.01)
                    rec.poll()
                end = time.monotonic() + 0.2  # what is in flight from processes that went meanwhile
                while not stop.is_set() and time.monotonic() < end:
                    stop.wait(0.01)
                    rec.poll()
        finally:
            rec.close()  # takes what arrived since the last poll
            log.info("closed recording: %d messages", rec.count)
        if rec.stopped.is_set() and not stop.is_set() and (missing := rec.missing_finals(procs)):
            # The report will call them not alive at the end: say what was seen of them.
            log.warning(
                "no final stats from %s (token up at the end: %s)",
                ", ".join(f"{r} {i}" for r, i in missing),
                ", ".join(f"{r} {i}: {rec.alive.get(keys.alive(run, r, i))}" for r, i in missing),
            )
    if not args.no_report and start:
        summary = results.make_report(out, sc, "run", float(start["duration"]), float(start["time_scale"]), int(start["seed"]))  # type: ignore[arg-type]
        print(results.table(summary))
    return 0
