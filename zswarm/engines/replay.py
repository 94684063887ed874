"""``zswarm replay``: play a results folder's recording back.

Two ways, at ``speed`` times the pace of the recording's log times (``inf``:
as fast as the output takes them):

* ``live``: every channel of the recording (the run's messages and the viewer
  channels, recomputed) on a Foxglove WebSocket server, for Foxglove or
  Lichtblick;
* ``bus``: every message back onto a Zenoh network as the original msgpack
  payload on its original key under run id ``run``, liveliness tokens
  included, so that anything that listens to a run (``zswarm record``, a
  user's own subscriber) sees it again.  Publishers block rather than drop
  (this is not a control path), so a recorder there gets every message.
"""

from __future__ import annotations

import argparse
import logging
import math
import threading
import time
from pathlib import Path
from typing import Any

from zswarm.recording.mcap_io import ALIVE_CHANNEL, MALFORMED_CHANNEL, ViewerOut, read, recorded_run_id
from zswarm.scenario import Scenario
from zswarm.transport import keys, procutil, wire, wire_json

log = logging.getLogger("zswarm.engines.replay")


def _rerun_alive_key(key: str, run: str) -> str | None:
    """``zswarm/<old>/alive/<role>/<i>`` under run id ``run``."""
    k = keys.parse(key)
    return None if k is None or k.kind != "alive" else keys.stream_key(run, k.stream)


def replay(
    path: Path,
    speed: float,
    stop: threading.Event,
    live: ViewerOut | None = None,
    bus: Any = None,
    run: str | None = None,
) -> dict[str, int]:
    """Play ``path`` back onto ``live`` and/or ``bus``; return counts of what went out."""
    pubs: dict[str, Any] = {}
    tokens: set[str] = set()
    sent = {"messages": 0, "malformed_skipped": 0, "alive_events": 0}
    t0_log: int | None = None
    t0_wall = time.monotonic()
    for stream, payload, t in read(path):
        if stop.is_set():
            break
        if stream == MALFORMED_CHANNEL:
            continue
        if t0_log is None:
            t0_log = t
        if math.isfinite(speed):
            wait = t0_wall + (t - t0_log) * 1e-9 / speed - time.monotonic()
            if wait > 0 and stop.wait(wait):
                break
        if stream == ALIVE_CHANNEL:
            event = payload if isinstance(payload, dict) else None
            if event is None or not isinstance(event.get("key"), str):
                continue
            sent["alive_events"] += 1
            if live is not None:
                live.alive(event, t)
            if bus is not None and run is not None:
                key = _rerun_alive_key(event["key"], run)
                if key is None:
                    continue
                if event.get("alive") and key not in tokens:
                    bus.declare_token(key)
                    tokens.add(key)
                elif not event.get("alive") and key in tokens:
                    bus.undeclare_token(key)
                    tokens.discard(key)
            continue
        if live is not None and live.message(stream, payload, t) is None:
            sent["malformed_skipped"] += 1
            continue
        if bus is not None and run is not None:
            try:
                # Sent as this version's payload (an earlier recording's message upgraded: a live
                # receiver refuses another version).
                data = (payload if wire.version_of(payload) == wire.VERSION else wire.encode_message(wire.decode_recorded(payload))) if isinstance(payload, bytes) else wire_json.payload_from_json(payload)
            except wire.MessageError:
                sent["malformed_skipped"] += 1
                continue
            key = keys.stream_key(run, stream)
            pub = pubs.get(key)
            if pub is None:
                pub = pubs[key] = bus.publisher(key, block=True)
            pub.put(data)
        sent["messages"] += 1
    if live is not None:
        live.flush()
    return sent


def run_replay(
    results: Path, sc: Scenario | None, speed: float, live_at: tuple[str, int] | None, bus: Any, run: str | None, stop: threading.Event, hold: bool = False
) -> dict[str, int]:
    """The CLI's body: a ViewerOut for ``live_at`` (if any), then :func:`replay`;
    ``hold``: keep serving after the end until ``stop``."""
    out = ViewerOut(None, live_at, sc, server_name=f"zswarm replay {results.name}") if live_at is not None else None
    try:
        if out is not None:
            log.info("serving on ws://%s:%d (Foxglove or Lichtblick: open connection, Foxglove WebSocket)", live_at[0], out.live_port)  # type: ignore[index]
        counts = replay(results / "recording.mcap", speed, stop, live=out, bus=bus, run=run)
        if hold and out is not None:
            log.info("replayed; still serving until Ctrl-C")
            stop.wait()
        return counts
    finally:
        if out is not None:
            out.close()


# --------------------------------------------------------------------------- the command (zswarm.cli dispatches here)


def command(args: argparse.Namespace) -> int:
    from zswarm.engines import replay
    from zswarm.recording.mcap_io import ensure_recording

    sc = procutil.load_or_exit(str(args.results / "scenario.toml")) if (args.results / "scenario.toml").exists() else None
    rec_path = ensure_recording(args.results, sc)
    if not rec_path.exists():
        procutil.fail_usage(f"{rec_path}: no recording there")
    zenoh_out = bool(args.connect or args.listen or args.config)
    if args.live is None and not zenoh_out:
        procutil.fail_usage("replay needs --live [HOST:PORT] or a Zenoh endpoint (--connect/--listen/--config)")
    log = procutil.setup_logging("replay")
    stop = procutil.stop_on_signals()
    run = None
    if zenoh_out:
        run = keys.check_run_id(args.run_id or recorded_run_id(rec_path) or "default")
    bus = None
    try:
        if zenoh_out:
            from zswarm.transport.bus import ZenohBus

            bus = ZenohBus(procutil.zenoh_conf(args))
            if args.wait_for_recorder:
                up = threading.Event()
                bus.watch_alive(keys.alive(run, "recorder", 0), lambda _k, alive: up.set() if alive else None)  # type: ignore[arg-type]
                log.info("waiting for a recorder of run %r", run)
                while not up.wait(0.2):
                    if stop.is_set():
                        return procutil.interrupted_code()
        counts = replay.run_replay(args.results, sc, args.speed, args.live, bus, run, stop, hold=args.hold)
        log.info("replayed %d messages and %d liveliness events%s", counts["messages"], counts["alive_events"], f" onto run {run!r}" if run else "")
    finally:
        if bus is not None:
            time.sleep(0.5)  # let the last samples leave before the session closes
            bus.close()
    return procutil.interrupted_code() if stop.is_set() else 0
