"""One agent on MemoryBus with a manual clock."""

import msgpack
import numpy as np
import pytest

from agent.runtime import AgentNode
from tests.conftest import TOPO
from zswarm.math import so3
from zswarm.scenario import load
from zswarm.scenario.clock import ManualClock
from zswarm.scenario.programs import agent_program
from zswarm.transport import keys, wire
from zswarm.transport.bus import MemoryBus


def setup():
    sc = load(TOPO / "thesis-3.2-fixed8.toml")
    bus = MemoryBus()
    clock = ManualClock()
    node = AgentNode(agent_program(sc, 3, 1), bus, "t", now=clock.now)
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


def test_edges_only_from_in_neighbours_and_only_with_their_own_src(caplog):
    """Any ``edge/<anything>/3`` used to be a link of its own (a counter and a stored
    message each, memory without bound), and any src was taken on any key."""
    _, bus, _, node, _ = setup()
    msg = {"t_local": 0.0, "R_hat": np.eye(3), "p_hat": np.zeros(3), "b": np.array([0, 0, 1.0])}
    for n in range(2000):
        bus.put(f"zswarm/t/edge/junk{n}/3", wire.encode("edge", 1, n, 0.0, **msg))
    bus.put(keys.edge("t", 5, 3), wire.encode("edge", 5, 0, 0.0, **msg))  # 5 is not an in-neighbour of 3
    bus.put(keys.edge("t", 1, 3), wire.encode("edge", 2, 0, 0.0, **msg))  # 2 claiming to be 1
    c = node.counters()
    assert c["malformed"] == 2002
    assert set(c["links"]) == set()  # nothing delivered: no link counter made
    assert len(node.inbox.recent) == 0
    assert sum("malformed" in r.message for r in caplog.records) <= 16  # logged for at most 16 keys
    bus.put(keys.edge("t", 1, 3), wire.encode("edge", 1, 0, 0.0, **msg))
    assert set(node.counters()["links"]) == {"1->3"}


def test_a_hostile_measurement_is_dropped_on_arrival(caplog):
    """A gyro of 1e200 (finite, so the decoder of the time took it) raised ValueError in
    so3.exp and killed the agent; it is beyond the wire's bound now: counted, dropped."""
    sc, bus, clock, node, got = setup()
    clock.set(0.0)
    bus.put(keys.sense("t", 3), sense_for(sc, 3, 0.0, np.eye(3)))
    node.tick(0.0)
    good = node.state
    clock.set(0.005)
    hostile = {j: np.array([0, 0, 1.0]) for j in (1, 2)}
    bus.put(keys.sense("t", 3), msgpack.packb({**msgpack.unpackb(wire.encode("sense", 0, 1, 0.005, bearings=hostile), strict_map_key=False), "gyro": [[3], np.array([1e200, 0.0, 0.0]).tobytes()]}))
    node.tick(0.005)
    assert node.state is good and node.counters()["malformed"] == 1 and node.step_failures == 0
    assert any("gyro: values beyond" in r.message for r in caplog.records)


def test_a_step_that_fails_keeps_the_last_good_state_and_the_agent_goes_on(caplog):
    """A step that raises (here a part made to raise, as a bug or an input the algorithm
    cannot take would) is counted and logged; the agent keeps its last good state over
    that interval and goes on."""
    import dataclasses

    sc, bus, clock, node, got = setup()
    msg = {"t_local": 0.0, "R_hat": np.eye(3), "b": np.array([0, 0, 1.0])}

    def feed(t):
        clock.set(t)
        bus.put(keys.sense("t", 3), sense_for(sc, 3, t, np.eye(3)))
        for j in (1, 2):
            bus.put(keys.edge("t", j, 3), wire.encode("edge", j, int(t * 1000), t, p_hat=np.array(sc.agent(j).p), **msg))

    for t in (0.0, 0.005):
        feed(t)
        node.tick(t)
    good = node.state
    ps = node.parts[0]
    part = ps.part

    def broken(*a):
        raise ValueError("math domain error")

    ps.part = dataclasses.replace(part, step=broken)
    feed(0.01)
    node.tick(0.01)
    assert node.state is good and node.step_failures == 1
    assert node.counters()["step_failures"] == 1
    assert any("a step failed" in r.message for r in caplog.records)
    ps.part = part
    for t in (0.015, 0.02):
        feed(t)
        node.tick(t)
    assert node.state is not good and node.step_failures == 1  # stepping again
    est = [wire.decode(p) for k, p in got if k == keys.est("t", 3)]
    assert [e["t"] for e in est][:2] == [0.0, 0.005] and est[-1]["t"] == 0.02  # nothing published from a failed step
    assert all(np.isfinite(e["R_hat"]).all() for e in est)


def _feed(bus, sc, clock, t, R=np.eye(3)):
    clock.set(t)
    bus.put(keys.sense("t", 3), sense_for(sc, 3, t, R))


def test_steps_end_at_the_newest_measurement_and_a_late_tick_catches_up_a_period_at_a_time():
    sc, bus, clock, node, got = setup()
    _feed(bus, sc, clock, 0.0)
    node.tick(0.0)
    ends = []
    orig = node._step_part
    node._step_part = lambda ps, dt: (ends.append((round(node.view.t, 6), round(dt, 6), round(node.view.sense_t, 6))), orig(ps, dt))[1]
    # Sensor packets every 5 ms up to 0.035 s, none after; the tick comes at 0.042 s
    # (a stalled process): one step per 10 ms period, each ending at a packet and
    # seeing that packet, the last at the newest packet, not at the tick.
    for k in range(1, 8):
        _feed(bus, sc, clock, 0.005 * k)
    clock.set(0.042)
    node.tick(0.042)
    assert ends == [(0.01, 0.01, 0.01), (0.02, 0.01, 0.02), (0.03, 0.01, 0.03), (0.035, 0.005, 0.035)]
    est = [wire.decode(p) for k, p in got if k == keys.est("t", 3)]
    assert est[-1]["t"] == 0.035 and est[-1]["t_local"] == 0.042  # stamped with its data's time, sent at the tick
    assert node.counters()["catch_up_steps"] == 3
    # No packet newer than the last step: the tick neither steps nor publishes.
    n = len(got)
    node.tick(0.05)
    assert len(got) == n and node.counters()["idle_ticks"] == 1
    # The world skipped 0.04–0.05: a step a period on ends between packets, on the older one.
    ends.clear()
    _feed(bus, sc, clock, 0.055)
    node.tick(0.06)
    assert ends == [(0.045, 0.01, 0.035), (0.055, 0.01, 0.055)]


def test_a_step_reads_the_newest_neighbour_message_at_or_before_its_time():
    sc, bus, clock, node, got = setup()
    for t in (0.0, 0.01):
        _feed(bus, sc, clock, t)
    for t in (0.0, 0.005, 0.015):  # neighbour 1's steps; the last is newer than our data
        bus.put(keys.edge("t", 1, 3), wire.encode("edge", 1, int(t * 1000), t, t_local=t, R_hat=np.eye(3), p_hat=np.zeros(3), b=np.array([0, 0, 1.0])))
    node.view.begin(0.01, 0.01, node.inbox.get("world->3"), first=False)
    m = node.view.neighbor(1)
    assert m.t_world == 0.005 and m.age == pytest.approx(0.005)
    node.view.begin(0.02, 0.02, node.inbox.get("world->3"), first=False)
    assert node.view.neighbor(1).t_world == 0.015


def test_emulated_links_stay_fifo_when_a_message_is_released_on_arrival():
    """A message whose drawn delay is 0 must not overtake one still held on the same link."""
    from zswarm.scenario.links import LinkModel

    class Scripted(LinkModel):
        releases = iter([0.004, 0.005])  # first held 4 ms, second released on arrival at 5 ms

        def admit(self, t_arrival):
            return next(self.releases)

    sc = load(TOPO / "thesis-3.2-fixed8.toml")
    bus, clock = MemoryBus(), ManualClock()
    node = AgentNode(agent_program(sc, 3, 1), bus, "t", now=clock.now)
    node.inbox._link_model = lambda name: Scripted(sc.link_spec(name), name, 1)
    _feed(bus, sc, clock, 0.0)
    _feed(bus, sc, clock, 0.005)
    node.inbox.drain()  # arrivals are processed when the agent reads its inbox (stamped on arrival)
    assert [p["t"] for p in node.inbox.packets] == [0.0, 0.005]
    assert node.inbox.get("world->3")["t"] == 0.005


def test_the_commands_lead_counts_the_agents_own_delay_and_none_on_catch_up_steps():
    """§5.6 agent 3: the torque is evaluated at the middle of its hold, ``command_lead`` after
    the step's end: the measurement's age at the tick, plus the command's way to the world
    (this agent's tick-to-put delay, measured, and the sensor packets' transit), plus half
    a period.  A catch-up step's torque is never sent: no lead."""
    sc = load(TOPO / "thesis-5.6-hybrid7.toml")
    bus, clock = MemoryBus(), ManualClock()
    busy = [0.0]  # how long a step takes: the clock moves on while the agent computes
    node = AgentNode(agent_program(sc, 3, 1), bus, "t", now=lambda: clock.now() + busy[0])
    leads = []
    orig = node._step_part
    node._step_part = lambda ps, dt: (leads.append(node.view.command_lead), busy.__setitem__(0, 0.002), orig(ps, dt))[2]
    transit, T = 0.003, 0.01

    def feed(t):  # sampled at t, arrives transit later
        clock.set(t + transit)
        busy[0] = 0.0
        rel = {j: np.eye(3) for j in sc.graph_neighbors(3)}
        bus.put(keys.sense("t", 3), wire.encode("sense", 0, round(t * 200), t, gyro=np.zeros(3), rel_att=rel))

    def tick(t):
        clock.set(t)
        busy[0] = 0.0
        node.tick(t)

    for k in range(6):
        feed(0.005 * k)
    tick(0.0295)  # the first step (prediction only: it sends no command)
    for k in range(6, 8):
        feed(0.005 * k)
    leads.clear()
    tick(0.0395)  # 1.5 ms after the newest packet's arrival; no tick-to-put delay measured yet
    assert leads == [pytest.approx(0.0395 - 0.035 + transit + 0.5 * T)]
    for k in range(8, 10):
        feed(0.005 * k)
    leads.clear()
    tick(0.0495)  # the last command was put 2 ms after its tick
    assert leads == [pytest.approx(0.0495 - 0.045 + 0.002 + transit + 0.5 * T)]
    for k in range(10, 15):
        feed(0.005 * k)
    leads.clear()
    tick(0.0795)  # behind: three steps (0.055, 0.065, 0.07); only the last one's torque is sent
    assert leads[:-1] == [0.0, 0.0] and leads[-1] == pytest.approx(0.0795 - 0.07 + 0.002 + transit + 0.5 * T)


def test_a_restarted_neighbour_is_used_at_once():
    """Neighbour 1 restarts (a new incarnation, seq from 0 again).  Its new messages are the
    newest at once; they used to be ignored until their seq passed the old one (on the
    README's §3.2 launch, agent 6 kept 5's pre-crash estimate for 17.7 s), and the link
    counted them as reordered."""
    sc, bus, clock, node, got = setup()
    b = np.array([0, 0, 1.0])

    def edge(seq, inc, t, R):
        return wire.encode("edge", 1, seq, t, inc=inc, t_local=t, R_hat=R, p_hat=np.array(sc.agent(1).p), b=b)

    R_old, R_new = so3.exp(np.array([0.0, 0.0, 0.5])), so3.exp(np.array([0.0, 0.3, 0.0]))
    for s in range(500):
        bus.put(keys.edge("t", 1, 3), edge(s, 1000, s * 0.01, R_old))
    bus.put(keys.edge("t", 1, 3), edge(0, 2000, 10.0, R_new))
    newest = node.inbox.get("1->3")
    assert newest["inc"] == 2000 and np.array_equal(newest["R_hat"], R_new)
    assert [m["inc"] for m in node.inbox.recent["1->3"]] == [2000]  # the dead incarnation's are gone
    link = node.counters()["links"]["1->3"]
    assert (link["delivered"], link["dropped"], link["reordered"], link["restarts"]) == (501, 0, 0, 1)


def test_the_inbox_is_bounded_under_a_flood():
    """A flood of arrivals between two ticks (junk or not) grew the agent's queue without bound
    (+26 MB): past MAX_PENDING waiting, an arrival is dropped and counted (inbox_overflow)."""
    from agent.inbox import MAX_PENDING

    sc, bus, clock, node, got = setup()
    junk = b"\x92" + b"\x00" * 1000
    for _ in range(MAX_PENDING + 1000):
        bus.put(keys.edge("t", 1, 3), junk)
    assert len(node.inbox._pending) == MAX_PENDING
    c = node.counters()  # drains what waited
    assert c["inbox_overflow"] == 1000 and c["malformed"] == MAX_PENDING
    bus.put(keys.sense("t", 3), sense_for(sc, 3, 0.0, np.eye(3)))
    node.tick(0.0)
    assert node.steps == 1 and not node.inbox._pending  # and it goes on


def _edge_from(sc, j, t):
    return wire.encode("edge", j, int(round(t * 100)), t, t_local=t, R_hat=np.eye(3), p_hat=np.array(sc.agent(j).p), b=np.array([0.0, 0.0, 1.0]))


def test_a_neighbour_silent_while_its_token_stands_is_lost_and_back_when_it_speaks(caplog):
    """Issue 50: a token is a key any peer can declare, its tag included; one that copied agent
    1's kept agent 1's death from agent 3.  Messages stamped with the run's time come only from
    a process that runs: 2 s (SILENT_S) without one, and the neighbour is lost; back when they
    come again.  Whatever the tokens say: here they are never touched."""
    from agent.runtime import SILENT_S

    caplog.set_level("INFO")
    sc, bus, clock, node, _got = setup()
    for t in np.arange(0.0, 1.0, 0.01):
        bus.put(keys.edge("t", 1, 3), _edge_from(sc, 1, float(t)))
        bus.put(keys.edge("t", 2, 3), _edge_from(sc, 2, float(t)))
    last = 0.99
    for t in (1.0, 2.0, last + SILENT_S):  # agent 1 says nothing more; agent 2 goes on
        bus.put(keys.edge("t", 2, 3), _edge_from(sc, 2, t))
        node.check_silent(t)
        assert 1 not in node.lost and 2 not in node.lost, (t, node.lost)  # quiet for at most SILENT_S
    t = last + SILENT_S + 0.01
    bus.put(keys.edge("t", 2, 3), _edge_from(sc, 2, t))
    node.check_silent(t)
    assert set(node.lost) == {1} and node.silent == {1}
    assert "in-neighbour 1 lost: silent for 2.0 s while its liveliness token is up" in caplog.text
    node.check_silent(t + 1.0)  # told once
    assert caplog.text.count("in-neighbour 1 lost") == 1
    bus.put(keys.edge("t", 1, 3), _edge_from(sc, 1, t + 1.5))
    node.check_silent(t + 1.5)
    assert node.lost == {} and node.silent == set() and "in-neighbour 1 is sending again" in caplog.text
    assert [(j, up) for j, _t, up in node.neighbor_events] == [(1, False), (1, True)]
    node.run_over = lambda: True  # at the run's end a silence is the end, not a loss
    node.check_silent(t + 10.0)
    assert node.lost == {}
