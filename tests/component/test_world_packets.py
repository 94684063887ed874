"""The world's sense packets in ``zswarm sim`` (world.node._sealed): the arrays a sample makes
are handed over read-only without a copy, so what a message holds must never change after it is
sent, whatever the world does next (its motion advancing in place, the next sample's noise)."""

import numpy as np
import pytest

from world.node import World
from zswarm.scenario import load
from zswarm.scenario.programs import world_program
from zswarm.transport.bus import MemoryBus

TOPO = __import__("pathlib").Path(__file__).resolve().parents[2] / "topologies"


def _arrays(m):
    for name in ("gyro", "velocity", "velocity_body", "attitude", "position"):
        v = getattr(m, name)
        if v is not None:
            yield name, v
    for name in ("bearings", "rel_att", "rel_pos"):
        for j, v in (getattr(m, name) or {}).items():
            yield f"{name}[{j}]", v


# Noise-free bearings (rows of the sample's bearing stack) and a prescribed motion; noisy
# attitudes, relative attitudes and gyros on a rigid-body plant; positions and relative
# positions on the kinematic plant (a view of the truth's positions).
@pytest.mark.parametrize("name", ["thesis-3.2-fixed8", "thesis-5.6-hybrid7-noisy", "decarli-8-formation", "thesis-3.3-moving5-noisy", "thesis-5.6-hybrid7", "thesis-5.6-velocity-free7"])
def test_a_sent_packet_never_changes_and_the_truth_stays_the_worlds(name):
    sc = load(TOPO / f"{name}.toml")
    bus = MemoryBus(objects=True)
    got = []
    bus.subscribe("**", lambda key, m: got.append(m))
    world = World(world_program(sc, 3), bus, "r", now=lambda: 0.0)
    for _ in range(3):
        world.sample()
    sent = [m for m in got if m.type == "sense"]
    assert sent
    frozen = [(m, [(n, v, v.copy()) for n, v in _arrays(m)]) for m in sent]
    assert any(arrays for _, arrays in frozen)
    for _m, arrays in frozen:
        for n, v, _ in arrays:
            assert not v.flags.writeable, n  # a message's arrays are read-only, sealed or copied
    for _ in range(200):  # the motion moves on in place, new noise is drawn
        world.sample()
    for _m, arrays in frozen:
        for n, v, before in arrays:
            assert np.array_equal(v, before), n
    # The world's own state was not sealed with them: it still advances (a rigid body's plant
    # writes its arrays in place).  (The formation's kinematic plant stands still without the
    # agents' commands.)
    truth = [m for m in got if m.type == "truth"]
    assert name.startswith("decarli") or not np.array_equal(truth[0].R, truth[-1].R)
