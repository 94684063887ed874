"""Processes started by hand (README's manual way) and their behaviour under signals."""

from __future__ import annotations

import json
import signal
import sys
import time

import msgpack
import pytest

from tests.conftest import TOPO
from tests.integration.conftest import wait_for, zswarm
from zswarm import keys
from zswarm.bus import ZenohBus, zenoh_config
from zswarm.launch import free_port

pytestmark = pytest.mark.integration
TOPOLOGY = str(TOPO / "thesis-3.2-fixed8.toml")


def test_manual_launch_signals_and_malformed_messages(procs, tmp_path):
    ep = f"tcp/127.0.0.1:{free_port()}"
    run = "manual1"
    common = ["--run-id", run, "--connect", ep]
    router = procs.start(zswarm("router", "--listen", ep), log=tmp_path / "router.log")
    alive: set = set()
    with ZenohBus(zenoh_config("client", connect=[ep])) as bus:
        bus.watch_alive(keys.alive_all(run), lambda k, up: (alive.add if up else alive.discard)(keys.parse_alive(k)))
        rec = procs.start(zswarm("record", TOPOLOGY, "--out", str(tmp_path / "out"), *common), log=tmp_path / "rec.log")
        agents = {i: procs.start([sys.executable, "-m", "agent", "--topology", TOPOLOGY, "--id", str(i), *common], log=tmp_path / f"a{i}.log") for i in range(1, 9)}
        wait_for(lambda: {("agent", i) for i in range(1, 9)} | {("recorder", 0)} <= alive, 60, "agents and recorder alive")

        # An agent waiting for the start exits promptly on SIGTERM (no hang on an open session).
        extra = procs.start([sys.executable, "-m", "agent", "--topology", TOPOLOGY, "--id", "5", "--run-id", "other", "--connect", ep], log=tmp_path / "x.log")
        wait_for(lambda: (tmp_path / "x.log").exists() and "waiting for start" in (tmp_path / "x.log").read_text(), 60, "extra agent ready")
        t0 = time.monotonic()
        extra.send_signal(signal.SIGTERM)
        assert extra.wait(5) == 0 and time.monotonic() - t0 < 2.0

        # Time scale 0.5 (12 s of wall time): at 1, a busy machine left agent 3 499 of the 600
        # ticks (world skipping 8 % of its samples) and the step count below failed.
        world = procs.start(
            [sys.executable, "-m", "world", "--topology", TOPOLOGY, "--duration", "6", "--time-scale", "0.5", "--wait-for-recorder", *common], log=tmp_path / "world.log"
        )
        wait_for(lambda: "start:" in (tmp_path / "world.log").read_text(), 60, "world start")
        time.sleep(1.0)
        # Garbage and foreign messages on zswarm keys: counted, logged once, dropped.
        pub_sense = bus.publisher(keys.sense(run, 3))
        pub_edge = bus.publisher(keys.edge(run, 1, 3))
        for _ in range(5):
            pub_sense.put(b"\x93garbage")
            pub_edge.put(msgpack.packb({"v": 1, "type": "edge", "src": 1}))
        time.sleep(1.0)
        # SIGINT one agent mid-run: it exits 0 within 2 s; the others go on.
        t0 = time.monotonic()
        agents[6].send_signal(signal.SIGINT)
        assert agents[6].wait(5) == 0 and time.monotonic() - t0 < 2.0
        assert world.wait(30) == 0
        for i, a in agents.items():
            assert a.wait(10) == 0, i
        assert rec.wait(60) == 0
    out = tmp_path / "out"
    s = json.loads((out / "summary.json").read_text())
    assert s["agents"]["3"]["malformed_received"] >= 10
    assert s["agents"]["3"]["alive_at_end"] and s["agents"]["3"]["steps"] > 500
    log3 = (tmp_path / "a3.log").read_text()
    assert log3.count("dropped malformed message") == 2  # once per key
    # The SIGINT'd agent stopped cleanly, early.
    assert s["agents"]["6"]["last_estimate_t"] < 5.0
    t0 = time.monotonic()
    router.send_signal(signal.SIGTERM)
    assert router.wait(5) == 0 and time.monotonic() - t0 < 2.0


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_world_and_recorder_exit_within_2s_mid_run(procs, tmp_path, sig):
    ep = f"tcp/127.0.0.1:{free_port()}"
    common = ["--run-id", "sig", "--connect", ep]
    router = procs.start(zswarm("router", "--listen", ep))
    rec = procs.start(zswarm("record", TOPOLOGY, "--out", str(tmp_path / "out"), "--no-report", *common), log=tmp_path / "rec.log")
    agents = [procs.start([sys.executable, "-m", "agent", "--topology", TOPOLOGY, "--id", str(i), *common], log=tmp_path / f"a{i}.log") for i in range(1, 9)]
    world = procs.start([sys.executable, "-m", "world", "--topology", TOPOLOGY, "--duration", "60", "--wait-for-recorder", *common], log=tmp_path / "world.log")
    wait_for(lambda: "start:" in (tmp_path / "world.log").read_text(), 60, "world start")
    time.sleep(1.5)
    t0 = time.monotonic()
    world.send_signal(sig)
    assert world.wait(5) == 0
    assert time.monotonic() - t0 < 2.0
    # The world's stop ends the run for everyone.
    for a in agents:
        assert a.wait(5) == 0
    t0 = time.monotonic()
    rec.send_signal(sig)
    assert rec.wait(5) == 0 and time.monotonic() - t0 < 2.0
    from zswarm.record import ensure_recording, read

    # --no-report leaves the payloads as they came (recording.raw.mcap): readable as they
    # are, and transcoded into the viewer recording by whatever reads the folder next.
    assert sum(1 for _ in read(tmp_path / "out" / "recording.raw.mcap")) > 1000
    assert sum(1 for _ in read(ensure_recording(tmp_path / "out", None))) > 1000
    router.send_signal(sig)
    assert router.wait(5) == 0
