"""One agent on MemoryBus with a manual clock."""

import numpy as np

from agent.runtime import AgentNode
from tests.conftest import TOPO
from zswarm import keys, so3, wire
from zswarm.bus import MemoryBus
from zswarm.clock import ManualClock
from zswarm.scenario import load


def setup():
    sc = load(TOPO / "thesis-3.2-fixed8.toml")
    bus = MemoryBus()
    clock = ManualClock()
    node = AgentNode(sc, 3, bus, "t", 1, now=clock.now)
    got = []
    bus.subscribe("zswarm/t/**", lambda k, p: got.append((k, p)))
    return sc, bus, clock, node, got


def sense_for(sc, i, t, R):
    p = {a.id: np.array(a.p) for a in sc.agents}
    bs = {j: R.T @ ((p[j] - p[i]) / np.linalg.norm(p[j] - p[i])) for j in sc.graph_neighbors(i)}
    return wire.encode("sense", 0, int(round(t * 200)), t, gyro=np.zeros(3), bearings=bs)


def test_agent_steps_and_publishes_its_out_edges_and_estimate():
    sc, bus, clock, node, got = setup()
    node.tick(0.0)
    assert got == []  # nothing measured yet: no step, nothing sent
    for t in (0.0, 0.01, 0.02):
        clock.set(t)
        bus.put(keys.sense("t", 3), sense_for(sc, 3, t, np.eye(3)))
        for j in (1, 2):
            Rj = np.eye(3)
            bus.put(keys.edge("t", j, 3), wire.encode("edge", j, int(t * 100), t, t_local=t, R_hat=Rj, p_hat=np.array(sc.agent(j).p), b=-(sc.agent(3).R_matrix.T @ np.zeros(3) + 0) + np.array([0, 0, 1.0])))
        node.tick(t)
    keys_seen = {k for k, _ in got}
    assert {keys.edge("t", 3, 4), keys.edge("t", 3, 7), keys.est("t", 3)} <= keys_seen
    est = [wire.decode(p) for k, p in got if k == keys.est("t", 3)]
    assert len(est) == 3 and est[-1]["t"] == 0.02
    # The estimate moved away from its initial value (the observer is running).
    R0 = so3.Ra(0.1 * np.pi, np.array([1.0, 0, 0]))
    assert not np.allclose(est[-1]["R_hat"], R0)
    c = node.counters()
    assert c["steps"] == 3 and c["links"]["world->3"]["delivered"] == 3 and c["links"]["1->3"]["delivered"] == 3


def test_malformed_and_foreign_messages_are_counted_and_dropped(caplog):
    sc, bus, clock, node, got = setup()
    bus.put(keys.sense("t", 3), b"\x00\x01garbage")
    bus.put(keys.sense("t", 3), b"\x00\x01garbage")
    bus.put(keys.edge("t", 1, 3), wire.encode("stop", 1, 0, 0.0, reason="x"))  # foreign type on an edge key
    bus.put("zswarm/t/edge/x/3", wire.encode("stop", 1, 0, 0.0, reason="x"))
    c = node.counters()
    assert c["malformed"] == 4
    assert node.inbox.get("world->3") is None
    # Logged once per key, not once per message.
    assert sum("malformed" in r.message for r in caplog.records) == 3
    # The node still works afterwards.
    bus.put(keys.sense("t", 3), sense_for(sc, 3, 0.0, np.eye(3)))
    node.tick(0.0)
    assert node.steps == 1
