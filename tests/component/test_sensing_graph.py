"""A "sensing" graph (De Carli et al. §II): agents[].neighbors lists the robots each one senses
(directed); communication is the undirected counterpart.  The loader's checks, and what the
world and the runtime make of it."""

import textwrap

import pytest

from agent.runtime import AgentNode
from world.node import World
from zswarm.scenario import ScenarioError, load
from zswarm.scenario.programs import agent_program, world_program
from zswarm.transport import keys, wire
from zswarm.transport.bus import MemoryBus

MODULE = '''
from dataclasses import dataclass
from zswarm.scenario.algorithm import AlgorithmSpec, Field, Publish


@dataclass(frozen=True, slots=True)
class Gains:
    pass


@dataclass(frozen=True, slots=True)
class State:
    pass


def initial_state(init, gains):
    return State()


def publish(state, outputs, view):
    return Publish({j: {"x": 1.0} for j in view.out_neighbors}, {})


SPEC = AlgorithmSpec(
    description="test: a sensing-graph algorithm that only publishes",
    gains={},
    sensors=frozenset({"rel_pos"}),
    edge_in={"x": Field(())},
    edge_out={"x": Field(())},
    parts=(),
    graph="sensing",
)
'''


def _write(tmp_path, senses):
    """Four robots in a plane; ``senses[i]``: the robots robot i senses."""
    (tmp_path / "sensing_probe.py").write_text(MODULE)
    agents = "".join(
        f"\n[[agents]]\nid = {i}\np = [{i}.0, {i * i}.0, 0]\nneighbors = {list(senses[i])}\n" for i in sorted(senses)
    )
    text = textwrap.dedent(
        """
        [scenario]
        name = "sensing-probe"
        duration = 1.0
        seed = 1
        [algorithm]
        name = "sensing_probe"
        [world]
        plant = "kinematic"
        """
    ) + agents
    f = tmp_path / "probe.toml"
    f.write_text(text)
    return f


def test_the_loader_checks_the_sensing_graph(tmp_path):
    ok = load(_write(tmp_path, {1: (2,), 2: (3,), 3: (1, 4), 4: ()}))
    # communication both ways along every sensing edge; the sensed robots are kept apart
    assert ok.agent(4).neighbors == (3,) and ok.agent(4).senses == () and ok.sensed(4) == ()
    assert ok.agent(3).neighbors == (1, 2, 4) and ok.sensed(3) == (1, 4)
    assert ok.agent(1).neighbors == (2, 3) and ok.out_neighbors(1) == (2, 3)
    with pytest.raises(ScenarioError, match=r"agents\[3\]\.neighbors: robot 4 has no sensing edge"):
        load(_write(tmp_path, {1: (2,), 2: (3,), 3: (1,), 4: ()}))
    with pytest.raises(ScenarioError, match=r"the sensing graph's undirected version is disconnected: \[1, 2\] do not reach \[3, 4\]"):
        load(_write(tmp_path, {1: (2,), 2: (), 3: (4,), 4: ()}))
    with pytest.raises(ScenarioError, match=r"agents\[1\]\.neighbors: agent 2 cannot sense itself"):
        load(_write(tmp_path, {1: (2,), 2: (2, 3), 3: (4,), 4: ()}))
    with pytest.raises(ScenarioError, match=r"agents\[0\]\.neighbors: unknown agent 9"):
        load(_write(tmp_path, {1: (9,), 2: (3,), 3: (4,), 4: (1,)}))


def test_world_senses_along_the_directed_edges_and_agents_talk_both_ways(tmp_path):
    sc = load(_write(tmp_path, {1: (2,), 2: (3,), 3: (1, 4), 4: ()}))
    bus = MemoryBus()
    got = {}
    for i in sc.ids:
        bus.subscribe(keys.sense("r", i), lambda key, payload, i=i: got.setdefault(i, wire.decode(payload, "sense")))
    World(world_program(sc, 1), bus, "r").sample()
    assert {i: set(m["rel_pos"]) for i, m in got.items()} == {1: {2}, 2: {3}, 3: {1, 4}, 4: set()}
    node = AgentNode(agent_program(sc, 4, 1), bus, "r", now=lambda: 0.0)
    assert node.view.senses == () and node.view.neighbors == (3,) and node.out == (3,)
