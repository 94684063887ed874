"""The viewer recording's JSON of a message (wire_json.to_json_bytes, msgspec's encoder on the
Struct) is the very bytes it was before (orjson of wire_json.to_json's dict), for every kind of
message the shipped schemes send: numbers written with the same shortest round-trip repr, ids as
string keys, fields in the same order, defaults left out, an open kind's values beside its fields."""

from pathlib import Path

import pytest

from zswarm.engines.sim import simulate
from zswarm.recording.mcap_io import _dumps
from zswarm.scenario import load
from zswarm.transport import wire, wire_json

TOPO = Path(__file__).resolve().parents[2] / "topologies"


@pytest.fixture(scope="module")
def messages(tmp_path_factory):
    out = []
    # §3.2 (sense with bearings, edges, est), §4.5 hybrid pose (ξ on est, jumps), §5.6 velocity-free
    # (commands, ζ), De Carli (kinematic truth with u, rel_pos, commands), §5.6 noisy (attitudes).
    for name in ("thesis-3.2-fixed8", "thesis-4.5-hybrid-pose5", "thesis-5.6-velocity-free7", "decarli-8-formation", "thesis-5.6-hybrid7-noisy"):
        got = simulate(load(TOPO / f"{name}.toml"), tmp_path_factory.mktemp(name), 0.6, seed=2, record=False)
        out += [(name, ch, p) for ch, p, _t in got]
    return out


def test_the_json_bytes_are_orjsons_of_to_json(messages):
    kinds = set()
    n = 0
    for name, ch, p in messages:
        if ch.startswith(("events", "ctl")):
            continue
        m = wire.decode(p)
        assert wire_json.to_json_bytes(m) == _dumps(wire_json.to_json(m)), (name, ch)
        kinds.add(m.type)
        n += 1
    assert kinds >= {"sense", "edge", "est", "truth", "stats", "cmd"}, kinds
    assert n > 1000
