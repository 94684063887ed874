"""Message types on the wire: msgpack maps, validated on decode.

Every message is a map with ``v`` (schema version), ``type``, ``src``
(sender id), ``seq`` (per-key sequence number), ``inc`` (the sender process's
incarnation: a restarted process numbers its messages from 0 again under a new
one) and ``t`` (world time of the content, s) plus type-specific fields.  Arrays travel as ``[shape, bytes]``
with raw little-endian float64 data.  :func:`decode` checks everything and
raises :class:`MessageError` (never anything else) on a malformed message.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import msgpack
import numpy as np

from zswarm.math.limits import MAX_ABS, ROT_TOL  # (ROT_TOL: see _check_semantic)
from zswarm.math.so3 import _rotation_ok, rotations_ok
from zswarm.transport import keys
from zswarm.transport.wire_schema import (  # the types and bounds, which users read as wire.X
    _F8,
    _FIELDS,
    _MISSING,
    _OPTIONAL_OF,
    ENVELOPE,
    MAX_COUNTER_ITEMS,
    MAX_ID,
    MAX_IDS,
    MAX_OPEN,
    MAX_SEQ,
    MAX_VALUE_LEN,
    OPEN,
    SCHEMAS,
    UNIT_TOL,
    VERSION,
    Message,
    MessageError,
    _arr,
    _dec_value,
    _enc_value,
    _finite,
    _id,
    _Slow,
)


def encode(mtype: str, src: int, seq: int, t: float, *, inc: int = 0, **fields: Any) -> bytes:
    """Encode a message of type ``mtype`` from incarnation ``inc`` of ``src``; arrays may be numpy arrays."""
    return msgpack.packb(_unpacked(mtype, src, seq, t, inc, fields), use_bin_type=True)  # type: ignore[no-any-return]


def message(mtype: str, src: int, seq: int, t: float, *, inc: int = 0, **fields: Any) -> Message | bytes:
    """What :func:`decode` makes of :func:`encode`'s payload for the same arguments, without
    the bytes: the message the in-process bus delivers (validated once, at the sender).
    A message :func:`decode` would refuse comes back as its payload, so that every receiver
    counts and drops it as it would the bytes.

    The usual messages take a short path (:func:`_build`: one copy of every array into
    one read-only buffer, one finiteness check, the semantic checks); anything it is not
    sure of takes the exact one, ``decode(encode(...))`` without the msgpack bytes.  The
    two give equal messages (tests/component/test_wire.py)."""
    if mtype in _BUILDABLE:
        try:
            return _build(mtype, src, seq, t, inc, fields)
        except Exception:  # noqa: BLE001 - _Slow, a conversion's TypeError, ...: the exact path decides
            pass
    m = _unpacked(mtype, src, seq, t, inc, fields)
    try:
        return _validate(m, mtype)
    except MessageError:
        return msgpack.packb(m, use_bin_type=True)  # type: ignore[no-any-return]


_BUILDABLE = frozenset({"sense", "edge", "est", "truth", "cmd"})
_F8_DTYPE = np.dtype(np.float64)


# _build's plan of a message: per field present, in decode's order (the schema's fields,
# then an open type's others as given), what to check: (name, code, shape, semantic).
_K_ARRAY, _K_MAP, _K_FLOAT, _K_VALUE, _K_FIELDS, _K_FLOATMAP, _K_JUMPS, _K_INTLIST = range(8)
_KIND_CODE = {"vecmap": _K_MAP, "matmap": _K_MAP, "float": _K_FLOAT, "value": _K_VALUE, "fields": _K_FIELDS, "floatmap": _K_FLOATMAP, "jumps": _K_JUMPS, "intlist": _K_INTLIST}
_Plan = tuple[tuple[str, int, tuple[int, ...], int], ...]
_PLANS: dict[tuple[str, tuple[str, ...]], _Plan | None] = {}
_MAX_PLANS = 4096  # distinct (type, field names) seen; past it plans are made per message


def _plan(mtype: str, names: tuple[str, ...]) -> _Plan | None:
    """The plan of a ``mtype`` message with fields ``names`` (None: the exact path decides)."""
    schema = SCHEMAS[mtype]
    given = set(names)
    if len(given) != len(names):
        return None
    if mtype in OPEN:
        if "t_local" not in given or len(names) > MAX_OPEN + 1 or any(len(k) > 64 for k in names):
            return None
    elif not schema.keys() >= given:
        return None  # encode raises KeyError: so does the exact path
    if any(k not in given and k not in _OPTIONAL_OF[mtype] for k in schema):
        return None  # missing: the exact path names it
    order = [k for k in schema if k in given] + [k for k in names if k not in schema]
    rot, unit = _ROTATION_FIELDS.get(mtype, ()), _UNIT_FIELDS.get(mtype, ())
    plan = []
    for k in order:
        kind = schema.get(k, "value")
        sem = 1 if k in rot else 2 if k in unit else 0
        if type(kind) is tuple:
            plan.append((k, _K_ARRAY, kind, sem))
        elif kind in _KIND_CODE:
            code = _KIND_CODE[kind]
            plan.append((k, code, ((3,) if kind == "vecmap" else (3, 3)) if code == _K_MAP else (), sem))
        else:
            return None
    return tuple(plan)


def _build(mtype: str, src: Any, seq: Any, t: Any, inc: Any, fields: Mapping[str, Any]) -> Message:
    """:func:`message`'s short path; raises (_Slow or a conversion's error) where unsure."""
    if not (type(src) is int and 0 <= src <= MAX_ID and type(seq) is int and 0 <= seq < MAX_SEQ and type(inc) is int and 0 <= inc < MAX_SEQ):
        raise _Slow
    t = float(t)
    if not -MAX_ABS <= t <= MAX_ABS:  # False for NaN
        raise _Slow
    key = (mtype, tuple(fields))
    if key in _PLANS:
        plan = _PLANS[key]
    else:
        plan = _plan(*key)
        if len(_PLANS) < _MAX_PLANS:
            _PLANS[key] = plan
    if plan is None:
        raise _Slow
    out = Message(type=mtype, src=src, seq=seq, inc=inc, t=t)
    bufs: list[bytes] = []
    places: list[tuple[dict[Any, Any], Any, int, tuple[int, ...]]] = []
    f8 = _F8_DTYPE
    # decode's semantic checks (_SEMANTIC), made on the values gathered below: rotations
    # and unit vectors as (offset of their first value, how many) in the buffer.
    rots: list[tuple[int, int]] = []
    units: list[tuple[int, int]] = []
    n_vals = 0
    for k, code, want, sem in plan:
        v = fields[k]
        if code == _K_ARRAY:
            if type(v) is not np.ndarray or v.dtype is not f8:
                raise _Slow
            shape = v.shape
            if shape != want and (len(shape) != len(want) or any(w != -1 and w != g for w, g in zip(want, shape, strict=True))):
                raise _Slow
            if sem:
                rots.append((n_vals, v.size // 9))
            bufs.append(v.tobytes())
            places.append((out, k, v.size, shape))
            n_vals += v.size
            out[k] = None  # its place in the message's order; the array below
        elif code == _K_MAP:
            if type(v) is not dict or len(v) > MAX_IDS:
                raise _Slow
            size = 3 if want == (3,) else 9
            sem_list = rots if sem == 1 else units if sem == 2 else None
            m: dict[int, Any] = {}
            for j, x in v.items():
                if type(j) is not int or not 0 <= j <= MAX_ID or type(x) is not np.ndarray or x.dtype is not f8 or x.shape != want:
                    raise _Slow
                if sem_list is not None:
                    sem_list.append((n_vals, 1))
                bufs.append(x.tobytes())
                places.append((m, j, size, want))
                n_vals += size
                m[j] = None
            out[k] = m
        elif code == _K_FLOAT:
            x = float(v)
            if not -MAX_ABS <= x <= MAX_ABS:
                raise _Slow
            out[k] = x
        elif code == _K_VALUE or code == _K_FIELDS:
            if code == _K_VALUE:
                items: Any = ((k, v),)
                d: dict[str, Any] = out
            else:
                if type(v) is not dict or len(v) > MAX_OPEN:
                    raise _Slow
                items = [(str(n), x) for n, x in v.items()]
                if len({n for n, _ in items}) != len(items) or any(len(n) > 64 for n, _ in items):
                    raise _Slow
                d = out[k] = {}
            for n, x in items:
                if type(x) is np.ndarray:
                    if x.dtype is not f8 or x.ndim > 4 or x.size > MAX_VALUE_LEN or max(x.shape, default=0) > MAX_VALUE_LEN:
                        raise _Slow
                    bufs.append(x.tobytes())
                    places.append((d, n, x.size, x.shape))
                    n_vals += x.size
                    d[n] = None
                elif isinstance(x, (int, float, np.floating)) and not isinstance(x, bool):
                    y = float(x)
                    if not -MAX_ABS <= y <= MAX_ABS:
                        raise _Slow
                    d[n] = y
                else:
                    raise _Slow
        elif code == _K_FLOATMAP:
            if type(v) is not dict or len(v) > MAX_IDS:
                raise _Slow
            fm: dict[int, float] = {}
            for j, x in v.items():
                y = float(x)
                if type(j) is not int or not 0 <= j <= MAX_ID or not -MAX_ABS <= y <= MAX_ABS:
                    raise _Slow
                fm[j] = y
            out[k] = fm
        elif code == _K_JUMPS:
            if type(v) is not list or len(v) > MAX_IDS or not all(len(e) == 4 for e in v):
                raise _Slow
            js = [(int(e[0]), float(e[1]), float(e[2]), float(e[3])) for e in v]
            if not all(0 <= e[0] <= MAX_ID and -MAX_ABS <= e[1] <= MAX_ABS and -MAX_ABS <= e[2] <= MAX_ABS and -MAX_ABS <= e[3] <= MAX_ABS for e in js):
                raise _Slow
            out[k] = js
        else:  # _K_INTLIST
            if type(v) is not list or len(v) > MAX_IDS or not all(map(_id, v)):
                raise _Slow
            out[k] = list(v)
    if bufs:
        # One buffer for every array: read-only views of it, as decode's arrays are.
        flat = np.frombuffer(b"".join(bufs), dtype=_F8)
        xs = flat.tolist()
        # A NaN or an infinity makes the sum non-finite; values within ±MAX_ABS (1e12) cannot
        # overflow it (that would take ~1e296 of them; a message holds at most ~3e5).
        if not math.isfinite(sum(xs)) or max(xs) > MAX_ABS or min(xs) < -MAX_ABS:
            raise _Slow
        o = 0
        for d_, k_, n_, shape_ in places:
            d_[k_] = flat[o : o + n_] if len(shape_) == 1 else flat[o : o + n_].reshape(shape_)
            o += n_
        # _rotations and _unit of decode, on the same values (rotations_ok takes one 3x3
        # matrix, or up to 8 of a stack, through _rotation_ok; more as numpy: left to it).
        for o, count in rots:
            if count > 8:
                if not rotations_ok(flat[o : o + 9 * count].reshape(count, 3, 3), ROT_TOL):
                    raise _Slow
            elif not all(_rotation_ok(xs[o + 9 * c : o + 9 * c + 9], ROT_TOL) for c in range(count)):
                raise _Slow
        for o, _ in units:
            x, y, z = xs[o : o + 3]
            if not abs(x * x + y * y + z * z - 1.0) <= 2 * UNIT_TOL:
                raise _Slow
    if mtype == "truth":
        _truth_rows(out)  # MessageError: the exact path decides
    return out


def encode_message(m: Message) -> bytes:
    """The payload of a decoded message (``decode(encode_message(m)) == m``): how a Message
    that travelled in-process is written to a raw recording."""
    schema = SCHEMAS[m["type"]]
    out: dict[str, Any] = {"v": VERSION}
    for k, v in m.items():
        kind = schema.get(k, "value" if k not in ENVELOPE else None)
        if kind == "value":
            out[k] = _enc_value(v)
        elif kind == "fields":
            out[k] = {n: _enc_value(x) for n, x in v.items()}
        elif isinstance(kind, tuple):
            out[k] = _arr(v)
        elif kind in ("vecmap", "matmap"):
            out[k] = {j: _arr(x) for j, x in v.items()}
        elif kind == "jumps":
            out[k] = [list(e) for e in v]
        else:
            out[k] = v
    return msgpack.packb(out, use_bin_type=True)  # type: ignore[no-any-return]


def _unpacked(mtype: str, src: int, seq: int, t: float, inc: int, fields: Mapping[str, Any]) -> dict[str, Any]:
    """The map :func:`encode` packs (what msgpack gives back of it: arrays as ``[shape, bytes]``)."""
    schema = SCHEMAS[mtype]
    m: dict[str, Any] = {"v": VERSION, "type": mtype, "src": src, "seq": seq, "inc": inc, "t": float(t)}
    for k, v in fields.items():
        kind = schema.get(k, "value" if mtype in OPEN else None)
        if kind is None:
            raise KeyError(f"{mtype}: unknown field {k!r}")
        if kind in ("value", "fields"):
            m[k] = _enc_value(v) if kind == "value" else {str(n): _enc_value(x) for n, x in v.items()}
        elif isinstance(kind, tuple):
            m[k] = _arr(v)
        elif kind in ("vecmap", "matmap"):
            m[k] = {int(j): _arr(x) for j, x in v.items()}
        elif kind == "floatmap":
            m[k] = {int(j): float(x) for j, x in v.items()}
        elif kind == "jumps":
            m[k] = [[int(e[0]), float(e[1]), float(e[2]), float(e[3])] for e in v]
        elif kind == "float":
            m[k] = float(v)
        else:
            m[k] = v
    return m


def check_stream(stream: str, m: Mapping[str, Any]) -> None:
    """A message belongs to the key it came on: ``est/i``, ``cmd/i`` carry ``src = i``,
    ``edge/j/i`` its tail ``src = j``, ``stats/<role>/<i>`` that role and ``src = i``, and
    ``truth``, ``sense/i`` and ``ctl/...`` the world's ``src = 0``.

    ``stream`` is the key without the run's prefix.  Raises :class:`MessageError` otherwise:
    the identity inside a message is the sender's word, the key is what the access control
    (``--secure``) checks, so a message is filed under its key's process or not at all (a
    peer holding agent 4's certificate put ``src = 3`` in ``est/4`` and the report filed it
    as agent 3's estimate).
    """
    k = keys.parse_stream(stream)
    if k is None or k.kind not in ("est", "cmd", "edge", "stats", "truth", "sense", "ctl"):
        raise MessageError(f"{stream!r} is not a zswarm stream (or not a process id in the key)")
    if m.get("src") != k.src:
        raise MessageError(f"src {m.get('src')!r} on {stream}, whose sender is {k.src}")
    if k.kind == "stats" and m.get("role") != k.role:
        raise MessageError(f"role {m.get('role')!r} on {stream}")


def decode(payload: bytes | Message, expect: str | tuple[str, ...] | None = None) -> dict[str, Any]:
    """Decode and validate; arrays come back as read-only float64 numpy arrays.

    Raises
    ------
    MessageError
        For anything that is not a well-formed message (of type ``expect``).
    """
    if type(payload) is Message:  # decoded and validated already (the in-process bus)
        _check_expect(payload["type"], expect)
        return payload
    try:
        # Lengths capped before anything is built: a 3 MB map of 100 000 entries took 0.3 s
        # to unpack before its first check (no message of a run has a list or map longer
        # than a process's counters).
        m = msgpack.unpackb(
            payload, raw=False, strict_map_key=False, max_bin_len=1 << 20, max_str_len=1 << 16, max_array_len=MAX_COUNTER_ITEMS, max_map_len=MAX_COUNTER_ITEMS
        )
    except Exception as exc:  # msgpack raises a zoo of types on garbage
        raise MessageError(f"not msgpack ({type(exc).__name__}{': ' + str(exc)[:80] if isinstance(exc, ValueError) and 'exceeds' in str(exc) else ''})") from None
    return _validate(m, expect)


def _check_expect(mtype: str, expect: str | tuple[str, ...] | None) -> None:
    """A message of type ``mtype`` where ``expect`` (a type, or any of several) was expected."""
    if expect is not None and mtype != expect and (isinstance(expect, str) or mtype not in expect):
        raise MessageError(f"type {mtype!r} where {expect!r} was expected")


def _validate(m: Any, expect: str | tuple[str, ...] | None) -> Message:
    """:func:`decode` after unpacking: ``m`` as msgpack gives it (arrays as ``[shape, bytes]``)."""
    if type(m) is not dict:
        raise MessageError("not a map")
    if m.get("v") != VERSION:
        raise MessageError(f"schema version {m.get('v')!r}, expected {VERSION}")
    mtype = m.get("type")
    fields = _FIELDS.get(mtype) if type(mtype) is str else None
    if fields is None:
        raise MessageError(f"unknown type {mtype!r}")
    _check_expect(str(mtype), expect)  # a str: a known type by now
    src, seq, inc, t = m.get("src"), m.get("seq"), m.get("inc"), m.get("t")
    if not _id(src):
        raise MessageError(f"src: expected an integer in [0, {MAX_ID}]")
    if type(seq) is not int or not 0 <= seq < MAX_SEQ:
        raise MessageError("seq: expected an integer in [0, 2**53)")
    if type(inc) is not int or not 0 <= inc < MAX_SEQ:
        raise MessageError("inc: expected an integer in [0, 2**53)")
    if not _finite(t):
        raise MessageError(f"t: expected a finite number within ±{MAX_ABS:g}")
    out = Message(type=mtype, src=src, seq=seq, inc=inc, t=float(t))
    for k, handle, optional in fields:
        v = m.get(k, _MISSING)
        if v is _MISSING:
            if optional:
                continue
            raise MessageError(f"{k}: missing")
        out[k] = handle(v, k)
    if mtype in OPEN:
        extra = [k for k in m if k not in out and k not in ENVELOPE]
        if len(extra) > MAX_OPEN:
            raise MessageError(f"{len(extra)} fields (at most {MAX_OPEN})")
        for k in extra:
            if type(k) is not str or len(k) > 64:
                raise MessageError("field names must be strings of at most 64 characters")
            out[k] = _dec_value(m[k], k)
    check = _SEMANTIC.get(mtype)
    if check is not None:
        check(out)
    return out


# What the fields mean, beyond their shapes: rotations are rotations, bearings unit
# vectors, the truth's arrays one row per id.  ROT_TOL: attitudes are products of
# exponentials (never re-orthonormalised); each product adds at most ~1e-16 to
# |R^T R − I|, so 1e9 of them (a 1e6 s run at 1 kHz) stay under 1e-6 — a matrix beyond
# that did not come from the world or an observer.
def _rotations(mats: Any, k: str) -> None:
    if not all(rotations_ok(R, ROT_TOL) for R in mats.values()) if isinstance(mats, dict) else not rotations_ok(mats, ROT_TOL):
        raise MessageError(f"{k}: not a rotation (R^T R = I, det R = 1 within {ROT_TOL:g})")


def _unit(vecs: dict[int, np.ndarray], k: str) -> None:
    for v in vecs.values():
        x, y, z = v.tolist()
        if not abs(x * x + y * y + z * z - 1.0) <= 2 * UNIT_TOL:  # |b|² − 1 ≈ 2(|b| − 1); False for NaN
            raise MessageError(f"{k}: not a unit vector (|b| = 1 within {UNIT_TOL:g})")


# The fields that hold rotations and unit bearings, per type, in the order they are checked
# (by _semantic here, and on the values it gathers by message()'s _build).
_ROTATION_FIELDS: Mapping[str, tuple[str, ...]] = {"sense": ("attitude", "rel_att"), "est": ("R_hat",), "truth": ("R",)}
_UNIT_FIELDS: Mapping[str, tuple[str, ...]] = {"sense": ("bearings",)}


def _truth_rows(m: dict[str, Any]) -> None:
    """A truth's ids are distinct and each of its arrays has a row per id."""
    ids = m["ids"]
    if len(set(ids)) != len(ids):
        raise MessageError("ids: repeated")
    for k in ("R", "p", "w", "tau", "u"):
        if k in m and m[k].shape[0] != len(ids):
            raise MessageError(f"{k}: {m[k].shape[0]} rows for {len(ids)} ids")


def _semantic(m: dict[str, Any]) -> None:
    mtype = m["type"]
    if mtype == "truth":
        _truth_rows(m)
    for k in _ROTATION_FIELDS.get(mtype, ()):
        if k in m:
            _rotations(m[k], k)
    for k in _UNIT_FIELDS.get(mtype, ()):
        if k in m:
            _unit(m[k], k)


_SEMANTIC: Mapping[str, Callable[[dict[str, Any]], None]] = dict.fromkeys(("sense", "est", "truth"), _semantic)


# ---------------------------------------------------------------- the receivers' fast path
#
# An agent decodes every sensor packet and every in-neighbour message: on the run
# engine that was half of its Python time (py-spy, 6 agents).  decoder() gives a
# receiver decode(payload, mtype) for the fields it expects, with the structure
# checked in C (msgspec: a typed msgpack decoder) and the arrays made from one
# buffer with one finiteness check.  Anything the fast path is not sure of (a
# malformed message, an unusual but valid one: a field it does not expect, an
# array of another shape, a huge value) goes to decode(), which decides and names
# the problem: the result is decode()'s whichever path it took (tested).

_D_ARR, _D_MAP, _D_NUM = 0, 1, 2
