"""The kinematic plant (De Carli et al. (1)) in a scenario: what the loader accepts and refuses."""

import re
from pathlib import Path

import numpy as np
import pytest

from world.node import World
from world.plant import KinematicPlant
from zswarm.scenario import ScenarioError, loads
from zswarm.scenario.programs import world_program
from zswarm.transport import keys, wire
from zswarm.transport.bus import MemoryBus

TOPO = Path(__file__).resolve().parents[2] / "topologies"


def _text():
    """§4.5's five-agent tree observer, on the kinematic plant without its rotating formation
    (its algorithm sends nothing, so the vehicles stay put: enough to exercise the loader
    and the world)."""
    text = (TOPO / "thesis-4.5-continuous5.toml").read_text()
    text = re.sub(r"(?m)^formation = .*\n", "", text)
    return text.replace("[world]\n", "[world]\nplant = \"kinematic\"\n", 1)


def test_a_kinematic_plant_refuses_prescribed_motions_and_non_yaw_attitudes():
    text = _text()
    with pytest.raises(ScenarioError, match=r"agents\[0\]\.omega: the kinematic plant moves each vehicle by its commands"):
        loads(text, "k.toml")
    no_omega = re.sub(r"(?m)^omega = .*\n", "", text)
    sc = loads(no_omega, "k.toml")
    assert sc.plant == "kinematic" and sc.moving
    assert loads(no_omega.replace("[[agents]]\n", '[[agents]]\nR = { angle = "0.3", axis = [0, 0, 1] }\n', 1), "k.toml").agents[0].R_matrix[2, 2] == 1.0
    tilted = no_omega.replace("[[agents]]\n", '[[agents]]\nR = { angle = "0.3", axis = [1, 0, 0] }\n', 1)
    with pytest.raises(ScenarioError, match=r"\.R: a vehicle of the kinematic plant has a yaw only"):
        loads(tilted, "k.toml")


def test_world_on_a_kinematic_plant_measures_relative_positions():
    """§3.2's eight agents (a directed leader-follower graph) on the kinematic plant: agent 3
    senses 1 and 2 (its neighbours) and is sensed by 4 and 7; ⁱp_ij goes only toward the
    robots it senses."""
    text = (TOPO / "thesis-3.2-fixed8.toml").read_text()
    text = re.sub(r"(?m)^omega = .*\n", "", text).replace("[world]\n", '[world]\nplant = "kinematic"\n', 1)
    sc = loads(text, "k.toml")
    assert sc.agent(3).neighbors == (1, 2) and set(sc.graph_neighbors(3)) == {1, 2, 4, 7}
    bus = MemoryBus()
    got = {}
    bus.subscribe(keys.sense("r", 3), lambda key, payload: got.setdefault("m", payload))
    w = World(world_program(sc, 1), bus, "r")
    w.sensing.sensors = {i: s | {"rel_pos"} for i, s in w.sensing.sensors.items()}  # this observer declares no rel_pos; fit it
    assert isinstance(w.motion, KinematicPlant)
    w.sample()  # MemoryBus delivers synchronously
    m = wire.decode(got["m"], "sense")
    a = sc.agent(3)
    R3 = np.array(a.R_matrix).reshape(3, 3)
    assert set(m["rel_pos"]) == {1, 2}
    for j, d in m["rel_pos"].items():
        assert np.allclose(d, R3.T @ (np.array(sc.agent(j).p) - np.array(a.p)), atol=1e-12)
