"""Several hosts on one machine: Linux network namespaces joined by veth pairs to a
bridge in a namespace of its own (a switch), nothing on the host's own network.

    router  10.201.0.1   zswarm router
    world   10.201.0.2   world + recorder
    fleet-a 10.201.0.3   agents 1–4
    fleet-b 10.201.0.4   agents 5–7
    lone    10.201.0.5   agent 8

§3.2 runs across them; mid-run agent 8's cable is pulled (``ip link set … down``
on the switch's side) for longer than the Zenoh lease, then plugged back.  The
others go on; the gap shows in the link counters of agent 8's links; agent 8
re-joins (its liveliness comes back, its estimates resume and re-converge).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest

from tests.conftest import TOPO
from tests.integration.conftest import wait_for, zswarm
from zswarm.recording.mcap_io import read
from zswarm.report import load_recording
from zswarm.transport.bus import LEASE_MS

pytestmark = pytest.mark.integration

NET = "10.201.0"
HOSTS = {"router": 1, "world": 2, "fleet-a": 3, "fleet-b": 4, "lone": 5}
PLACE = {**{i: "fleet-a" for i in (1, 2, 3, 4)}, **{i: "fleet-b" for i in (5, 6, 7)}, 8: "lone"}
CUT_S = 3.0  # wall seconds, > the 1 s lease (zswarm.transport.bus.zenoh_config): the router closes agent 8's session
LEASE_S = LEASE_MS / 1000
# Eight agents at 100 Hz, the world at 200 Hz, the recorder and the router on 2 cores at
# time scale 1 are at the machine's capacity (measured on a quiet machine: 1585-1802 of
# 2000 steps in 20 s, estimate gaps of up to 0.335 s anywhere in the run, cut or not), so
# the run goes at time scale 0.5 as the suite's other long runs do: world time is half the
# wall time, the cut 1.5 s of world time.
SCALE = 0.5


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    r = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if check and r.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {r.stderr.strip()}")
    return r


class Network:
    """The namespaces of one test, named after its PID; deleted in :meth:`remove`."""

    def __init__(self) -> None:
        self.tag = f"zs{os.getpid() % 100000}"
        self.names: list[str] = []

    def ns(self, host: str) -> str:
        return f"{self.tag}-{host}"

    def create(self) -> None:
        sw = self.ns("switch")
        _ip("netns", "add", sw)
        self.names.append(sw)
        _ip("-n", sw, "link", "add", "br0", "type", "bridge")
        _ip("-n", sw, "link", "set", "br0", "up")
        for host, k in HOSTS.items():
            ns = self.ns(host)
            _ip("netns", "add", ns)
            self.names.append(ns)
            a, b = f"{self.tag}h{k}", f"{self.tag}s{k}"
            _ip("link", "add", a, "type", "veth", "peer", "name", b)
            _ip("link", "set", a, "netns", ns)
            _ip("link", "set", b, "netns", sw)
            _ip("-n", ns, "link", "set", a, "name", "eth0")
            _ip("-n", ns, "addr", "add", f"{NET}.{k}/24", "dev", "eth0")
            _ip("-n", ns, "link", "set", "eth0", "up")
            _ip("-n", ns, "link", "set", "lo", "up")
            _ip("-n", sw, "link", "set", b, "master", "br0")
            _ip("-n", sw, "link", "set", b, "up")

    def cable(self, host: str, up: bool) -> None:
        _ip("-n", self.ns("switch"), "link", "set", f"{self.tag}s{HOSTS[host]}", "up" if up else "down")

    def exec(self, host: str, cmd: list[str]) -> list[str]:
        # `ip netns exec` execs the command: the PID we get is the process's own.
        return ["ip", "netns", "exec", self.ns(host), *cmd]

    def remove(self) -> None:
        for n in reversed(self.names):
            _ip("netns", "delete", n, check=False)


@pytest.fixture
def network():
    if os.geteuid() != 0 or not shutil.which("ip"):
        pytest.skip("network namespaces need root and iproute2's ip")
    net = Network()
    try:
        net.create()
    except RuntimeError as exc:
        net.remove()
        pytest.skip(f"no network namespaces here: {exc}")
    try:
        yield net
    finally:
        net.remove()


def test_agents_on_separate_hosts_and_a_pulled_cable(procs, network, tmp_path):
    topo = str(TOPO / "thesis-3.2-fixed8.toml")
    ep = f"tcp/{NET}.{HOSTS['router']}:7447"
    run = ["--run-id", "netns", "--connect", ep]
    out = tmp_path / "out"
    logs = tmp_path / "logs"
    logs.mkdir()
    procs.start(network.exec("router", zswarm("router", "--listen", ep)), log=logs / "router.log")
    rec = procs.start(network.exec("world", zswarm("record", topo, "--out", str(out), *run)), log=logs / "recorder.log")
    for i, host in PLACE.items():
        procs.start(network.exec(host, [sys.executable, "-m", "agent", "--topology", topo, "--id", str(i), *run]), log=logs / f"agent-{i}.log")
    world = procs.start(
        network.exec("world", [sys.executable, "-m", "world", "--topology", topo, "--duration", "20", "--time-scale", str(SCALE), "--wait-for-recorder", *run]),
        log=logs / "world.log",
    )
    wait_for(lambda: "started" in (logs / "agent-8.log").read_text(), 90, "agent 8 started")
    time.sleep(5.0)
    t_down = time.time()
    network.cable("lone", up=False)
    time.sleep(CUT_S)
    network.cable("lone", up=True)
    t_up = time.time()
    assert world.wait(90) == 0, (logs / "world.log").read_text()[-2000:]
    assert rec.wait(60) == 0, (logs / "recorder.log").read_text()[-2000:]
    agent8 = (logs / "agent-8.log").read_text()
    assert "lost the world's token" in agent8 and "the world is back" in agent8, agent8[-2000:]

    s = json.loads((out / "summary.json").read_text())
    r = load_recording(out / "recording.mcap")
    epoch = r.start["epoch"]
    w_down, w_up = (t_down - epoch) * SCALE, (t_up - epoch) * SCALE  # world time
    # The others went on through the cut: estimates all along, converged (sim: 7e-5 at 20 s).
    for i in range(1, 8):
        a = s["agents"][str(i)]
        assert a["alive_at_end"] and a["last_estimate_t"] > 19.9, (i, a)
        t = np.array([e[0] for e in r.est[i]])
        # No gap in theirs.  What the cut could do to the others (the router held up by
        # agent 8's stalled link, then closing its session) lasts from the cut until the
        # lease expires: a gap it caused is ≥ the lease (1 s of wall time, LEASE_S * SCALE
        # of world time).  Half of that is the bound: above a busy machine's scheduling
        # stalls (at most 0.335 s of wall time measured at time scale 1, which loads the
        # machine more than 0.5 does), below a stall caused by the cut.
        win = (t > w_down - SCALE) & (t < w_up + SCALE)
        assert np.max(np.diff(t[win])) < 0.5 * LEASE_S * SCALE, i
        if i > 2:
            assert a["attitude_error_final"] < 1e-2, (i, a)
    # The cut in the counters: every link into agent 8 (its sensors at 200 Hz, its
    # in-neighbours 1 and 7 at 100 Hz of world time; it has no out-edges) lost everything
    # sent during the cut (CUT_S * SCALE of world time) and the reconnection.  At least half
    # of that: agents behind on a busy machine publish fewer messages in the window (up to
    # a third of their ticks missed under stress at time scale 1), and a link that lost
    # nothing fails it.
    links = s["links"]
    into_8 = {k: v for k, v in links.items() if k.endswith("->8")}
    assert set(into_8) == {"world->8", "1->8", "7->8"}, into_8
    for k, v in into_8.items():
        rate = 200 if k.startswith("world") else 100
        assert v["dropped"] > 0.5 * CUT_S * SCALE * rate, (k, v)
    for k, v in links.items():
        if "8" not in k.split("->"):
            assert v["dropped"] == 0, (k, v)  # nobody else lost anything
    # Agent 8 left (its session closed after the lease) and came back.
    ev8 = [(e["t_wall"], e["alive"]) for e in r.alive_events if e["key"].endswith("/alive/agent/8")]
    assert any(not up and t_down <= tw <= t_up + 1 for tw, up in ev8), ev8
    assert any(up and tw >= t_up for tw, up in ev8), ev8
    t8 = np.array([e[0] for e in r.est[8]])
    gap = np.diff(t8)
    assert np.max(gap) > 0.5 * CUT_S * SCALE, "no gap in agent 8's estimates"
    assert t8[-1] > 19.9 and s["agents"]["8"]["alive_at_end"], s["agents"]["8"]
    assert s["agents"]["8"]["attitude_error_final"] < 1e-2, s["agents"]["8"]
    assert any(st == "events/alive" for st, _, _ in read(out / "recording.mcap"))
