"""A raw zenoh-python swarm: zswarm's traffic with no estimator math (bench_capacity.py's baseline).

One process per role, as ``zswarm run`` starts them: ``world`` publishes a
sensor packet to every agent at the sensor rate and the truth to the
recorder; each ``agent`` i ticks at its rate on the wall clock and puts one
message per out-edge and one estimate; the ``recorder`` takes everything
from a FIFO channel every 10 ms, as zswarm's does.  Payloads are msgpack maps
padded to the sizes zswarm's messages have in the same scenario, keys and
transport settings (``zswarm.transport.bus.zenoh_config``, DROP, REAL_TIME, not
express) are zswarm's.  Callbacks unpack and store the newest message per
key, as zswarm's inbox does, without validation.

Usage: python bench/raw_swarm.py ROLE CONFIG.json ENDPOINT OUT.json [ID]
"""

from __future__ import annotations

import json
import math
import sys
import threading
import time
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import zenoh

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from zswarm.transport.bus import zenoh_config  # noqa: E402

ROOT = "raw"


def pub(s: Any, key: str) -> Any:
    return s.declare_publisher(key, congestion_control=zenoh.CongestionControl.DROP, priority=zenoh.Priority.REAL_TIME, express=False)


def msg(src: int, seq: int, size: int) -> bytes:
    """A map with the envelope zswarm's messages have, padded to ``size`` bytes."""
    base = {"v": 2, "type": "x", "src": src, "seq": seq, "t": time.time()}
    n = len(msgpack.packb(base | {"pad": b""}))
    return msgpack.packb(base | {"pad": b"\0" * max(0, size - n)})


def wait_start(s: Any) -> float:
    got: list[float] = []
    ev = threading.Event()

    def on_start(sample: Any) -> None:
        if not got:
            got.append(msgpack.unpackb(sample.payload.to_bytes())["epoch"])
            ev.set()

    sub = s.declare_subscriber(f"{ROOT}/ctl/start", on_start)
    ev.wait(120)
    sub.undeclare()
    return got[0]


def sleep_until(t: float) -> None:
    d = t - time.time()
    if d > 0:
        time.sleep(d)


def agent(cfg: dict[str, Any], s: Any, i: int) -> dict[str, Any]:
    me = cfg["agents"][str(i)]
    lock = threading.Lock()
    latest: dict[str, dict[str, Any]] = {}
    lat: dict[str, list[float]] = {}
    seen: dict[str, list[int]] = {}

    def on_msg(sample: Any) -> None:
        now = time.time()
        key = str(sample.key_expr)
        m = msgpack.unpackb(sample.payload.to_bytes())
        with lock:
            latest[key] = m
            lat.setdefault(key, []).append(now - m["t"])
            seen.setdefault(key, [0, -1])
            seen[key][0] += 1
            seen[key][1] = max(seen[key][1], m["seq"])

    subs = [s.declare_subscriber(f"{ROOT}/sense/{i}", on_msg)]
    if me["in"]:
        subs.append(s.declare_subscriber(f"{ROOT}/edge/*/{i}", on_msg))
    pubs = {j: pub(s, f"{ROOT}/edge/{i}/{j}") for j in me["out"]}
    est = pub(s, f"{ROOT}/est/{i}")
    token = s.liveliness().declare_token(f"{ROOT}/alive/agent/{i}")
    epoch = wait_start(s)
    period, duration = 1.0 / cfg["rate"], cfg["duration"]
    # The first tick at or after the start reached this process (zswarm's AgentClock.first_tick):
    # ticks before it are not missed deadlines.
    k, missed, ticks = max(0, math.ceil((time.time() - epoch) / period)), 0, 0
    while k * period <= duration:
        sleep_until(epoch + k * period)
        with lock:
            _ = [latest.get(f"{ROOT}/edge/{j}/{i}") for j in me["in"]]
        for j, p in pubs.items():
            p.put(msg(i, ticks, me["out"][j]))
        est.put(msg(i, ticks, me["est"]))
        ticks += 1
        k += 1
        now = time.time() - epoch
        while k * period < now - period:  # zswarm's AgentClock.next_tick: a tick more than a period late is missed
            k += 1
            missed += 1
    time.sleep(0.3)
    for x in subs:
        x.undeclare()
    token.undeclare()
    with lock:
        links = {
            k.split("/", 1)[1]: {"p50_ms": 1e3 * float(np.percentile(v, 50)), "p99_ms": 1e3 * float(np.percentile(v, 99)), "delivered": seen[k][0], "dropped": seen[k][1] + 1 - seen[k][0]}
            for k, v in lat.items()
        }
    return {"ticks": ticks, "missed": missed, "links": links}


def world(cfg: dict[str, Any], s: Any) -> dict[str, Any]:
    ids = [int(i) for i in cfg["agents"]]
    pubs = {i: pub(s, f"{ROOT}/sense/{i}") for i in ids}
    truth = pub(s, f"{ROOT}/truth")
    start = s.declare_publisher(f"{ROOT}/ctl/start")
    alive: set[str] = set()
    changed = threading.Event()

    def on_alive(sample: Any) -> None:
        (alive.add if sample.kind == zenoh.SampleKind.PUT else alive.discard)(str(sample.key_expr))
        changed.set()

    sub = s.liveliness().declare_subscriber(f"{ROOT}/alive/**", on_alive, history=True)
    token = s.liveliness().declare_token(f"{ROOT}/alive/world/0")
    need = {f"{ROOT}/alive/agent/{i}" for i in ids} | {f"{ROOT}/alive/recorder/0"}
    while not need <= alive:
        changed.wait(0.2)
        changed.clear()
    epoch = time.time() + 1.0
    start.put(msgpack.packb({"epoch": epoch}))
    period, duration = 1.0 / cfg["sensor_rate"], cfg["duration"]
    k, late = 0, 0
    while k * period <= duration:
        sleep_until(epoch + k * period)
        now = time.time() - epoch
        if now - k * period > period:  # zswarm's world: skip the samples it is late for
            skip = int(now / period) - k
            k += skip
            late += skip
        truth.put(msg(0, k, cfg["truth"]))
        for i in ids:
            pubs[i].put(msg(0, k, cfg["agents"][str(i)]["sense"]))
        k += 1
    start.put(msgpack.packb({"epoch": epoch, "stop": True}))
    time.sleep(0.5)
    sub.undeclare()
    token.undeclare()
    return {"samples": k, "late": late}


def recorder(cfg: dict[str, Any], s: Any) -> dict[str, Any]:
    sub = s.declare_subscriber(f"{ROOT}/**", zenoh.handlers.FifoChannel(1 << 18))
    token = s.liveliness().declare_token(f"{ROOT}/alive/recorder/0")
    count: dict[str, int] = {}
    end = None
    while end is None or time.time() < end:
        time.sleep(0.01)
        while (sample := sub.try_recv()) is not None:
            key = str(sample.key_expr)
            data = sample.payload.to_bytes()
            stream = key.split("/")[1]
            count[stream] = count.get(stream, 0) + 1
            if key == f"{ROOT}/ctl/start" and end is None and msgpack.unpackb(data).get("stop"):
                end = time.time() + 1.0
    sub.undeclare()
    token.undeclare()
    return {"received": count}


def main() -> int:
    role, cfg_path, ep, out = sys.argv[1:5]
    cfg = json.loads(Path(cfg_path).read_text())
    with zenoh.open(zenoh_config("client", connect=[ep])) as s:
        if role == "agent":
            res = agent(cfg, s, int(sys.argv[5]))
        elif role == "world":
            res = world(cfg, s)
        else:
            res = recorder(cfg, s)
    Path(out).write_text(json.dumps(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
