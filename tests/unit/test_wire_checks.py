"""The wire's checks in C (zswarm/math/_kernels.c f8_ok, idmap_ok) give the Python checks' verdicts
(zswarm/transport/message_checks.py) on every array a payload can carry, and a message decodes to
the same thing, or is refused with the same words, with or without them.

The C loops only say "passes"; on False the Python checks the array again and names the problem.
So the one way they could change what a receiver accepts is a True where the Python says no:
these tests look for one at the edges of every bound (±MAX_ABS, NaN and inf, |b| = 1 ± UNIT_TOL,
R^T R = I and det R = 1 ± ROT_TOL) and on everything that is not a decoded array.
"""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest

from zswarm.math import kernels
from zswarm.math.limits import MAX_ABS, ROT_TOL
from zswarm.math.so3 import exp
from zswarm.transport import message_checks as mc
from zswarm.transport import wire

NEEDED = "zswarm.math._kernels was not built (no C compiler at install?): pip install -e . with gcc"


def decoded(x) -> np.ndarray:
    """An array as a payload's decoding makes it: read-only, over bytes."""
    a = np.asarray(x, dtype=np.float64)
    return np.frombuffer(a.tobytes(), dtype=np.float64).reshape(a.shape)


def python_verdict(a: np.ndarray, check) -> bool:
    try:
        b = mc._fixed(a, a.shape, "x")
        mc._check_values(b, "x")
        if check is not None:
            check(b, "x")
    except mc.MessageError:
        return False
    return True


def near_unit(rng, n):
    """Unit vectors scaled to |b|² − 1 around ±2·UNIT_TOL, the bound, on both sides of it."""
    out = []
    for s in np.linspace(-3e-6, 3e-6, n):
        u = rng.normal(size=3)
        out.append(u / np.linalg.norm(u) * math.sqrt(1.0 + s))
    return out


def near_rotation(rng, n):
    """Rotations with one entry moved by around ±ROT_TOL, on both sides of the bound."""
    out = []
    for s in np.linspace(-2 * ROT_TOL, 2 * ROT_TOL, n):
        R = exp(rng.normal(size=3)).copy()
        R[rng.integers(3), rng.integers(3)] += s
        out.append(R)
    return out


def specials(shape):
    n = int(np.prod(shape))
    out = []
    for v in (np.nan, np.inf, -np.inf, MAX_ABS, -MAX_ABS, np.nextafter(MAX_ABS, np.inf), -np.nextafter(MAX_ABS, np.inf), 0.0, -0.0, 5e-324):
        for k in (0, n - 1):
            a = np.zeros(n)
            a[k] = v
            out.append(a.reshape(shape))
    return out


def test_one_array_gets_the_python_verdict():
    assert kernels.f8_ok is not None, NEEDED
    rng = np.random.default_rng(3)
    cases = (
        [(a, mc.CHECK_NONE, None, 3) for a in specials((3,)) + list(rng.normal(size=(50, 3)) * 10.0 ** rng.integers(-3, 14, size=(50, 1)))]
        + [(a, mc.CHECK_UNIT, mc._unit, 3) for a in near_unit(rng, 401) + specials((3,))]
        + [(a, mc.CHECK_ROTATION, mc._rotation, 9) for a in near_rotation(rng, 401) + specials((3, 3)) + [np.eye(3), -np.eye(3), np.diag([1.0, 1.0, -1.0])]]
    )
    both = set()
    for a, code, check, n in cases:
        want = python_verdict(decoded(a), check)
        assert mc.decoded_ok(decoded(a), n, code) == want, (a, code)
        both.add(want)
    assert both == {True, False}  # the cases lie on both sides of every bound


def test_anything_but_a_decoded_array_of_the_shape_is_left_to_the_python():
    assert kernels.f8_ok is not None, NEEDED
    good = np.array([0.6, 0.8, 0.0])
    for x in (good, good.tolist(), tuple(good), good.astype(np.float32), decoded(good).reshape(1, 3), decoded(np.eye(3)), memoryview(good.tobytes()), b"x" * 24, None, 1.0):
        assert not mc.decoded_ok(x, 3), x  # a sender's writable array, a list, another dtype or shape, not an array
    assert not mc.decoded_ok(decoded(np.eye(3))[:, :1].copy(), 9)
    assert not mc.decoded_ok(decoded(np.eye(3)).T, 9, mc.CHECK_ROTATION)  # not C-contiguous (a transposed view)
    assert mc.decoded_ok(decoded(good), 3, mc.CHECK_UNIT)


def test_id_maps_get_the_python_verdict():
    assert kernels.idmap_ok is not None, NEEDED
    u = decoded([0.6, 0.8, 0.0])
    for m in ({}, {0: u}, {mc.MAX_ID: u}, {j: u for j in range(mc.MAX_IDS)}):
        assert kernels.idmap_ok(m, 3, mc.CHECK_UNIT, MAX_ABS, mc.UNIT_TOL, mc.MAX_ID, mc.MAX_IDS)
        assert mc._id_map(m, "b", (3,), mc._unit) == m
    for m in ({True: u}, {-1: u}, {mc.MAX_ID + 1: u}, {2**80: u}, {"1": u}, {1.0: u}, {j: u for j in range(mc.MAX_IDS + 1)}, {1: np.array([0.6, 0.8, 0.0])}, {1: decoded([0.6, 0.8, 0.1])}, [(1, u)]):
        assert not kernels.idmap_ok(m, 3, mc.CHECK_UNIT, MAX_ABS, mc.UNIT_TOL, mc.MAX_ID, mc.MAX_IDS), m


def _python_only(monkeypatch) -> None:
    """Every check of a message in Python: the C checks of arrays, id maps, named values and of
    the envelope with a kind's fixed fields (messages.Msg.__post_init__) off."""
    monkeypatch.setattr(mc, "f8_ok", None)
    monkeypatch.setattr(mc, "idmap_ok", None)  # decoded_ok and _id_map then check in Python
    monkeypatch.setattr(mc, "named_decoded", None)
    monkeypatch.setattr(kernels, "fields_ok", None)


def _envelopes(kind: str) -> list[dict]:
    """A kind's ordinary payload with each envelope field (and t_local) at, inside and past its
    bound, of the right type and of others."""
    base = {"type": kind, "v": wire.VERSION, "src": 0 if kind == "sense" else 2, "seq": 1, "t": 0.5}
    if kind != "sense":
        base["t_local"] = 0.5
    if kind == "est":
        base |= {"R_hat": [[3, 3], np.eye(3).tobytes()], "p_hat": [[3], np.zeros(3).tobytes()]}
    elif kind == "sense":
        base |= {"gyro": [[3], np.zeros(3).tobytes()]}
    big = np.nextafter(MAX_ABS, np.inf)
    out = []
    for k, values in (("v", (wire.VERSION - 1, float(wire.VERSION), True)), ("src", (-1, mc.MAX_ID, mc.MAX_ID + 1, 2.0, True)),
                      ("seq", (0, mc.MAX_SEQ - 1, mc.MAX_SEQ, -1, 1.0)), ("inc", (0, mc.MAX_SEQ - 1, mc.MAX_SEQ, 2.5)),
                      ("t", (MAX_ABS, -MAX_ABS, big, -big, float("nan"), float("inf"), 3, True, "t")),
                      ("t_local", (MAX_ABS, big, float("nan"), 2, False))):  # fmt: skip
        if k == "t_local" and kind == "sense":
            continue
        out += [base | {k: x} for x in values]
    if kind == "est":
        out += [base | {"edges": {"xi": {1: 0.5}}}, base | {"jumps": [["xi", "edge", 1, 0.1, 0.0, 2.5]]}, base | {"values": {"sigma": 0.5}}, base | {"R_hat": None}]
    return out


@pytest.mark.parametrize("kind", ["sense", "edge", "est"])
def test_a_message_decodes_the_same_with_and_without_the_c_checks(kind, monkeypatch):
    """Hostile and ordinary payloads: the same message, or the same refusal, either way."""
    rng = np.random.default_rng(11)
    payloads = _envelopes(kind)
    for a in near_unit(rng, 60) + specials((3,)):
        arr = [[3], np.asarray(a, dtype="<f8").tobytes()]
        if kind == "sense":
            payloads.append({"type": "sense", "v": wire.VERSION, "src": 0, "seq": 1, "t": 0.5, "gyro": arr, "bearings": {2: arr, 3: [[3], decoded([0, 0, 1.0]).tobytes()]}})
            payloads.append({"type": "sense", "v": wire.VERSION, "src": 0, "seq": 1, "t": 0.5, "position": arr, "rel_pos": {2: arr}})
        elif kind == "edge":
            payloads.append({"type": "edge", "v": wire.VERSION, "src": 2, "seq": 1, "t": 0.5, "t_local": 0.5, "values": {"b": arr, "R_hat": [[3, 3], np.eye(3).tobytes()], "k": 1.5}})
        else:
            payloads.append({"type": "est", "v": wire.VERSION, "src": 2, "seq": 1, "t": 0.5, "t_local": 0.5, "p_hat": arr, "values": {"b": arr}})
    for R in near_rotation(rng, 40) + specials((3, 3)):
        arr = [[3, 3], np.asarray(R, dtype="<f8").tobytes()]
        if kind == "sense":
            payloads.append({"type": "sense", "v": wire.VERSION, "src": 0, "seq": 1, "t": 0.5, "attitude": arr, "rel_att": {4: arr}})
        elif kind == "edge":
            payloads.append({"type": "edge", "v": wire.VERSION, "src": 2, "seq": 1, "t": 0.5, "t_local": 0.5, "values": {"R_hat": arr}})
        else:
            payloads.append({"type": "est", "v": wire.VERSION, "src": 2, "seq": 1, "t": 0.5, "t_local": 0.5, "R_hat": arr})

    def outcomes():
        out = []
        for p in payloads:
            try:
                m = wire.decode(msgpack.packb(p), kind)
                out.append(("ok", wire.encode_message(m)))
            except wire.MessageError as exc:
                out.append(("refused", str(exc)))
        return out

    with_c = outcomes()
    _python_only(monkeypatch)
    without = outcomes()
    assert with_c == without
    assert {o for o, _ in with_c} == {"ok", "refused"}


def test_a_sender_builds_the_same_message_with_and_without_the_c_checks(monkeypatch):
    """A sender's arrays (writable, copied by the checks) of every kind an agent sends: the same
    message, or the same refusal, either way."""
    rng = np.random.default_rng(5)
    cases = []
    for a in near_unit(rng, 30) + specials((3,)):
        cases.append(("sense", dict(gyro=np.array(a), bearings={2: np.array(a), 3: np.array([0.0, 0.0, 1.0])})))
        cases.append(("edge", dict(t_local=0.5, b=np.array(a), k=1.5)))
        cases.append(("est", dict(t_local=0.5, p_hat=np.array(a), values={"sigma": np.array(a)})))
    for R in near_rotation(rng, 30) + specials((3, 3)):
        cases.append(("sense", dict(attitude=np.array(R), rel_att={4: np.array(R)})))
        cases.append(("est", dict(t_local=0.5, R_hat=np.array(R))))

    def outcomes():
        out = []
        for kind, fields in cases:
            try:
                out.append(("ok", wire.encode_message(wire.build(kind, 2, 1, 0.5, **fields))))
            except wire.MessageError as exc:
                out.append(("refused", str(exc)))
        return out

    with_c = outcomes()
    _python_only(monkeypatch)
    assert with_c == outcomes()
    assert {o for o, _ in with_c} == {"ok", "refused"}
