import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from agent.algorithms import bearing_pose_fixed
from tests.conftest import examples
from zswarm.math import so3
from zswarm.transport import run_control, wire, wire_fast, wire_json

R = np.eye(3)
R2 = so3.exp(np.array([0.3, -1.2, 2.0]))
v = np.array([1.0, 2.0, 3.0])
u = v / np.linalg.norm(v)  # a bearing
CASES = {
    "sense": dict(gyro=v, bearings={1: u, 7: -u}, rel_att={2: R2, 4: R2.T}, velocity=v, velocity_body=-v, attitude=R2, position=v),
    "edge": dict(t_local=1.5, R_hat=R, p_hat=v, b=v, w=-v, xi=0.25),
    "est": dict(t_local=1.5, R_hat=R, p_hat=v, extra={"sigma": v, "U": 0.5}, xi={1: 0.25, 3: -0.5}, jumps=[(1, 0.01, 0.0, 0.25)], agent_jumps=[(3, 0.01, 0.0, 2.8)]),
    "cmd": dict(t_local=1.5, tau=-v),
    "truth": dict(ids=[1, 2], R=np.stack([R, R]), p=np.stack([v, v]), w=np.stack([v, v]), tau=np.stack([v, -v])),
    "stats": dict(role="agent", counters={"steps": 3, "links": {"1->3": {"delivered": 2}}}),
    "start": dict(epoch=1e9, time_scale=2.0, duration=40.0, seed=1, run="r1"),
    "stop": dict(reason="duration"),
    "progress": dict(duration=40.0),
}


def test_every_type_has_a_round_trip_case():
    assert set(CASES) == set(wire.SCHEMAS)


@pytest.mark.parametrize("mtype", sorted(CASES))
def test_round_trip(mtype):
    m = wire.decode(wire.encode(mtype, 3, 42, 1.25, **CASES[mtype]))
    assert (m["type"], m["src"], m["seq"], m["t"]) == (mtype, 3, 42, 1.25)
    for k, want in CASES[mtype].items():
        got = m[k]
        if isinstance(want, np.ndarray):
            assert np.array_equal(got, want)
        elif isinstance(want, dict) and want and any(isinstance(x, np.ndarray) for x in want.values()):
            assert set(got) == set(want) and all(np.array_equal(got[j], want[j]) for j in want)
        else:
            assert got == want


def _raw(**over):
    m = {"v": wire.VERSION, "type": "edge", "src": 1, "seq": 0, "inc": 0, "t": 0.0, "t_local": 0.0, "R_hat": [[3, 3], R.tobytes()], "p_hat": [[3], v.tobytes()], "b": [[3], v.tobytes()]}
    m.update(over)
    return msgpack.packb({k: x for k, x in m.items() if x is not None}, use_bin_type=True)


@pytest.mark.parametrize(
    "payload, match",
    [
        (b"\xc1garbage", "not msgpack"),
        (b"", "not msgpack"),
        (msgpack.packb([1, 2]), "not a map"),
        (_raw(v=1), "schema version"),
        (_raw(type="nope"), "unknown type"),
        (_raw(seq="x"), "seq"),
        (_raw(t=float("nan")), "t: expected a finite number"),
        (_raw(type="est", extra={}, jumps=[[1, 0.0, 0.0]]), "jumps: expected a list"),
        (_raw(type="est", extra={}, xi={"1": 0.2}), "xi: expected a map"),
        (_raw(type="sense", gyro=[[3], v.tobytes()], rel_att={2: [[3], v.tobytes()]}), r"rel_att\[2\]: bad shape"),
        (_raw(xi="x"), r"xi: expected a number or \[shape, bytes\]"),
        (_raw(R_hat=[[3, 3], b"\x00" * 8]), "R_hat: 8 bytes"),
        (_raw(p_hat=[[3], np.array([np.inf, 0, 0]).tobytes()]), "non-finite"),
        (_raw(p_hat=[[10**6], b""]), "p_hat: bad shape"),
        (_raw(**{f"f{n}": 1.0 for n in range(70)}), "at most 64"),
        (_raw(**{"x" * 100: 1.0}), "at most 64 characters"),
        (_raw(type="est", R_hat=None, extra={"s": [[2], b"\x00" * 8]}), r"extra.s: 8 bytes"),
    ],
)
def test_malformed_raises_message_error_only(payload, match):
    with pytest.raises(wire.MessageError, match=match):
        wire.decode(payload)


@pytest.mark.parametrize(
    "payload, match",
    [
        (_raw(p_hat=None), "'p_hat' missing"),
        (_raw(R_hat=[[4, 4], b"\x00" * 128]), r"'R_hat': shape \(4, 4\), expected \(3, 3\)"),
        (_raw(p_hat=5), r"'p_hat': shape \(\), expected \(3,\)"),
    ],
)
def test_edge_fields_are_checked_against_the_receivers_declaration(payload, match):
    """Edge messages are open at the wire level; the receiving agent checks what its
    algorithm declares it reads (SPEC.edge_in) and counts and drops the rest."""
    m = wire.decode(payload, "edge")
    with pytest.raises(ValueError, match=match):
        bearing_pose_fixed.SPEC.check_edge(m)


def test_wrong_type_for_key_rejected():
    with pytest.raises(wire.MessageError, match="where 'sense' was expected"):
        wire.decode(wire.encode("stop", 0, 0, 0.0, reason="x"), "sense")


# ---------------------------------------------------------------- JSON (recordings)


def _same(a, b):
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(a, b) and np.shape(a) == np.shape(b)
    if isinstance(a, dict):
        return isinstance(b, dict) and set(a) == set(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return a == b and type(a) is type(b)


@pytest.mark.parametrize("mtype", sorted(CASES))
def test_json_round_trip_is_exact_and_matches_its_schema(mtype):
    """from_json(to_json(m)) == m bit for bit (JSON floats are written in their
    shortest round-tripping form), and what to_json writes is valid under the
    type's JSON schema, checked by a generic validator."""
    import jsonschema
    import orjson

    rng = np.random.default_rng(7)
    # Vectors perturbed (every bit of the mantissa in play); rotations stay rotations.
    fields = {k: (v + rng.standard_normal(v.shape) / 3.0 if isinstance(v, np.ndarray) and v.shape[-2:] != (3, 3) else v) for k, v in CASES[mtype].items()}
    m = wire.decode(wire.encode(mtype, 3, 42, 1.0 / 3.0, **fields))
    text = orjson.dumps(wire_json.to_json(m), option=orjson.OPT_NON_STR_KEYS)
    obj = orjson.loads(text)
    jsonschema.validate(obj, wire_json.json_schema(mtype))
    assert _same(wire_json.from_json(obj), m)
    assert _same(wire.decode(wire_json.payload_from_json(obj)), m)


@pytest.mark.parametrize(
    "change, match",
    [
        ({"p_hat": [1.0, 2.0]}, r"p_hat: shape \(2,\)"),
        ({"p_hat": ["a", 1.0, 2.0]}, "p_hat: expected a .*array of numbers"),
        ({"p_hat": [1.0, None, 2.0]}, "p_hat: non-finite"),  # null reads as NaN, then fails the finiteness check
        ({"R_hat": [[1.0, 0.0], [0.0, 1.0, 0.0]]}, "R_hat: expected a .*array of numbers"),
        ({"xi": {"x": 0.2}}, "xi: expected a map keyed by id"),
        ({"xi": [0.2]}, "xi: expected a map keyed by id"),
        ({"extra": {"s": "text"}}, "extra.s: expected a .*array of numbers"),
        ({"type": "nope"}, "unknown type"),
        ({"v": 1}, "schema version"),
        ({"seq": 1.5}, "seq: expected an integer"),
    ],
)
def test_malformed_json_raises_message_error_only(change, match):
    obj = wire_json.to_json(wire.decode(wire.encode("est", 3, 1, 0.5, **CASES["est"])))
    obj.update(change)
    with pytest.raises(wire.MessageError, match=match):
        wire_json.from_json(obj)
    with pytest.raises(wire.MessageError):
        wire_json.payload_from_json(obj)


def test_json_of_a_non_map_is_rejected():
    for bad in ([1, 2], "x", None, 3):
        with pytest.raises(wire.MessageError, match="not a map"):
            wire_json.from_json(bad)


# ---------------------------------------------------------------- the receivers' fast decoder


def _identical(a, b):
    """Equal as decode's results must be for a receiver: types, key order, dtype, shape,
    bytes and the read-only flag of every array (views of one buffer or not)."""
    if isinstance(a, np.ndarray):
        return type(b) is np.ndarray and a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes() and a.flags.writeable == b.flags.writeable
    if isinstance(a, dict):
        return isinstance(b, dict) and list(a) == list(b) and all(_identical(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(_identical(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


EDGE_IN = {"R_hat": ((3, 3), False), "p_hat": ((3,), False), "b": ((3,), False), "vel": ((3,), True), "s": ((), True)}
DECODERS = {"sense": wire_fast.decoder("sense"), "edge": wire_fast.decoder("edge", EDGE_IN), "cmd": wire_fast.decoder("cmd", {"tau": ((3,), False)})}


def _outcome(dec, payload):
    """What a decoder makes of ``payload``: ('ok', message) or ('error', its message)."""
    try:
        return "ok", dec(payload)
    except wire.MessageError as exc:
        return "error", str(exc)


def _same_outcome(mtype, payload):
    got, want = _outcome(DECODERS[mtype], payload), _outcome(lambda p: wire.decode(p, mtype), payload)
    assert got[0] == want[0], (got, want)
    if got[0] == "error":
        assert got[1] == want[1]
    elif mtype == "sense":
        assert _identical(got[1], want[1])  # the schema's order
    else:  # an open type: the same fields, perhaps in another order
        assert _identical(dict(sorted(got[1].items())), dict(sorted(want[1].items())))


@pytest.mark.parametrize(
    "mtype, fields",
    [
        ("sense", CASES["sense"]),
        ("sense", dict(gyro=v, bearings={})),
        ("sense", dict(gyro=v, rel_pos={3: v}, velocity=v, velocity_body=v, attitude=R, position=v)),
        ("edge", dict(t_local=1.5, R_hat=R, p_hat=v, b=v)),
        ("edge", dict(b=v, p_hat=v, t_local=1, R_hat=R, vel=-v, s=2)),  # another order, an int, every optional field
        ("edge", dict(t_local=1.5, R_hat=R, p_hat=v, b=v, unexpected=v)),  # a field the receiver does not read
        ("edge", dict(t_local=1.5, R_hat=R, p_hat=v, b=v, s=v)),  # a declared number sent as an array
        ("edge", dict(t_local=1.5, R_hat=R, p_hat=v)),  # b missing: decode takes it, the receiver's check does not
        ("edge", dict(t_local=1.5, R_hat=np.eye(4), p_hat=v, b=v)),
        ("edge", dict(t_local=1.5, R_hat=R, p_hat=np.array([np.nan, 0.0, 0.0]), b=v)),
        ("edge", dict(t_local=1.5, R_hat=R, p_hat=np.array([1e308, 1e308, 0.0]), b=v)),  # finite; the fast sum overflows
        ("cmd", CASES["cmd"]),
        ("cmd", dict(t_local=0.0, tau=np.array([np.inf, 0.0, 0.0]))),
    ],
)
def test_fast_decoder_is_decode(mtype, fields):
    _same_outcome(mtype, wire.encode(mtype, 3, 42, 1.25, **fields))


def test_fast_decoder_is_decode_on_foreign_and_broken_payloads():
    ok = wire.encode("sense", 0, 1, 0.5, gyro=v, bearings={2: v})
    cases = [
        ok + b"\x00",  # trailing bytes
        ok[:-3],  # cut short
        _raw(),  # an edge message, on the sensor key
        msgpack.packb({"v": wire.VERSION, "type": "sense", "src": True, "seq": 0, "inc": 0, "t": 0.0}),
        msgpack.packb({"v": wire.VERSION, "type": "sense", "src": 0, "seq": 0, "inc": 0, "t": float("nan")}),
        msgpack.packb({"v": wire.VERSION, "type": "sense", "src": 0, "seq": 0, "inc": 0, "t": 0.0, "gyro": None}),
        msgpack.packb({"v": wire.VERSION, "type": "sense", "src": 0, "seq": 0, "inc": 0, "t": 0.0, "bearings": {True: [[3], v.tobytes()]}}),
        msgpack.packb({"v": wire.VERSION, "type": "sense", "src": 0, "seq": 0, "inc": 0, "t": 0.0, "gyro": [[3], v.tobytes()[:16]]}),
        msgpack.packb({"v": wire.VERSION, "type": "sense", "src": 0, "seq": 0, "inc": 0, "t": 0.0, "gyro": [(3,), v.tobytes(), 1]}),
        # the same key twice: msgpack keeps the last, and so must the fast path
        b"\x87" + b"".join(msgpack.packb(x) for x in ("v", wire.VERSION, "type", "sense", "src", 0, "seq", 0, "inc", 0, "t", 0.0, "src", 7)),
    ]
    for p in cases:
        _same_outcome("sense", p)


_floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
_vec = hnp.arrays(np.float64, st.sampled_from([(3,), (2,), (3, 3)]), elements=_floats)


@settings(max_examples=examples(300), deadline=None)
@given(_vec, st.dictionaries(st.integers(-3, 3), _vec, max_size=3), _floats, st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 255)), max_size=3))
def test_fast_decoder_property(g, bearings, t, flips):
    """Random messages and random byte mutations of valid ones: the fast decoder's outcome
    (the message, or the MessageError and its text) is decode's."""
    for mtype, fields in (("sense", dict(gyro=g, bearings=bearings)), ("edge", dict(t_local=t, R_hat=R, p_hat=g, b=v))):
        try:
            p = bytearray(wire.encode(mtype, 1, 2, 0.5, **fields))
        except (ValueError, TypeError):
            continue
        for at, byte in flips:
            p[at % len(p)] = byte
        _same_outcome(mtype, bytes(p))


# ---------------------------------------------------------------- the in-process bus's messages


def _message_is_decode_of_encode(mtype, fields, src=3, seq=42, t=1.25, inc=0):
    """``wire.message`` is what ``decode(encode(...))`` gives (types, key order, dtypes,
    shapes, bytes, read-only arrays), or, where decode refuses, the payload itself; an
    argument encode refuses is refused alike."""
    try:
        payload = wire.encode(mtype, src, seq, t, inc=inc, **fields)
    except Exception as exc:  # noqa: BLE001 - whatever encode raises, message raises too
        with pytest.raises(type(exc)):
            wire.message(mtype, src, seq, t, inc=inc, **fields)
        return
    got = wire.message(mtype, src, seq, t, inc=inc, **fields)
    try:
        want = wire.decode(payload, mtype)
    except wire.MessageError:
        assert got == payload, got
        return
    assert type(got) is wire.Message and _identical(dict(got), dict(want)), (got, want)


T3 = np.stack([R, R2, R2.T])


@pytest.mark.parametrize(
    "mtype, fields",
    [
        *CASES.items(),
        ("sense", dict(gyro=v, bearings={})),
        ("sense", dict(bearings={1: u, 2: -u, 3: u}, gyro=v)),  # another order than the schema's
        ("sense", dict(gyro=v, bearings={1: v})),  # not a unit bearing
        ("sense", dict(gyro=v, rel_att={2: 1.01 * R})),  # not a rotation
        ("sense", dict(gyro=v, attitude=np.eye(3)[:, [1, 0, 2]])),  # det −1
        ("sense", dict(gyro=np.array([1.0, 2.0]))),  # wrong shape
        ("sense", dict(gyro=np.array([1, 2, 3]))),  # integers: converted as encode does
        ("sense", dict(gyro=v, bearings={-1: u})),  # a negative id
        ("sense", dict(gyro=v, unknown=v)),  # not a field of sense
        ("sense", dict(gyro=np.array([1e13, 0.0, 0.0]))),  # over MAX_ABS
        ("edge", dict(b=v, p_hat=v, t_local=1, R_hat=R, vel=-v, s=2)),
        ("edge", dict(t_local=1.5, R_hat=R, p_hat=np.array([np.nan, 0.0, 0.0]), b=v)),
        ("edge", dict(t_local=1.5, R_hat=R, p_hat=np.array([1e308, 1e308, 0.0]), b=v)),
        ("edge", dict(t_local=1.5, big=np.zeros((2, 2, 2, 2, 2)))),  # 5 dimensions
        ("edge", dict(t_local=1.5, flag=True)),  # a bool is not a number here
        ("edge", dict(R_hat=R)),  # no t_local
        ("est", dict(t_local=1.5, R_hat=R2, p_hat=v)),
        ("est", dict(t_local=1.5, R_hat=2 * R, p_hat=v)),  # not a rotation
        ("est", dict(t_local=1.5, extra={"a": 1, "b": np.ones((2, 3))}, xi={}, jumps=[], agent_jumps=[])),
        ("cmd", dict(t_local=0.0, tau=np.array([np.inf, 0.0, 0.0]))),
        ("truth", dict(ids=[1, 2, 3], R=T3, p=np.ones((3, 3)), w=np.zeros((3, 3)))),
        ("truth", dict(ids=list(range(1, 11)), R=np.stack([R2] * 10), p=np.ones((10, 3)), w=np.zeros((10, 3)), u=np.zeros((10, 4)))),
        ("truth", dict(ids=[1, 2], R=T3, p=np.ones((3, 3)), w=np.zeros((3, 3)))),  # rows do not match ids
        ("truth", dict(ids=[1, 2, 3], R=np.stack([R, R2, 3 * R]), p=np.ones((3, 3)), w=np.zeros((3, 3)))),
    ],
)
def test_message_is_decode_of_encode(mtype, fields):
    _message_is_decode_of_encode(mtype, fields)


def test_the_usual_messages_take_the_short_path():
    """What the engines send every tick is built by ``_build``, not by the exact path (a
    field it no longer recognised would cost every message a second, slower validation
    without changing a result: test_message_is_decode_of_encode would not notice)."""
    for mtype in ("sense", "edge", "est", "cmd", "truth"):
        got = wire._build(mtype, 3, 42, 1.25, 0, CASES[mtype])
        assert _identical(dict(got), dict(wire.decode(wire.encode(mtype, 3, 42, 1.25, **CASES[mtype]), mtype))), mtype
    got = wire._build("edge", 3, 42, 1.25, 0, dict(b=v, t_local=1.0))
    assert list(got) == [*wire.ENVELOPE[1:], "t_local", "b"]  # decode's order: the schema's fields first


def test_message_envelope_edges():
    for src, seq, t, inc in ((0, 0, 0.0, 0), (wire.MAX_ID, wire.MAX_SEQ - 1, -1e12, 5), (-1, 0, 0.0, 0), (1, wire.MAX_SEQ, 0.0, 0), (True, 0, 0.0, 0), (1, 0, float("nan"), 0), (1, 0, 2e12, 0), (1, 0, 1, 0)):
        _message_is_decode_of_encode("sense", dict(gyro=v), src, seq, t, inc)


_rot_stacks = st.integers(1, 12).flatmap(lambda n: st.tuples(st.just(n), hnp.arrays(np.float64, (n, 3), elements=st.floats(-4, 4))))


@settings(max_examples=examples(200), deadline=None)
@given(_vec, st.dictionaries(st.integers(-3, 3), _vec, max_size=3), _floats, _rot_stacks, st.floats(0.0, 2e-6))
def test_message_property(g, bearings, t, rots, wobble):
    """Random sense, edge, est and truth fields: ``wire.message`` is decode(encode(...)),
    including rotations off by up to twice ROT_TOL and bearings off unit length."""
    n, axes = rots
    Rs = np.stack([so3.exp(a) for a in axes]) * (1.0 + wobble)
    with np.errstate(over="ignore", invalid="ignore"):  # huge draws: their norm overflows, and they stay as drawn
        unit = {j: b / nb * (1.0 + wobble) if b.shape == (3,) and np.isfinite(nb := np.linalg.norm(b)) and nb > 0 else b for j, b in bearings.items()}
    cases = [
        ("sense", dict(gyro=g, bearings=unit)),
        ("sense", dict(gyro=g, rel_att={j + 10: Rs[j % n] for j in range(3)}, attitude=Rs[0])),
        ("edge", dict(t_local=t, R_hat=Rs[0], p_hat=g, b=v)),
        ("est", dict(t_local=t, R_hat=Rs[-1], p_hat=g, extra={"x": g})),
        ("truth", dict(ids=list(range(1, n + 1)), R=Rs, p=np.zeros((n, 3)), w=np.zeros((n, 3)))),
    ]
    for mtype, fields in cases:
        _message_is_decode_of_encode(mtype, fields)


@pytest.mark.parametrize(
    "counters, match",
    [
        (5, "counters: expected a map"),  # wire-valid before: the report then raised TypeError after the run
        ({1: 2}, "keys must be names"),
        ({"a": {"b": {"c": {"d": {"e": {"f": {"g": 1}}}}}}}, "nested deeper than 6"),
        ({"a": list(range(15000)), "b": list(range(15000))}, "more than 20000 entries"),
        ({"a": "x" * 5000}, "more than 4096 characters"),
        ({"a": b"bytes"}, "expected a number, a string, a list or a map"),
    ],
)
def test_stats_counters_are_bounded(counters, match):
    payload = msgpack.packb({"v": wire.VERSION, "type": "stats", "src": 1, "seq": 0, "inc": 0, "t": 0.0, "role": "agent", "counters": counters}, use_bin_type=True)
    with pytest.raises(wire.MessageError, match=match):
        wire.decode(payload)
    with pytest.raises(wire.MessageError, match=match):
        wire_json.from_json({"v": wire.VERSION, "type": "stats", "src": 1, "seq": 0, "inc": 0, "t": 0.0, "role": "agent", "counters": counters})


def test_real_counters_pass():
    c = {"links": {"1->3": {"delivered": 10, "dropped": 0, "latency_p50_ms": 1.5}}, "final": True, "stale_policy": "hold after 0.2 s", "x": None, "l": [1, 2.5, "s"]}
    m = wire.decode(wire.encode("stats", 3, 0, 1.0, role="agent", counters=c))
    assert m["counters"] == c


def test_run_control_is_the_worlds_and_makes_sense():
    ok_stop = wire.encode("stop", 0, 0, 1.0, reason="duration")
    assert run_control.decode_ctl(ok_stop, "stop")["reason"] == "duration"
    start = {"epoch": 1.0, "time_scale": 0.5, "duration": 10.0, "seed": 1, "run": "r"}
    assert run_control.decode_ctl(wire.encode("start", 0, 0, 0.0, **start), "start")["time_scale"] == 0.5
    # Any payload on ctl/stop stopped every agent and the recorder; a start with time_scale 0
    # crashed the agents.
    for payload, match in (
        (b"anything", "not msgpack"),
        (wire.encode("stop", 3, 0, 1.0, reason="x"), "only the world"),
        (wire.encode("progress", 0, 0, 1.0, duration=3.0), "where .stop. was expected"),
        (wire.encode("start", 0, 0, 0.0, **{**start, "time_scale": 0.0}), "time_scale must be > 0"),
        (wire.encode("start", 0, 0, 0.0, **{**start, "duration": -1.0}), "duration must be > 0"),
    ):
        with pytest.raises(wire.MessageError, match=match):
            run_control.decode_ctl(payload, "start" if b"start" in payload else "stop")


def test_the_recorder_stops_only_on_the_worlds_stop():
    from zswarm.recording.capture import Recorder
    from zswarm.transport.bus import MemoryBus

    bus = MemoryBus()
    rec = Recorder(bus, "t", None)
    for junk in (b"x", wire.encode("stop", 5, 0, 1.0, reason="spoof")):
        bus.put("zswarm/t/ctl/stop", junk)
    assert not rec.stopped.is_set()
    bus.put("zswarm/t/ctl/stop", wire.encode("stop", 0, 0, 1.0, reason="duration"))
    assert rec.stopped.is_set()
    rec.close()


# ---------------------------------------------------------------- bounds on every field (issue 14)

BIG = np.array([1e13, 0.0, 0.0])  # finite, beyond MAX_ABS
NOT_ROT = np.diag([1.0, 1.0, 1.0 + 1e-5])  # |R^T R − I| = 2e-5 > ROT_TOL
REFLECT = np.diag([1.0, 1.0, -1.0])  # orthonormal, det −1


def _env(**over):
    """A raw sense message: the envelope and ``over``, as a hostile sender could write it."""
    m = {"v": wire.VERSION, "type": "sense", "src": 0, "seq": 0, "inc": 0, "t": 0.0}
    m.update(over)
    return msgpack.packb({k: x for k, x in m.items() if x is not None}, use_bin_type=True)


def _a(x):
    x = np.asarray(x, dtype=float)
    return [list(x.shape), x.tobytes()]


@pytest.mark.parametrize(
    "payload, match",
    [
        # Each of these decoded before: an agent got a gyro of 1e200 (so3.exp raised and killed
        # it), a reflection or a scaled matrix as an attitude, a bearing of length 10.
        (_env(gyro=_a([1e200, 0, 0])), "gyro: values beyond"),
        (_env(gyro=_a(BIG)), "gyro: values beyond"),
        (_env(t=1e13), "t: expected a finite number within"),
        (_env(attitude=_a(NOT_ROT)), "attitude: not a rotation"),
        (_env(attitude=_a(REFLECT)), "attitude: not a rotation"),
        (_env(rel_att={2: _a(np.eye(3)), 5: _a(2 * np.eye(3))}), "rel_att: not a rotation"),
        (_env(bearings={2: _a([0.0, 0.0, 10.0])}), "bearings: not a unit vector"),
        (_env(bearings={-1: _a([0.0, 0.0, 1.0])}), "bearings: expected a map of at most 4096 ids"),
        (_env(rel_pos={j: _a([0.0, 0.0, 1.0]) for j in range(5000)}), "rel_pos: expected a map of at most 4096 ids"),
        (_env(src=-1), "src: expected an integer in"),
        (_env(seq=2**63), r"seq: expected an integer in \[0, 2\*\*53\)"),
        (_env(seq=-5), "seq: expected an integer in"),
        (_env(inc=None), "inc: expected an integer"),
        (_env(inc=2**60), "inc: expected an integer"),
        (_env(type="est", t_local=0.0, R_hat=_a(NOT_ROT)), "R_hat: not a rotation"),
        (_env(type="est", t_local=0.0, xi={1: 1e300}), "xi: expected a map of at most 4096 ids to finite numbers"),
        (_env(type="est", t_local=0.0, jumps=[[1, 0.0, 0.0, 1e300]]), "jumps: expected a list"),
        (_env(type="est", t_local=0.0, extra={"s": 1e300}), "extra.s: expected a finite number within"),
        (_env(type="edge", t_local=0.0, p_hat=_a(BIG)), "p_hat: values beyond"),
        (_env(type="edge", t_local=1e300), "t_local: expected a finite number within"),
        (_env(type="cmd", t_local=0.0, tau=_a(np.full(100, 1e13))), "tau: values beyond"),  # the numpy path (> 32 elements)
        (_env(type="truth", ids=[1, 2], R=_a([np.eye(3)]), p=_a([[0, 0, 0]] * 2), w=_a([[0, 0, 0]] * 2)), "R: 1 rows for 2 ids"),
        (_env(type="truth", ids=[1, 1], R=_a([np.eye(3)] * 2), p=_a([[0, 0, 0]] * 2), w=_a([[0, 0, 0]] * 2)), "ids: repeated"),
        (_env(type="truth", ids=[1], R=_a([REFLECT]), p=_a([[0, 0, 0]]), w=_a([[0, 0, 0]])), "R: not a rotation"),
        (_env(type="stop", reason="x" * 5000), "reason: expected a string of at most 4096"),
        (_env(type="stats", role="agent", counters={"x": float("nan")}), r"counters.x: not finite"),
    ],
)
def test_every_field_is_bounded(payload, match):
    with pytest.raises(wire.MessageError, match=match):
        wire.decode(payload)
    if b"sense" in payload:
        _same_outcome("sense", payload)  # the fast path rejects it too (through decode)


def test_wire_bounds_pass_what_the_papers_produce():
    """The bounds' edges: a rotation off by 1e-7 (beyond anything a run accumulates, see
    ROT_TOL) and values of 1e12 still decode."""
    R_ok = np.diag([1.0, 1.0, 1.0 + 1e-7 / 2])  # |R^T R − I| = 1e-7
    m = wire.decode(_env(attitude=_a(R_ok), gyro=_a([1e12, -1e12, 0.0]), bearings={7: _a([0.0, 0.6, 0.8])}))
    assert m["gyro"][0] == 1e12 and set(m["bearings"]) == {7}
    _same_outcome("sense", _env(attitude=_a(R_ok), gyro=_a([1e12, -1e12, 0.0])))


def test_an_edge_rotation_field_is_checked_by_the_receiver():
    """Open edge fields: the receiver's declaration says R_hat is a rotation (Field.rotation)."""
    m = wire.decode(_raw(R_hat=_a(REFLECT)), "edge")
    with pytest.raises(ValueError, match="'R_hat': not a rotation"):
        bearing_pose_fixed.SPEC.check_edge(m)
    bearing_pose_fixed.SPEC.check_edge(wire.decode(_raw(R_hat=_a(R2)), "edge"))


def test_lengths_are_capped_before_anything_is_built():
    """A map of 100 000 entries took 0.3 s to unpack before its first check; msgpack now
    refuses any list or map longer than a process's counters may be, at its header (the
    reason names the header's limit, not a check made after building)."""
    payload = msgpack.packb({"v": wire.VERSION, "type": "sense", "src": 0, "seq": 0, "inc": 0, "t": 0.0, "bearings": {j: [[3], bytes(24)] for j in range(100_000)}})
    with pytest.raises(wire.MessageError, match="exceeds max_map_len"):
        wire.decode(payload)
