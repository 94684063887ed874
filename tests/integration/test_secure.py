"""The authenticated profile (issue 14): ``zswarm run --secure`` runs every process with
mutual TLS and the router's access control.  A process that holds a valid certificate
(agent 4's) but claims to be agent 3 gets nothing delivered; on its own keys it gets
through (so its silence as agent 3 is the ACL's doing, not a dead connection).  A process
without a certificate, or with one from another CA, cannot connect."""

from __future__ import annotations

import json
import subprocess
import time

import msgpack
import numpy as np
import pytest
import zenoh

from tests.conftest import TOPO
from tests.integration.conftest import unconfirmed, wait_for, world_started, zswarm
from zswarm.engines.launch import free_port
from zswarm.math import so3
from zswarm.recording.mcap_io import ensure_recording, read
from zswarm.transport import keys, wire
from zswarm.transport.bus import zenoh_config
from zswarm.transport.secure import make_certs

pytestmark = pytest.mark.integration
T32 = str(TOPO / "thesis-3.2-fixed8.toml")
SPOOF_INC, OWN_INC = 777, 778


def _edge(src: int, seq: int, inc: int) -> bytes:
    return wire.encode("edge", src, seq, 1.0, inc=inc, t_local=1.0, R_hat=so3.exp(np.array([0.1, 0.2, 0.3])), p_hat=np.zeros(3), b=np.array([0.0, 0.0, 1.0]))


def test_secure_run_rejects_spoofing_and_strangers(procs, tmp_path):
    out = tmp_path / "out"
    p = procs.start(zswarm("run", T32, "--duration", "10", "--time-scale", "0.5", "--out", str(out), "--quiet", "--no-plots", "--secure"), log=tmp_path / "launcher.log")
    wait_for(lambda: procs.adopt(out), 60, "processes.json")
    info = json.loads((out / "processes.json").read_text())
    ep, run = info["router"]["endpoint"], info["run_id"]
    assert ep.startswith("tls/")
    world_started(out)
    certs = out / "secure"

    # A stranger: no client certificate (mTLS), or one signed by another CA.
    other = make_certs(tmp_path / "other", ["agent-3"])
    for conf in (zenoh_config("client", connect=[ep]), zenoh_config("client", connect=[ep], secure=(str(other), "agent-3"))):
        conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(certs / "ca.pem")))  # it trusts the router
        conf.insert_json5("connect/timeout_ms", "{router: -1, peer: -1, client: 3000}")
        with pytest.raises(zenoh.ZError):
            zenoh.open(conf).close()

    # An insider with agent 4's certificate: as agent 3 on 3->4, and as itself on 4->5.
    # On its own keys (the access control lets it) it also claims to be agent 3 and the
    # world inside the message: an estimate of agent 3 far off, agent 3's stats with
    # 424242 steps and links "all dropped", the world's stats "late 999999".
    forged = [
        (keys.est(run, 4), wire.encode("est", 3, 10**6, 9.0, inc=SPOOF_INC, t_local=9.0, R_hat=so3.exp(np.array([2.0, 0.0, 0.0])), p_hat=np.full(3, 50.0))),
        (keys.stats(run, "agent", 4), wire.encode("stats", 3, 10**6, 9.0, inc=SPOOF_INC, role="agent", counters={"steps": 424242, "final": True, "links": {"1->3": {"delivered": 0, "dropped": 10**6, "reordered": 0}}})),
        (keys.stats(run, "agent", 4), wire.encode("stats", 0, 10**6, 9.0, inc=SPOOF_INC, role="world", counters={"late": 999999, "final": True})),
    ]
    with zenoh.open(zenoh_config("client", connect=[ep], secure=(str(certs), "agent-4"))) as s:
        spoof, own = s.declare_publisher(keys.edge(run, 3, 4)), s.declare_publisher(keys.edge(run, 4, 5))
        for k in range(200):
            spoof.put(_edge(3, 10**6 + k, SPOOF_INC))
            own.put(_edge(4, 10**6 + k, OWN_INC))
            if k % 50 == 0:
                for key, payload in forged:
                    s.put(key, payload)
            time.sleep(0.005)
    # Least privilege (issue 50): agent 4's certificate subscribes to the whole run and to keys
    # one by one; it gets its own sensor packets and the edges into it (the subscriptions of
    # its role), and nothing of the truth, of agent 3's sensors or of any estimate.
    got: dict[str, int] = {}
    with zenoh.open(zenoh_config("client", connect=[ep], secure=(str(certs), "agent-4"))) as s:
        subs = [s.declare_subscriber(k, lambda sample: got.__setitem__(str(sample.key_expr), got.get(str(sample.key_expr), 0) + 1)) for k in (f"{keys.ROOT}/{run}/**", keys.truth(run), keys.sense(run, 3), f"{keys.ROOT}/{run}/est/*", keys.sense(run, 4), keys.edges_into(run, 4))]
        time.sleep(2.0)
        for sub in subs:
            sub.undeclare()
    # 2 s of wall time at time scale 0.5: 100 sensor packets (100 Hz of world time) and 100 edge
    # messages expected; half of that proves the subscriptions work, whatever the machine's load.
    assert got.get(keys.sense(run, 4), 0) > 50 and got.get(keys.edge(run, 3, 4), 0) > 50, got
    assert not [k for k in got if k.split(f"/{run}/", 1)[1].split("/")[0] in ("truth", "est", "cmd", "stats") or k == keys.sense(run, 3)], got
    # zswarm echo and hz on the secured run through its results folder (the recorder's certificate).
    echo = subprocess.run(zswarm("echo", "est/5", "--results", str(out), "--count", "2"), capture_output=True, text=True, timeout=60)
    assert echo.returncode == 0, echo.stderr
    assert [json.loads(line)["message"]["src"] for line in echo.stdout.splitlines()] == [5, 5]
    hz = subprocess.run(zswarm("hz", "est/*", "--results", str(out), "--duration", "1", "--json"), capture_output=True, text=True, timeout=60)
    assert hz.returncode == 0, hz.stderr
    seen = set(json.loads(hz.stdout.splitlines()[-1])["keys"])
    assert {keys.est(run, i) for i in range(1, 9)} <= seen, seen
    assert p.wait(120) == 0, (tmp_path / "launcher.log").read_text()[-2000:]
    s = json.loads((out / "summary.json").read_text())
    # None of it was filed under agent 3 or the world: each is counted malformed (12 sent).
    a3, world = s["agents"]["3"], s["world"]
    assert a3["steps"] < 424242 and a3["alive_at_end"] and world.get("late", 0) < 999999, (a3, world)
    assert a3["position_error_final"] < 1.0 and s["links"]["1->3"]["dropped"] < 10**6, (a3, s["links"]["1->3"])
    # Counted, at most once each (a put may be dropped by Zenoh's congestion control when the
    # recorder lags, so not exactly 12 on a busy machine).
    assert 0 < s["malformed_in_recording"] <= 12, s["malformed_in_recording"]
    incs: dict[str, set[int]] = {}
    for stream, m, _ in read(ensure_recording(out, None)):
        if stream in ("edge/3/4", "edge/4/5"):
            e = m if isinstance(m, dict) else msgpack.unpackb(m)
            incs.setdefault(stream, set()).add(e["inc"])
    assert SPOOF_INC not in incs["edge/3/4"]  # not one spoofed message reached anyone
    assert s["links"]["3->4"].get("restarts", 0) == 0 and s["agents"]["4"]["malformed_received"] == 0
    # Its own key: delivered, and counted at agent 5 as a second sender on the link (an
    # incarnation older than agent 4's real one: never taken for agent 4's data).
    assert OWN_INC in incs["edge/4/5"] and s["links"]["4->5"].get("old_incarnation", 0) >= 1, s["links"]["4->5"]
    assert all(c == 0 for c in s["exit_codes"].values())
    assert not unconfirmed(out)  # the access control lets each ask for its own final stats, the recorder answer


def test_secure_router_started_by_hand(procs, tmp_path):
    """`zswarm certs` and `zswarm router --secure`: the profile without `zswarm run` (processes
    started by hand, on other hosts).  The router gives the rights of the certificates in
    its folder for its --run-id: agent 4 on its own key is delivered, as agent 3 it is not;
    a process without a certificate cannot connect."""
    certs, run = tmp_path / "certs", "byhand"
    made = procs.start(zswarm("certs", str(certs), T32, "--host", "10.9.8.7"), log=tmp_path / "certs.log")
    assert made.wait(60) == 0, (tmp_path / "certs.log").read_text()
    assert not (certs / "ca.key").exists()  # nothing more can be signed by this CA
    assert oct((certs / "agent-3.key").stat().st_mode & 0o777) == "0o600"
    ep = f"tls/127.0.0.1:{free_port()}"
    procs.start(zswarm("router", "--secure", str(certs), "--run-id", run, "--listen", ep), log=tmp_path / "router.log")
    wait_for(lambda: "mutual TLS" in (tmp_path / "router.log").read_text(), 60, "router up")

    conf = zenoh_config("client", connect=[ep])
    conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(certs / "ca.pem")))
    conf.insert_json5("connect/timeout_ms", "{router: -1, peer: -1, client: 3000}")
    with pytest.raises(zenoh.ZError):
        zenoh.open(conf).close()

    got: dict[str, set[int]] = {}
    with zenoh.open(zenoh_config("client", connect=[ep], secure=(str(certs), "recorder"))) as rec:

        def on(sample):
            got.setdefault(str(sample.key_expr), set()).add(msgpack.unpackb(sample.payload.to_bytes())["inc"])

        sub = rec.declare_subscriber(keys.everything(run), on)
        with zenoh.open(zenoh_config("client", connect=[ep], secure=(str(certs), "agent-4"))) as s:
            spoof, own = s.declare_publisher(keys.edge(run, 3, 4)), s.declare_publisher(keys.edge(run, 4, 5))
            # Until the subscriber's declaration has reached the router, puts go nowhere: wait
            # for its own key to arrive, then send both for the count.
            wait_for(lambda: (own.put(_edge(4, 0, OWN_INC)), keys.edge(run, 4, 5) in got)[1], 30, "own key delivered", step=0.1)
            for k in range(100):
                spoof.put(_edge(3, k, SPOOF_INC))
                own.put(_edge(4, k + 1, OWN_INC + 1))
            wait_for(lambda: OWN_INC + 1 in got[keys.edge(run, 4, 5)], 30, "the second batch delivered")
        sub.undeclare()
    assert keys.edge(run, 3, 4) not in got  # not one spoofed message delivered


def test_only_agent_i_certificate_declares_agent_i_token(procs, tmp_path):
    """Issue 50: under --secure a copied liveliness token hides nothing.  An insider with agent
    8's certificate re-declares every token it has seen (their secret tags included) and
    agents 3 and 8 are SIGKILLed.  The router's access control drops the copy of agent 3's
    token (not agent 8's certificate): everyone sees agent 3 go at once, its out-neighbour 4 by
    liveliness rather than by its silence.  Agent 8's own certificate may declare agent 8's
    token, so that copy stands and agent 8 is not seen to go: the control that shows the
    copies were declared and that the access control is what tells them apart (without
    --secure agent 3's copy stands too: test_processes.py)."""
    import os
    import signal

    out = tmp_path / "out"
    p = procs.start(zswarm("run", T32, "--duration", "10", "--out", str(out), "--quiet", "--no-plots", "--secure"), log=tmp_path / "launcher.log")
    kids = {c["name"]: c["pid"] for c in wait_for(lambda: procs.adopt(out), 60, "processes.json")}
    info = json.loads((out / "processes.json").read_text())
    ep, run, certs = info["router"]["endpoint"], info["run_id"], str(out / "secure")
    world_started(out)
    events: list[tuple[str, str]] = []  # (kind, role/id) of every liveliness sample

    def on(sample):
        events.append((str(sample.kind).rsplit(".", 1)[-1], "/".join(str(sample.key_expr).split("/alive/", 1)[1].split("/")[:2])))

    with zenoh.open(zenoh_config("client", connect=[ep], secure=(certs, "recorder"))) as watcher, zenoh.open(zenoh_config("client", connect=[ep], secure=(certs, "agent-8"))) as insider:
        seen: set[str] = set()
        watcher.liveliness().declare_subscriber(keys.alive_all(run), lambda sample: (seen.add(str(sample.key_expr)), on(sample)), history=True)
        # The 8 agents', the world's and the recorder's tokens.
        wait_for(lambda: len(seen) >= 10, 30, "every token seen", fail=lambda: sorted(seen))
        copies = [insider.liveliness().declare_token(k) for k in sorted(seen)]
        time.sleep(1.0)  # the copies reach the router (a round trip on localhost)
        os.kill(kids["agent-3"], signal.SIGKILL)
        os.kill(kids["agent-8"], signal.SIGKILL)
        # A killed process's TCP link closes at once: its tokens go when the router sees that
        # (the 1 s lease bounds it for a link that stays half-open); 10 s leaves room on a busy machine.
        wait_for(lambda: ("DELETE", "agent/3") in events, 10, "agent 3's token gone", fail=lambda: events[10:])
        time.sleep(2.0)  # twice the lease: had agent 8's token gone, it would be seen by now
        assert ("DELETE", "agent/8") not in events, events[10:]
        for c in copies:
            c.undeclare()
    assert p.wait(120) == 0, (tmp_path / "launcher.log").read_text()[-2000:]
    a4 = (out / "logs" / "agent-4.log").read_text()
    assert "in-neighbour 3 lost (liveliness)" in a4, a4[-2000:]
