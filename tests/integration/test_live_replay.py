"""``zswarm run --live`` serves the run on a Foxglove WebSocket server while it goes
on; ``zswarm replay`` plays the results back onto Zenoh, and a recorder there
reproduces the run's report.

The client is tests/foxglove_ws.py: the ``websockets`` library speaking the
Foxglove protocol (subprotocol ``foxglove.sdk.v1``) and decoding with the
advertised protobuf / JSON schemas, none of zswarm's code.
"""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from tests.conftest import TOPO
from tests.foxglove_ws import Client
from tests.integration.conftest import zswarm
from zswarm.engines.launch import free_port
from zswarm.scenario import load as load_scenario

pytestmark = pytest.mark.integration

# What may differ between a run's summary and its replay's: how the results were
# made (wall time, exit codes the launcher saw, the recording's own message counts,
# which include the viewer channels' inputs as they arrived).
NOT_REPRODUCED = {"wall_time_s", "exit_codes", "interrupted", "recorded_messages", "engine", "cpu"}  # cpu: what the processes of the run spent, not in the recording


def test_live_view_then_replay_reproduces_the_report(procs, tmp_path):
    name = "thesis-3.2-fixed8"
    sc = load_scenario(TOPO / f"{name}.toml")
    out = tmp_path / "out"
    port = free_port()
    p = procs.start(
        zswarm("run", str(TOPO / f"{name}.toml"), "--duration", "8", "--out", str(out), "--quiet", "--no-plots", "--live", f"127.0.0.1:{port}"), log=tmp_path / "launcher.log"
    )
    # Connect while it runs: the recorder's server comes up with the recorder.
    c = Client(f"ws://127.0.0.1:{port}", timeout=60)
    try:
        c.wait_for_topics({"/tf", "/errors/3", "/scene"}, timeout=60)
        assert c.by_topic["/tf"]["encoding"] == "protobuf" and c.by_topic["/tf"]["schemaName"] == "foxglove.FrameTransforms"
        c.subscribe(["/tf", "/errors/3"])
        got = c.receive(200, timeout=60)
    finally:
        c.close()
    now = time.time_ns()
    frames = {}
    for topic, log_time, m in got:
        # Run: log times are Unix time at the recorder (seconds behind now at most).
        assert abs(log_time - now) < 60e9, (topic, log_time, now)
        if topic == "/tf":
            for x in m.transforms:
                frames[x.child_frame_id] = x
        else:
            assert 0.0 <= m["attitude"] <= 1.0 and m["t"] >= 0.0
    assert {f"agent_{i}" for i in sc.ids} <= set(frames)
    assert any(f.endswith("_est") for f in frames)
    for a in sc.agents:  # §3.2: the agents turn in place, at their scenario positions
        x = frames[f"agent_{a.id}"]
        assert (x.translation.x, x.translation.y, x.translation.z) == tuple(a.p)
        q = np.array([x.rotation.x, x.rotation.y, x.rotation.z, x.rotation.w])
        assert abs(np.linalg.norm(q) - 1.0) < 1e-12
    assert any(t == "/errors/3" for t, _, _ in got)
    assert p.wait(150) == 0, (tmp_path / "launcher.log").read_text()
    procs.adopt(out)
    original = json.loads((out / "summary.json").read_text())

    # Replay onto a Zenoh network, as fast as it goes, with a recorder listening there.
    ep = f"tcp/127.0.0.1:{free_port()}"
    procs.start(zswarm("router", "--listen", ep), log=tmp_path / "router.log")
    out2 = tmp_path / "replayed"
    rec = procs.start(zswarm("record", str(out / "scenario.toml"), "--run-id", "replayed", "--connect", ep, "--out", str(out2)), log=tmp_path / "recorder.log")
    rp = procs.start(
        zswarm("replay", str(out), "--connect", ep, "--run-id", "replayed", "--speed", "inf", "--wait-for-recorder"),
        log=tmp_path / "replay.log",
    )
    assert rp.wait(120) == 0, (tmp_path / "replay.log").read_text()
    assert rec.wait(120) == 0, (tmp_path / "recorder.log").read_text()
    replayed = json.loads((out2 / "summary.json").read_text())
    # An agent's fate is the launcher's (its exit status), which a recording does not hold.
    for a in original["agents"].values():
        assert a.pop("fate") == "finished", a
    # The report of the replay is the report of the run: every number, exactly (the
    # same messages; JSON floats round-trip).
    diff = {k for k in set(original) | set(replayed) if original.get(k) != replayed.get(k)} - NOT_REPRODUCED
    assert not diff, {k: (original.get(k), replayed.get(k)) for k in diff}
    assert replayed["agents"]["3"]["attitude_error_final"] == original["agents"]["3"]["attitude_error_final"]
