"""Looking into a live swarm: ``zswarm echo`` (each message of a key expression, decoded, as a
JSON line) and ``zswarm hz`` (each key's rate and gaps), the ``ros2 topic echo`` / ``ros2 topic
hz`` of zswarm.

Both join the run's Zenoh network as a client: of a ``zswarm run`` through its results folder
(``--results DIR``: the router's endpoint, the run id and, under ``--secure``, the run's
certificates, from DIR/processes.json), or of processes started by hand through ``--connect``
and ``--run-id``.  Under ``--secure`` they use the recorder's certificate: the one process whose
job is to read every key of the run.

A stream is written as a recording's channel is (``est/3``, ``edge/*/3``, ``sense/**``), or
as a whole key expression (``zswarm/<run>/...``).  A payload that does not decode is counted
and named on stderr, never a crash; what each message says is the sender's word, checked as
every receiver checks it (zswarm.transport.wire).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any, TextIO

from zswarm.transport import keys, procutil, wire, wire_json

READER = "recorder"  # the certificate echo and hz use under --secure


def add_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("stream", help="a channel of the run (est/3, edge/*/3, sense/**, truth) or a whole key expression zswarm/RUN/...")
    p.add_argument("--results", type=Path, default=None, metavar="DIR", help="the results folder of a running zswarm run: its router, run id and certificates")
    p.add_argument("--run-id", default=None, help="the run's id (default: every run on the network, '*')")
    p.add_argument("--duration", type=procutil.positive_float, default=None, help="stop after this many seconds (default: Ctrl-C)")
    procutil.add_zenoh_args(p)


def _target(args: argparse.Namespace) -> tuple[Any, str]:
    """The Zenoh config to join with and the key expression to subscribe to."""
    run = args.run_id
    if args.results is not None:
        try:
            procs = json.loads((args.results / "processes.json").read_text())
            endpoint, found = procs["router"]["endpoint"], procs["run_id"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            procutil.fail_usage(f"{args.results}: no running zswarm run there (processes.json: {exc})")
        if not args.connect and not args.config:
            args.connect = [endpoint]
        run = run or found
        if endpoint.startswith("tls/") and args.secure is None:
            args.secure = str(args.results / "secure")
    if args.stream.startswith(keys.ROOT + "/"):
        key_expr = args.stream
    else:
        if run is not None and run != "*":
            try:
                keys.check_run_id(run)
            except ValueError as exc:
                procutil.fail_usage(f"--run-id: {exc}")
        key_expr = keys.stream_key(run or "*", args.stream.lstrip("/"))
    import zenoh

    try:
        zenoh.KeyExpr(key_expr)
    except zenoh.ZError:
        procutil.fail_usage(f"{args.stream}: not a key expression (empty chunks, e.g. a//b, and a trailing / are not allowed)")
    return procutil.zenoh_conf(args, READER), key_expr


def echo(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    """Print each message of ``args.stream`` as one JSON line ``{"key", "message"}`` until
    ``--count`` messages, ``--duration`` seconds or Ctrl-C."""
    from zswarm.transport.bus import ZenohBus

    conf, key_expr = _target(args)
    lines: deque[str] = deque()
    bad = [0]
    wake = threading.Event()

    def on_data(key: str, payload: bytes) -> None:
        try:
            m = wire.decode_recorded(payload)
        except wire.MessageError as exc:
            bad[0] += 1
            print(f"{key}: dropped: {exc}", file=sys.stderr)
            return
        lines.append(json.dumps({"key": key, "message": wire_json.to_json(m)}, allow_nan=False))
        wake.set()

    shown = 0
    with ZenohBus(conf) as bus:
        stop = procutil.stop_on_signals()
        bus.subscribe(key_expr, on_data)
        t_end = math.inf if args.duration is None else time.monotonic() + args.duration
        while not stop.is_set() and time.monotonic() < t_end and (args.count is None or shown < args.count):
            wake.wait(min(0.2, max(0.0, t_end - time.monotonic())))
            wake.clear()
            while lines and (args.count is None or shown < args.count):
                print(lines.popleft(), file=out, flush=True)
                shown += 1
    if bad[0]:
        print(f"zswarm echo: {bad[0]} payloads on {key_expr} did not decode (dropped)", file=sys.stderr)
    return procutil.interrupted_code() if stop.is_set() and args.duration is None and args.count is None else 0


class Rates:
    """Per key: the arrivals' count and the gaps between them (receiver's monotonic clock)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.last: dict[str, float] = {}
        self.gaps: dict[str, list[float]] = {}
        self.count: dict[str, int] = {}
        self.bad: dict[str, int] = {}

    def arrived(self, key: str, ok: bool, t: float) -> None:
        with self.lock:
            if not ok:
                self.bad[key] = self.bad.get(key, 0) + 1
                return
            prev = self.last.get(key)
            self.last[key] = t
            self.count[key] = self.count.get(key, 0) + 1
            if prev is not None:
                self.gaps.setdefault(key, []).append(t - prev)

    def take(self) -> dict[str, dict[str, Any]]:
        """Each key's figures since the last take: messages, rate (1 / mean gap), mean, min and
        max gap (ms) and the payloads that did not decode."""
        with self.lock:
            gaps, count, bad = self.gaps, self.count, self.bad
            self.gaps, self.count, self.bad = {}, {}, {}
        out = {}
        for key in sorted(set(count) | set(bad), key=keys.natural):
            g = gaps.get(key, [])
            mean = sum(g) / len(g) if g else None
            out[key] = {
                "messages": count.get(key, 0),
                "rate_hz": 1.0 / mean if mean else None,
                "gap_mean_ms": 1e3 * mean if mean is not None else None,
                "gap_min_ms": 1e3 * min(g) if g else None,
                "gap_max_ms": 1e3 * max(g) if g else None,
                "malformed": bad.get(key, 0),
            }
        return out


def _stream(key: str) -> str:
    """``zswarm/<run>/est/3`` as ``est/3`` (the run is one, or the key expression named it)."""
    parts = key.split("/", 2)
    return parts[2] if len(parts) == 3 and parts[0] == keys.ROOT else key


def _fmt(x: float | None, spec: str) -> str:
    return "-" if x is None else format(x, spec)


def hz(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    """Every ``--window`` seconds, one line per key of ``args.stream``: messages, rate, gaps;
    with ``--json``, one JSON object per window ``{"t", "keys": {key: figures}}``."""
    from zswarm.transport.bus import ZenohBus

    conf, key_expr = _target(args)
    rates = Rates()

    def on_data(key: str, payload: bytes) -> None:
        t = time.monotonic()  # at arrival, before the decode
        try:
            wire.decode_recorded(payload)
            ok = True
        except wire.MessageError:
            ok = False
        rates.arrived(key, ok, t)

    with ZenohBus(conf) as bus:
        stop = procutil.stop_on_signals()
        bus.subscribe(key_expr, on_data)
        t0 = time.monotonic()
        t_end = math.inf if args.duration is None else t0 + args.duration
        n = 0
        while not stop.is_set() and time.monotonic() < t_end:
            n += 1
            stop.wait(max(0.0, min(t0 + n * args.window, t_end) - time.monotonic()))
            figures = rates.take()
            t = round(time.monotonic() - t0, 3)
            if args.json:
                print(json.dumps({"t": t, "keys": figures}), file=out, flush=True)
                continue
            print(f"t = {t:.1f} s: {len(figures)} keys" + ("" if figures else f" (nothing on {key_expr})"), file=out)
            for key, f in figures.items():
                tail = f"  {f['malformed']} malformed" if f["malformed"] else ""
                print(
                    f"  {_stream(key):<20} {f['messages']:>6} msgs"
                    f" {_fmt(f['rate_hz'], '9.2f')} Hz  gap mean {_fmt(f['gap_mean_ms'], '7.2f')} min {_fmt(f['gap_min_ms'], '7.2f')} max {_fmt(f['gap_max_ms'], '7.2f')} ms{tail}",
                    file=out,
                )
            out.flush()
    return procutil.interrupted_code() if stop.is_set() and args.duration is None else 0
