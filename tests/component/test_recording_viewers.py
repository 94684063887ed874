"""A recording is what Foxglove and Lichtblick open: every channel decodes with a
generic reader (the ``mcap`` reader, ``mcap-protobuf-support``'s decoder factory,
and a JSON decoder that validates each message against its channel's JSON
schema with ``jsonschema``), none of zswarm's own code.

The values are then checked against the report, which reads the same run
through zswarm's code: the two must tell the same story.
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from mcap.decoder import DecoderFactory as McapDecoderFactory
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory

from tests.conftest import TOPO
from zswarm.engines.sim import simulate
from zswarm.report import errors, load_recording
from zswarm.results import make_report
from zswarm.scenario import load


class JsonSchemaDecoderFactory(McapDecoderFactory):
    """JSON messages, each validated against its channel's JSON schema (Draft 2020-12)."""

    def __init__(self) -> None:
        self.validated = 0

    def decoder_for(self, message_encoding, schema):
        if message_encoding != "json":
            return None
        assert schema is not None and schema.encoding == "jsonschema" and schema.data, "a JSON channel without a JSON schema"
        js = json.loads(schema.data)
        jsonschema.Draft202012Validator.check_schema(js)
        validator = jsonschema.Draft202012Validator(js)

        def decode(data: bytes):
            obj = json.loads(data)
            validator.validate(obj)
            self.validated += 1
            return obj

        return decode


def read_generic(path: Path):
    """Every message of the file as ``(topic, schema name, log_time, decoded)``; the metadata."""
    js = JsonSchemaDecoderFactory()
    out = []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[ProtobufDecoderFactory(), js])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            assert schema is not None, f"{channel.topic}: no schema"
            assert channel.message_encoding in ("json", "protobuf"), channel.message_encoding
            out.append((channel.topic, schema.name, message.log_time, decoded))
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    assert js.validated == sum(1 for m in out if isinstance(m[3], dict))
    return out, meta


def run(tmp: Path, name: str, duration: float):
    sc = load(TOPO / f"{name}.toml")
    simulate(sc, tmp, duration, sc.seed)
    summary = make_report(tmp, sc, "sim", duration, 0.0, sc.seed, plots=False)
    msgs, meta = read_generic(tmp / "recording.mcap")
    by_topic = defaultdict(list)
    for topic, schema, t, m in msgs:
        by_topic[topic].append((schema, t, m))
    return sc, summary, by_topic, meta


@pytest.fixture(scope="module")
def fixed8(tmp_path_factory):
    return run(tmp_path_factory.mktemp("fixed8"), "thesis-3.2-fixed8", 2.0)


def test_every_channel_decodes_and_the_viewer_channels_are_there(fixed8):
    sc, _summary, by_topic, meta = fixed8
    n = len(sc.ids)
    assert {s for s, _, _ in by_topic["/tf"]} == {"foxglove.FrameTransforms"}
    assert {s for s, _, _ in by_topic["/scene"]} == {"foxglove.SceneUpdate"}
    for i in sc.ids:
        for topic in (f"/est/{i}", f"/sense/{i}", f"/errors/{i}", f"/stats/agent/{i}"):
            assert by_topic[topic], f"no {topic}"
    assert {s for s, _, _ in by_topic["/truth"]} == {"zswarm.truth"}
    assert {s for s, _, _ in by_topic["/errors/3"]} == {"zswarm.AgentErrors"}
    assert any(t.startswith("/edge/") for t in by_topic)
    assert any(t.startswith("/links/") for t in by_topic)
    assert len(by_topic["/events/alive"]) >= n + 1
    assert "/events/malformed" not in by_topic
    # Stated: sim log times are world time.
    assert meta["zswarm"]["engine"] == "sim" and meta["zswarm"]["log_time"].startswith("world time")
    for _, t, m in by_topic["/truth"]:
        assert t == round(m["t"] * 1e9)


def test_frames_are_the_true_and_estimated_poses(fixed8):
    """/tf holds world → agent_i at the truth's pose and world → agent_i_est at the
    estimate's: translation equal to the float, rotation the same matrix (the
    quaternion rebuilt to 1e-12, the rounding of a 3×3 product)."""
    from scipy.spatial.transform import Rotation

    sc, _summary, by_topic, _meta = fixed8
    truth = {t: m for _, t, m in by_topic["/truth"]}
    est = {(m["src"], t): m for i in sc.ids for _, t, m in by_topic[f"/est/{i}"]}
    children = set()
    checked = 0
    for _, t, tf in by_topic["/tf"]:
        for x in tf.transforms:
            children.add(x.child_frame_id)
            assert x.parent_frame_id == "world"
            assert x.timestamp.seconds * 10**9 + x.timestamp.nanos == t
            q = [x.rotation.x, x.rotation.y, x.rotation.z, x.rotation.w]
            p = [x.translation.x, x.translation.y, x.translation.z]
            i = int(x.child_frame_id.split("_")[1])
            if x.child_frame_id.endswith("_est"):
                m = est[(i, t)]
                R, pos = np.array(m["R_hat"]), np.array(m["p_hat"])
            else:
                m = truth[t]
                k = m["ids"].index(i)
                R, pos = np.array(m["R"][k]), np.array(m["p"][k])
            assert np.array_equal(p, pos)
            assert np.max(np.abs(Rotation.from_quat(q).as_matrix() - R)) < 1e-12
            checked += 1
    assert children == {f"agent_{i}" for i in sc.ids} | {f"agent_{i}_est" for i in sc.ids}
    assert checked > 2 * len(sc.ids) * 50  # 50 Hz of world time over 2 s, true and estimated


def test_scene_shows_every_agent_and_every_edge(fixed8):
    sc, _summary, by_topic, _meta = fixed8
    edges = sum(len(a.neighbors) for a in sc.agents)
    for _, _t, upd in by_topic["/scene"][1:]:
        ids = {e.id for e in upd.entities}
        assert {f"agent_{i}" for i in sc.ids} | {f"agent_{i}_est" for i in sc.ids} | {"edges"} == ids
        (lines,) = next(e for e in upd.entities if e.id == "edges").lines
        assert len(lines.points) == 2 * edges
    assert len(by_topic["/scene"]) == pytest.approx(2.0 * 10, abs=1)  # 10 Hz of world time


def test_error_channels_agree_with_the_report(fixed8, tmp_path_factory):
    """/errors/<i> is computed while recording, from the truth samples around each
    estimate; the report computes it afterwards from the whole recording with the
    same formulas (3.15). Same times, same values up to the rounding of exp vs exp_batch."""
    sc, _summary, by_topic, _meta = fixed8
    rep = errors(load_recording(next(Path(p) for p in tmp_path_factory.getbasetemp().glob("fixed8*")) / "recording.mcap"))
    for i in sc.ids:
        live = np.array([(m["t"], m["attitude"], m["position"], m["position_direct"]) for _, _, m in by_topic[f"/errors/{i}"]])
        assert live.shape == rep[i].shape, i
        assert np.array_equal(live[:, 0], rep[i][:, 0])
        # |R̃|_I = sqrt((3 − tr R̃)/4): a rounding of tr (a few ulps of 3, < 1e-15) moves
        # it by up to sqrt(1e-15/4) ≈ 1.6e-8 near 0, so compare the squares; positions directly.
        assert np.max(np.abs(live[:, 1] ** 2 - rep[i][:, 1] ** 2)) < 1e-15
        assert np.max(np.abs(live[:, 2:] - rep[i][:, 2:])) < 1e-12


def test_link_counters_are_the_agents_own(fixed8):
    sc, summary, by_topic, _meta = fixed8
    for topic, rows in by_topic.items():
        if topic.startswith("/links/"):
            last = rows[-1][2]
            src, dst = topic.removeprefix("/links/").split("_to_")
            assert last["link"] == f"{src}->{dst}"
            assert last["delivered"] == summary["links"][last["link"]]["delivered"]


def test_hybrid_variables_and_jumps(tmp_path):
    """§4.5 hybrid observer: ξ_k of every edge on /hybrid/<head>, every jump on
    /hybrid/jumps (as many as the report counts), relative errors per edge."""
    sc, summary, by_topic, _meta = run(tmp_path, "thesis-4.5-hybrid5", 1.0)
    for k, (h, tl) in enumerate(sc.oriented, start=1):
        assert any(f"xi_{k}" in m for _, _, m in by_topic[f"/hybrid/{h}"]), k
        rows = by_topic[f"/errors/edge/{h}_{tl}"]
        assert rows and all(0.0 <= m["attitude"] <= 1.0 for _, _, m in rows)
    jumps = [m for _, _, m in by_topic["/hybrid/jumps"]]
    assert jumps and len(jumps) == summary["jumps_total"]
    assert {m["variable"] for m in jumps} == {"xi"}


def test_zeta_and_commands(tmp_path):
    """§5.6 velocity-free law: ζ_i on /hybrid/<i>, torques on /cmd/<i> as plottable arrays."""
    sc, _summary, by_topic, _meta = run(tmp_path, "thesis-5.6-velocity-free7", 0.5)
    for i in sc.ids:
        rows = by_topic[f"/hybrid/{i}"]
        assert len(rows) > 10 and all("zeta" in m for _, _, m in rows[1:])  # the first estimate (t = 0) is published before any step
        cmds = by_topic[f"/cmd/{i}"]
        assert cmds and all(len(m["tau"]) == 3 for _, _, m in cmds)


def test_recordings_of_earlier_versions_still_report(tmp_path):
    """Results folders written before the JSON recording (msgpack payloads, topics without
    a leading slash) are still read: the same messages give the same Recording."""
    import msgpack
    from mcap.writer import Writer

    from zswarm.recording.capture import Recorder
    from zswarm.transport.bus import MemoryBus

    sc = load(TOPO / "thesis-3.2-fixed8.toml")
    msgs = simulate(sc, tmp_path, 0.5, sc.seed, record=False, objects=False)  # payloads as bytes, as old recordings held
    old = tmp_path / "old.mcap"
    with open(old, "wb") as f:
        w = Writer(f)
        w.start(profile="zswarm", library="zswarm")
        ids: dict[str, int] = {}
        for topic, payload, t in msgs:
            if topic not in ids:
                ids[topic] = w.register_channel(topic, "msgpack", 0)
            w.add_message(ids[topic], log_time=t, data=payload, publish_time=t)
        w.finish()
    assert all(isinstance(p, bytes) for _, p, _ in msgs) and msgpack.unpackb(msgs[-1][1]) is not None
    new = tmp_path / "new.mcap"
    rec = Recorder(MemoryBus(), "sim", new, now_ns=lambda: 0)
    for topic, payload, t in msgs:
        if topic == "events/alive":
            rec.out.alive(msgpack.unpackb(payload), t)
        else:
            rec.out.message(topic, payload, t)
    rec.close()
    a, b = load_recording(old), load_recording(new)
    assert np.array_equal(a.truth_t, b.truth_t) and np.array_equal(a.truth_R, b.truth_R)
    assert a.est.keys() == b.est.keys()
    for i in a.est:
        assert all(x[0] == y[0] and np.array_equal(x[1], y[1]) and np.array_equal(x[2], y[2]) for x, y in zip(a.est[i], b.est[i], strict=True))
    assert a.stats == b.stats and len(a.alive_events) == len(b.alive_events) > 0
