"""Issue 47, a composed scenario: each process is built from its own program
(zswarm.scenario.programs), composed from the scenario once, and sees nothing else of it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agent.runtime import AgentNode
from tests.conftest import TOPO
from world.node import World
from zswarm.scenario import load
from zswarm.scenario.clock import ClockSpec, ManualClock
from zswarm.scenario.expr import parse
from zswarm.scenario.programs import AgentProgram, Body, WorldProgram, agent_program, world_program
from zswarm.scenario.world_config import NoiseTable
from zswarm.transport import keys, wire
from zswarm.transport.bus import MemoryBus


def _feed(sc, bus, clock, node, t):
    """Agent 3 of the §3.2 scenario at rest, its in-neighbours 1 and 2 at their true poses."""
    p = {a.id: np.array(a.p) for a in sc.agents}
    bearings = {j: (p[j] - p[3]) / np.linalg.norm(p[j] - p[3]) for j in sc.graph_neighbors(3)}
    clock.set(t)
    bus.put(keys.sense("t", 3), wire.encode("sense", 0, round(t * 200), t, gyro=np.zeros(3), bearings=bearings))
    for j in (1, 2):
        bus.put(keys.edge("t", j, 3), wire.encode("edge", j, round(t * 200), t, t_local=t, R_hat=np.eye(3), p_hat=p[j], b=(p[3] - p[j]) / np.linalg.norm(p[3] - p[j])))
    node.tick(t)


def _estimates(program: AgentProgram) -> list[np.ndarray]:
    sc = load(TOPO / "thesis-3.2-fixed8.toml")
    bus, clock = MemoryBus(), ManualClock()
    node = AgentNode(program, bus, "t", now=clock.now)
    out = []
    bus.subscribe(keys.est("t", 3), lambda k, m: out.append(wire.decode(m)["R_hat"]))
    for k in range(20):
        _feed(sc, bus, clock, node, 0.005 * k)
    return out


def test_an_agent_runs_on_its_program_and_its_typed_gains():
    sc = load(TOPO / "thesis-3.2-fixed8.toml")
    program = agent_program(sc, 3, seed=1)
    # Typed: the algorithm's own Gains, with the scenario's values (not a mapping of names).
    assert type(program.gains) is program.algorithm.Gains and program.gains == program.algorithm.Gains(**{k: sc.agent(3).gains[k] for k in ("k_R", "k_p")})
    assert program.neighbors == sc.agent(3).neighbors and program.out_neighbors == sc.out_neighbors(3) and program.links is None
    same, again = _estimates(program), _estimates(agent_program(sc, 3, seed=1))
    assert len(same) == 20 and all(np.array_equal(a, b) for a, b in zip(same, again, strict=True))  # deterministic
    # A gain changed on the program alone (no scenario, no file) is what the agent runs: the
    # attitude law's correction scales with k_R (3.9), so 10x k_R moves R̂ further in 20 steps.
    # Bound: over 0.095 s the rate k_R·σ moves R̂ by ~k_R·|σ|·t, 10x for small motions; the
    # correction shrinks as R̂ nears the bearings' attitude (σ → 0), so the ratio stays below
    # 10 (measured 5.3): 2x is a lower bound that any k_R-proportional law exceeds here.
    faster = _estimates(dataclasses.replace(program, gains=dataclasses.replace(program.gains, k_R=10 * program.gains.k_R)))
    R0 = same[0]
    moved = [float(np.linalg.norm(x[-1] - R0)) for x in (same, faster)]
    assert moved[1] > 2 * moved[0] > 0


def test_an_agent_emulates_only_the_links_its_program_names():
    sc = load(TOPO / "thesis-3.2-fixed8.toml", [])
    lossy = dataclasses.replace(sc, links=dataclasses.replace(sc.links, drop=0.5))
    program = agent_program(lossy, 3, seed=1)
    assert program.links is not None and set(program.links) == {"world->3", "1->3", "2->3"}
    assert program.links["1->3"].drop == 0.5 and program.links["world->3"].drop == 0.0


def test_a_world_runs_on_a_program_made_by_hand():
    """No scenario at all: two bodies 2 m apart on x, at rest, the first one measuring a
    bearing toward the second and a gyro with a bias (noise-free)."""
    zero = (parse("0"), parse("0"), parse("0"))
    eye = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    bodies = (
        Body(1, eye, (0.0, 0.0, 0.0), zero, (0.01, 0.0, 0.0), sensors=frozenset({"gyro", "bearings"}), bearing_to=(2,)),
        Body(2, eye, (2.0, 0.0, 0.0), zero, (0.0, 0.0, 0.0), sensors=frozenset({"gyro"}), bearing_to=(1,)),
    )
    program = WorldProgram(bodies, "prescribed", 0.001, 200.0, NoiseTable(), seed=7)
    bus, got = MemoryBus(), {}
    bus.subscribe("zswarm/w/**", lambda k, m: got.setdefault(k, wire.decode(m)))
    world = World(program, bus, "w")
    assert world.sample() == 0.0 and world.period == 1 / 200
    s1, s2 = got[keys.sense("w", 1)], got[keys.sense("w", 2)]
    assert np.array_equal(s1["gyro"], [0.01, 0.0, 0.0]) and np.array_equal(s1["bearings"][2], [1.0, 0.0, 0.0])
    assert "bearings" not in s2 and np.array_equal(got[keys.truth("w")]["p"], [[0, 0, 0], [2, 0, 0]])


def test_the_world_program_carries_what_the_scenario_says():
    sc = load(TOPO / "thesis-3.2-fixed8.toml")
    w = world_program(sc, seed=3)
    assert w.ids == sc.ids and w.seed == 3 and w.step == sc.step and w.sensor_rate == sc.sensor_rate
    assert w.noise.gyro_var == sc.gyro_var and w.noise.bearing_var == sc.bearing_var
    for b in w.bodies:
        assert b.sensors == sc.sensors_of(b.id) and b.bearing_to == sc.graph_neighbors(b.id) and np.array_equal(b.R_matrix, sc.agent(b.id).R_matrix)
    assert set(w.command_links) == {f"{i}->world" for i in sc.ids}


def test_a_clock_of_its_own_comes_with_the_program():
    sc = load(TOPO / "thesis-3.2-fixed8.toml")
    program = dataclasses.replace(agent_program(sc, 3, seed=1), clock=ClockSpec(rate=50.0))
    node = AgentNode(program, MemoryBus(), "t", now=ManualClock().now)
    assert node.clock.first_tick(0.0) == 0.0 and node.clock.next_tick(0.0)[0] == pytest.approx(0.02)
