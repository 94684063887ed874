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
from typing import Any, Literal, TypeGuard

import msgpack
import numpy as np

from zswarm.math.limits import MAX_ABS, ROT_TOL  # (ROT_TOL: see _check_semantic)
from zswarm.transport import keys
from zswarm.math.so3 import _rotation_ok, rotations_ok

VERSION = 4  # 2: edge messages carry the fields their algorithm declares (open schema); 3: inc, bounds; 4: sense fields named as the sensors (velocity, velocity_body, attitude, position)


class MessageError(ValueError):
    """A message that is not a valid zswarm message."""


class Message(dict):  # type: ignore[type-arg]
    """A message as :func:`decode` returns it: decoded and validated.

    The in-process bus (``zswarm sim``) delivers these to every subscriber instead of
    bytes each would decode and validate again (:func:`message`): :func:`decode` of a
    Message only checks its type.  Receivers must not change it (it is shared): copy
    it to add what they know of it (the arrival time, ...)."""

    __slots__ = ()


# Bounds on every field: a message that decodes but carries a value no experiment can
# produce is malformed, not something for an agent's math to choke on (a gyro of 1e200
# killed an agent in so3.exp).
MAX_SEQ = 1 << 53  # seq and inc are in [0, 2**53): integers JSON (and so the viewers) carry exactly
MAX_ID = (1 << 31) - 1  # src and agent ids are in [0, 2**31)
MAX_IDS = 4096  # entries of a map keyed by agent or edge id, of truth's ids, of a jump list
UNIT_TOL = 1e-6  # | |b| − 1 | of every bearing
MAX_STR = 4096


# field kinds: "int", "float", "str", (shape,) for float64 arrays,
# "vecmap" for {int: float64[3]}, "matmap" for {int: float64[3,3]}, "floatmap" for
# {int: float}, "jumps" for [[edge k, t, ξ before, ξ after], ...], "counters" (a map of names to
# numbers, strings, booleans, None, lists and maps of those: bounded, see _counters)
SCHEMAS: Mapping[str, Mapping[str, Any]] = {
    # world -> agent i, each field named as the sensor is (zswarm.scenario.algorithm.SENSORS): gyro,
    # body-frame bearings b_ij^i, relative attitudes R_ij, inertial velocity v_i, body-frame
    # velocity v_i^i, own attitude R_i and position p_i, body-frame relative positions ⁱp_ij
    # (rel_pos, De Carli et al. (2))
    "sense": {"gyro": (3,), "bearings": "vecmap", "rel_att": "matmap", "velocity": (3,), "velocity_body": (3,), "attitude": (3, 3), "position": (3,), "rel_pos": "vecmap"},
    # agent j -> agent i along edge j->i: the sender's clock, then the fields its
    # algorithm writes on out-edges (SPEC.edge_out: numbers or float64 arrays by
    # name; OPEN below), validated by the receiver against its SPEC.edge_in
    "edge": {"t_local": "float"},
    # agent i -> recorder: its estimate; xi: ξ_k of the edges it heads; jumps since the
    # last est (agent_jumps: of its own hybrid variable, ζ_i of (5.12), k = its id); extra: named values the algorithm reports (σ_i, Ω_i, ...)
    "est": {"t_local": "float", "R_hat": (3, 3), "p_hat": (3,), "extra": "fields", "xi": "floatmap", "jumps": "jumps", "agent_jumps": "jumps"},
    # agent i -> world on cmd/<i>: the sender's clock, then the fields its algorithm
    # sends the plant (SPEC.command: a torque "tau" for the rigid bodies of (5.1)), OPEN
    # below and validated by the world against the plant's inputs
    "cmd": {"t_local": "float"},
    # world -> recorder: ids[k] has attitude R[k], position p[k], true angular velocity w[k]
    # (and, for a rigid-body plant, the torque tau[k] it applied over the last world step;
    # for a kinematic plant, u[k] = [v (body frame), yaw rate] it applied)
    "truth": {"ids": "intlist", "R": (-1, 3, 3), "p": (-1, 3), "w": (-1, 3), "tau": (-1, 3), "u": (-1, 4)},
    # counters of a process
    "stats": {"role": "str", "counters": "counters"},
    # run control; mac: signed with the run's secret when there is one (encode_ctl, decode_ctl)
    "start": {"epoch": "float", "time_scale": "float", "duration": "float", "seed": "int", "run": "str", "mac": "str"},
    "stop": {"reason": "str", "mac": "str"},
    "progress": {"duration": "float", "mac": "str"},
}
_F8 = np.dtype("<f8")
ENVELOPE = ("v", "type", "src", "seq", "inc", "t")
assert not any(k in ENVELOPE for schema in SCHEMAS.values() for k in schema), "a field shadows the envelope"
OPTIONAL = {
    "sense": {"gyro", "bearings", "rel_att", "velocity", "velocity_body", "attitude", "position", "rel_pos"},
    "est": {"R_hat", "p_hat", "extra", "xi", "jumps", "agent_jumps"},
    "truth": {"tau", "u"},
    "start": {"mac"},
    "stop": {"mac"},
    "progress": {"mac"},
}
_OPTIONAL_OF: Mapping[str, frozenset[str]] = {t: frozenset(OPTIONAL.get(t, ())) for t in SCHEMAS}
# Types whose other keys are named values (a finite number or a float64 array), at most
# MAX_OPEN of them: what an algorithm declares, which the receiver validates.
OPEN = frozenset({"edge", "cmd"})
MAX_OPEN = 64
MAX_VALUE_LEN = 4096  # elements of one open array


def _arr(a: np.ndarray) -> list[Any]:
    if type(a) is not np.ndarray or a.dtype != _F8 or not a.flags.c_contiguous:
        a = np.ascontiguousarray(a, dtype="<f8")
    return [list(a.shape), a.tobytes()]


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


def _enc_value(v: Any) -> Any:
    """A named value: a number as a float, anything else as a float64 array."""
    if isinstance(v, (int, float, np.floating)) and not isinstance(v, bool):
        return float(v)
    return _arr(np.asarray(v))


_FAST = {(3,): ([3], 24), (3, 3): ([3, 3], 72)}  # the shapes of most fields: a shorter path


def _dec_arr(v: Any, shape: tuple[int, ...], fld: str) -> np.ndarray:
    fast = _FAST.get(shape)
    if fast is not None and type(v) is list and len(v) == 2 and v[0] == fast[0] and type(v[1]) is bytes and len(v[1]) == fast[1]:
        a = np.frombuffer(v[1], dtype="<f8").reshape(shape)
        _check_values(a.ravel().tolist(), fld)
        return a
    if not (type(v) in (list, tuple) and len(v) == 2 and type(v[1]) is bytes and type(v[0]) in (list, tuple)):
        raise MessageError(f"{fld}: expected [shape, bytes]")
    shp = tuple(v[0])
    if len(shp) != len(shape):
        raise MessageError(f"{fld}: bad shape {shp}")
    n = 1
    for want, got in zip(shape, shp, strict=True):
        if type(got) is not int or got < 0:
            raise MessageError(f"{fld}: bad shape {shp}")
        if want != -1 and want != got:
            raise MessageError(f"{fld}: shape {shp}, expected {shape}")
        n *= got
    if len(v[1]) != 8 * n:
        raise MessageError(f"{fld}: {len(v[1])} bytes for shape {shp}")
    a = np.frombuffer(v[1], dtype="<f8").reshape(shp)
    # Plain-Python check for the small arrays that are most messages (≈10x faster than numpy there).
    if n <= 32:
        _check_values(a.ravel().tolist(), fld)
    elif n and not np.abs(a).max() <= MAX_ABS:  # False for NaN too
        raise MessageError(f"{fld}: {'non-finite values' if not np.isfinite(a).all() else f'values beyond ±{MAX_ABS:g}'}")
    return a


def _check_values(xs: list[float], fld: str) -> None:
    """Every number of ``xs`` finite and within ±MAX_ABS (raises MessageError)."""
    if not all(map(math.isfinite, xs)):
        raise MessageError(f"{fld}: non-finite values")
    if xs and (max(xs) > MAX_ABS or min(xs) < -MAX_ABS):
        raise MessageError(f"{fld}: values beyond ±{MAX_ABS:g}")


def _dec_value(v: Any, k: str) -> float | np.ndarray:
    """A named value (see OPEN): a finite number, or a float64 array of at most 4 dimensions."""
    if type(v) is float or type(v) is int:
        if not _finite(v):
            raise MessageError(f"{k}: expected a finite number within ±{MAX_ABS:g}")
        return float(v)
    if not (type(v) is list and len(v) == 2 and type(v[0]) is list and len(v[0]) <= 4):
        raise MessageError(f"{k}: expected a number or [shape, bytes]")
    shape = v[0]
    if not all(type(d) is int and 0 <= d <= MAX_VALUE_LEN for d in shape) or math.prod(shape) > MAX_VALUE_LEN:
        raise MessageError(f"{k}: bad shape {shape}")
    return _dec_arr(v, tuple(shape), k)


def _fields(v: Any, k: str) -> dict[str, float | np.ndarray]:
    if type(v) is not dict or len(v) > MAX_OPEN or not all(type(n) is str and len(n) <= 64 for n in v):
        raise MessageError(f"{k}: expected a map of at most {MAX_OPEN} names to values")
    return {n: _dec_value(x, f"{k}.{n}") for n, x in v.items()}


def _finite(x: Any) -> TypeGuard[int | float]:
    """A number (not a bool), finite and within ±MAX_ABS."""
    return not isinstance(x, bool) and isinstance(x, (int, float)) and -MAX_ABS <= x <= MAX_ABS


def _id(j: Any) -> bool:
    return type(j) is int and 0 <= j <= MAX_ID


def _kind_handler(kind: Any) -> Callable[[Any, str], Any]:
    """The validator/converter of one field kind (see SCHEMAS)."""
    if isinstance(kind, tuple):
        shape = kind
        return lambda v, k: _dec_arr(v, shape, k)
    if kind == "fields":
        return _fields
    if kind in ("vecmap", "matmap"):
        shape = (3,) if kind == "vecmap" else (3, 3)
        what = "vector" if kind == "vecmap" else "3x3 matrix"

        def arrmap(v: Any, k: str) -> dict[int, np.ndarray]:
            if type(v) is not dict or len(v) > MAX_IDS or not all(map(_id, v)):
                raise MessageError(f"{k}: expected a map of at most {MAX_IDS} ids to {what}")
            d = {}
            for j, x in v.items():
                try:
                    d[j] = _dec_arr(x, shape, k)
                except MessageError as exc:  # name the entry (built only on error)
                    raise MessageError(str(exc).replace(f"{k}:", f"{k}[{j}]:", 1)) from None
            return d

        return arrmap
    if kind == "floatmap":

        def floatmap(v: Any, k: str) -> dict[int, float]:
            if type(v) is not dict or len(v) > MAX_IDS or not all(_id(j) and _finite(x) for j, x in v.items()):
                raise MessageError(f"{k}: expected a map of at most {MAX_IDS} ids to finite numbers")
            return {j: float(x) for j, x in v.items()}

        return floatmap
    if kind == "jumps":

        def jumps(v: Any, k: str) -> list[tuple[int, float, float, float]]:
            if type(v) is not list or len(v) > MAX_IDS or not all(type(e) is list and len(e) == 4 and _id(e[0]) and all(_finite(x) for x in e[1:]) for e in v):
                raise MessageError(f"{k}: expected a list of at most {MAX_IDS} [edge, t, xi_before, xi_after]")
            return [(e[0], float(e[1]), float(e[2]), float(e[3])) for e in v]

        return jumps
    if kind == "float":

        def flt(v: Any, k: str) -> float:
            if not _finite(v):
                raise MessageError(f"{k}: expected a finite number within ±{MAX_ABS:g}")
            return float(v)

        return flt
    if kind == "int":

        def integer(v: Any, k: str) -> int:
            if type(v) is not int:
                raise MessageError(f"{k}: expected an integer")
            return v

        return integer
    if kind == "str":

        def string(v: Any, k: str) -> str:
            if type(v) is not str or len(v) > MAX_STR:
                raise MessageError(f"{k}: expected a string of at most {MAX_STR} characters")
            return v

        return string
    if kind == "intlist":

        def intlist(v: Any, k: str) -> list[int]:
            if type(v) is not list or len(v) > MAX_IDS or not all(map(_id, v)):
                raise MessageError(f"{k}: expected a list of at most {MAX_IDS} ids")
            return v

        return intlist
    if kind == "counters":
        return _counters
    raise AssertionError(f"unknown field kind {kind!r}")


# A process's counters (stats): what a receiver accepts.  ``counters = 5`` used to pass as
# "any" and make the report raise TypeError after the run.
MAX_COUNTER_DEPTH = 6
MAX_COUNTER_ITEMS = 20000


def _counters(v: Any, k: str) -> dict[str, Any]:
    if type(v) is not dict:
        raise MessageError(f"{k}: expected a map of names to counters")
    left = [MAX_COUNTER_ITEMS]

    def check(x: Any, where: str, depth: int) -> None:
        left[0] -= 1
        if left[0] < 0:
            raise MessageError(f"{k}: more than {MAX_COUNTER_ITEMS} entries")
        if depth > MAX_COUNTER_DEPTH:
            raise MessageError(f"{where}: nested deeper than {MAX_COUNTER_DEPTH}")
        t = type(x)
        if t is dict:
            for n, y in x.items():
                if type(n) is not str or len(n) > 256:
                    raise MessageError(f"{where}: keys must be names (strings of at most 256 characters)")
                check(y, f"{where}.{n}", depth + 1)
        elif t is list:
            for i, y in enumerate(x):
                check(y, f"{where}[{i}]", depth + 1)
        elif x is not None and t not in (int, float, str, bool):
            raise MessageError(f"{where}: expected a number, a string, a list or a map")
        elif t is str and len(x) > MAX_STR:
            raise MessageError(f"{where}: a string of more than {MAX_STR} characters")
        elif t is float and not math.isfinite(x):
            raise MessageError(f"{where}: not finite")

    check(v, k, 0)
    return v


# Per message type: (field, handler, optional), in schema order.
_FIELDS = {t: tuple((k, _kind_handler(kind), k in OPTIONAL.get(t, ())) for k, kind in schema.items()) for t, schema in SCHEMAS.items()}
_MISSING = object()


def ctl_mac(secret: bytes, m: Mapping[str, Any]) -> str:
    """The signature of a run-control message: HMAC-SHA256 with the run's secret over its
    envelope and fields (floats by their exact hex), 32 hex digits."""
    import hashlib
    import hmac

    parts = [str(m["type"]), str(m["src"]), str(m["seq"]), str(m["inc"]), float(m["t"]).hex()]
    for k, kind in sorted(SCHEMAS[m["type"]].items()):
        if k != "mac":
            v = m[k]  # a "float" field is signed as the float the receiver decodes (1 and 1.0 alike)
            parts.append(f"{k}={float(v).hex() if kind == 'float' else v}")
    return hmac.new(secret, "|".join(parts).encode(), hashlib.sha256).hexdigest()[:32]


def encode_ctl(mtype: str, src: int, seq: int, t: float, *, inc: int = 0, **fields: Any) -> bytes:
    """A run-control message, signed (``mac``) with the run's secret when there is one
    (keys.run_secret)."""
    secret = keys.run_secret()
    if secret is not None:
        fields["mac"] = ctl_mac(secret, {"type": mtype, "src": src, "seq": seq, "inc": inc, "t": float(t), **fields})
    return encode(mtype, src, seq, t, inc=inc, **fields)


def decode_ctl(payload: bytes, expect: str) -> dict[str, Any]:
    """A run-control message (``start``, ``stop`` or ``progress`` on ctl/...), decoded and
    checked beyond its schema: only the world (src 0) controls a run, a start's clock must
    make sense, and with the run's secret (keys.run_secret) it must carry its signature.

    Any payload on ctl/stop used to stop every agent and the recorder, and a start with
    ``time_scale = 0`` crashed the agents (a division by it in their clock).  A wire-valid
    stop from a peer stopped the agents and the recorder while the world ran on, and an
    early start with time scale 1e-3 made a run of 2 steps that read as completed.
    """
    return check_ctl(decode(payload, expect), expect)


def check_signature(m: Mapping[str, Any]) -> None:
    """With the run's secret (keys.run_secret), a run-control message must carry its
    signature (:func:`ctl_mac`); raises MessageError otherwise."""
    secret = keys.run_secret()
    if secret is not None:
        import hmac

        if not hmac.compare_digest(str(m.get("mac", "")), ctl_mac(secret, m)):
            raise MessageError(f"{m['type']}: not signed with this run's secret")


def check_ctl(m: dict[str, Any], expect: str) -> dict[str, Any]:
    """:func:`decode_ctl`'s checks on a decoded run-control message (returns it)."""
    check_signature(m)
    if m["src"] != 0:
        raise MessageError(f"{expect}: from src {m['src']}; only the world (src 0) controls the run")
    if expect == "start":
        if not m["time_scale"] > 0:
            raise MessageError(f"start: time_scale must be > 0 (got {m['time_scale']!r})")
        if not m["duration"] > 0:
            raise MessageError(f"start: duration must be > 0 (got {m['duration']!r})")
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


class _Slow(Exception):
    """The fast path is not sure of decode()'s result: decode() decides."""


def _fast_type(code: int, optional: bool) -> Any:
    import msgspec

    arr = tuple[list[int], bytes]
    t: Any = arr if code == _D_ARR else (dict[int, arr] if code == _D_MAP else float)
    return (t | msgspec.UnsetType) if optional else t


def _fast(mtype: str, plan: list[tuple[str, int, tuple[int, ...], bool]]) -> Callable[[bytes], dict[str, Any]] | None:
    """A decoder of ``mtype`` for the fields of ``plan`` ((name, code, shape, optional)) that
    raises on anything it is not sure of; None where msgspec cannot express it.

    Any other field is left to decode(): msgspec would skip it unchecked (even a key
    that is not UTF-8, which decode rejects), decode ignores it or keeps it (open types)."""
    try:
        import msgspec

        fields: list[Any] = [("v", Literal[VERSION]), ("type", Literal[mtype]), ("src", int), ("seq", int), ("inc", int), ("t", float)]
        fields += [(n, _fast_type(code, opt), msgspec.UNSET) if opt else (n, _fast_type(code, opt)) for n, code, _, opt in plan]
        struct = msgspec.defstruct(f"_Fast_{mtype}", fields, kw_only=True, forbid_unknown_fields=True)
        dec = msgspec.msgpack.Decoder(struct).decode
    except (ImportError, TypeError, ValueError):
        return None
    unset = msgspec.UNSET
    steps = [(n, code, list(shape), 8 * math.prod(shape), shape) for n, code, shape, _ in plan]
    isfinite, fsum, frombuffer = math.isfinite, math.fsum, np.frombuffer
    semantic = _SEMANTIC.get(mtype)

    def fast(payload: bytes) -> dict[str, Any]:
        m: Any = dec(payload)
        t, src, seq, inc = m.t, m.src, m.seq, m.inc
        if not (-MAX_ABS <= t <= MAX_ABS and 0 <= src <= MAX_ID and 0 <= seq < MAX_SEQ and 0 <= inc < MAX_SEQ):
            raise _Slow
        out: dict[str, Any] = Message(type=mtype, src=src, seq=seq, inc=inc, t=t)
        bufs: list[bytes] = []
        places: list[tuple[dict[Any, Any], Any, int, tuple[int, ...]]] = []
        for name, code, shp, nb, shape in steps:
            x = getattr(m, name)
            if x is unset:
                continue
            if code == _D_ARR:
                if x[0] != shp or len(x[1]) != nb:
                    raise _Slow
                bufs.append(x[1])
                places.append((out, name, nb >> 3, shape))
                out[name] = None  # its place in decode's order; the array below
            elif code == _D_MAP:
                d: dict[int, Any] = {}
                if len(x) > MAX_IDS:
                    raise _Slow
                for j, y in x.items():
                    if y[0] != shp or len(y[1]) != nb or not 0 <= j <= MAX_ID:
                        raise _Slow
                    bufs.append(y[1])
                    places.append((d, j, nb >> 3, shape))
                    d[j] = None
                out[name] = d
            else:
                if not -MAX_ABS <= x <= MAX_ABS:  # False for NaN
                    raise _Slow
                out[name] = x
        if bufs:
            # One buffer for every array of the message: read-only views of it, as decode's
            # arrays are read-only.  Finite iff the exact sum is (fsum raises otherwise).
            flat = frombuffer(b"".join(bufs), dtype=_F8)
            xs = flat.tolist()
            if not isfinite(fsum(xs)) or max(xs) > MAX_ABS or min(xs) < -MAX_ABS:
                raise _Slow
            o = 0
            for d, k, n, shape in places:
                d[k] = flat[o : o + n].reshape(shape)
                o += n
        if semantic is not None:
            try:
                semantic(out)
            except MessageError:
                raise _Slow from None
        return out

    return fast


def decoder(mtype: str, fields: Mapping[str, tuple[tuple[int, ...], bool]] | None = None) -> Callable[[bytes], dict[str, Any]]:
    """``decode(payload, mtype)``, fast for the messages a receiver expects.

    ``mtype`` "sense" (its schema), or "edge"/"cmd" with ``fields``: the receiver's
    declaration, name -> (shape, optional) (``()``: a number).  Raises MessageError
    exactly where :func:`decode` does; returns what it returns (for an open type the
    fields may come in another order).
    """
    plan: list[tuple[str, int, tuple[int, ...], bool]] = []
    if mtype in OPEN:
        plan.append(("t_local", _D_NUM, (), False))
        for n, (shape, optional) in (fields or {}).items():
            plan.append((n, _D_ARR if shape else _D_NUM, tuple(shape), optional))
    else:
        for n, kind in SCHEMAS[mtype].items():
            if isinstance(kind, tuple) and -1 not in kind:
                plan.append((n, _D_ARR, kind, n in OPTIONAL.get(mtype, ())))
            elif kind in ("vecmap", "matmap"):
                plan.append((n, _D_MAP, (3,) if kind == "vecmap" else (3, 3), n in OPTIONAL.get(mtype, ())))
            elif kind == "float":
                plan.append((n, _D_NUM, (), n in OPTIONAL.get(mtype, ())))
            else:
                plan = []
                break
    fast = _fast(mtype, plan) if plan else None

    def dec(payload: bytes | Message) -> dict[str, Any]:
        if type(payload) is Message:
            return decode(payload, mtype)
        if fast is not None:
            try:
                return fast(payload)  # type: ignore[arg-type]  # bytes: a Message returned above
            except Exception:  # noqa: BLE001 - msgspec's errors, _Slow, ...: decode() decides
                pass
        return decode(payload, mtype)

    return dec


# ---------------------------------------------------------------- JSON (recordings, viewers)
#
# A recording stores every message as JSON (Foxglove and Lichtblick decode JSON with
# a JSON schema, not msgpack): arrays as nested lists, maps keyed by agent or edge id
# with the id as a string.  from_json(to_json(decode(p))) == decode(p), floats exactly
# (JSON numbers written with the shortest repr round-trip).


def to_json(m: Mapping[str, Any]) -> dict[str, Any]:
    """A decoded message (:func:`decode`'s output) as a JSON-ready dict."""
    out: dict[str, Any] = {"v": VERSION}
    schema = SCHEMAS[m["type"]]
    for k, v in m.items():
        kind = schema.get(k)
        if kind is None or kind in ("int", "float", "str", "intlist", "counters") or k in ENVELOPE:
            out[k] = v.tolist() if isinstance(v, np.ndarray) else v
        elif isinstance(kind, tuple):
            out[k] = v.tolist()
        elif kind in ("vecmap", "matmap"):
            out[k] = {str(j): x.tolist() for j, x in v.items()}
        elif kind == "floatmap":
            out[k] = {str(j): x for j, x in v.items()}
        elif kind == "fields":
            out[k] = {n: x.tolist() if isinstance(x, np.ndarray) else x for n, x in v.items()}
        elif kind == "jumps":
            out[k] = [list(e) for e in v]
        else:  # pragma: no cover - every kind is handled above
            raise KeyError(kind)
    return out


def _arr_from_json(v: Any, k: str) -> list[Any]:
    """A JSON array of numbers (nested) as the wire's ``[shape, bytes]``."""
    try:
        a = np.asarray(v, dtype="<f8")
    except (TypeError, ValueError):
        raise MessageError(f"{k}: expected a (nested) array of numbers") from None
    if a.dtype != _F8 or a.ndim > 4 or a.size > (1 << 17):
        raise MessageError(f"{k}: expected a (nested) array of numbers")
    return [list(a.shape), np.ascontiguousarray(a).tobytes()]


def _int_keys(v: Any, k: str) -> dict[int, Any]:
    if type(v) is not dict:
        raise MessageError(f"{k}: expected a map keyed by id")
    try:
        return {int(j): x for j, x in v.items()}
    except (TypeError, ValueError):
        raise MessageError(f"{k}: expected a map keyed by id") from None


def _named_from_json(v: Any, k: str) -> Any:
    return v if type(v) in (int, float) else _arr_from_json(v, k)


def _json_to_wire(obj: Any) -> dict[Any, Any]:
    """A JSON message back in the form msgpack gives (arrays as ``[shape, bytes]``), unvalidated."""
    if type(obj) is not dict:
        raise MessageError("not a map")
    mtype = obj.get("type")
    schema = SCHEMAS.get(mtype) if type(mtype) is str else None
    if schema is None:
        raise MessageError(f"unknown type {mtype!r}")
    m: dict[Any, Any] = {}
    for k, v in obj.items():
        kind = schema.get(k, "value" if mtype in OPEN and k not in ENVELOPE else None)
        if kind == "counters":
            m[k] = _counters(v, k)
        elif kind is None or kind in ("int", "float", "str", "intlist"):
            m[k] = v
        elif isinstance(kind, tuple):
            m[k] = _arr_from_json(v, k)
        elif kind in ("vecmap", "matmap"):
            m[k] = {j: _arr_from_json(x, f"{k}[{j}]") for j, x in _int_keys(v, k).items()}
        elif kind == "floatmap":
            m[k] = _int_keys(v, k)
        elif kind == "fields":
            if type(v) is not dict:
                raise MessageError(f"{k}: expected a map of names to values")
            m[k] = {n: _named_from_json(x, f"{k}.{n}") for n, x in v.items()}
        elif kind == "value":
            m[k] = _named_from_json(v, k)
        else:  # jumps: lists as they are
            m[k] = v
    return m


def from_json(obj: Any, expect: str | tuple[str, ...] | None = None) -> dict[str, Any]:
    """A message read back from JSON, validated exactly as :func:`decode` validates.

    Raises
    ------
    MessageError
        For anything that is not a well-formed message (of type ``expect``).
    """
    return _validate(_json_to_wire(obj), expect)


def payload_from_json(obj: Any) -> bytes:
    """The wire payload (msgpack) of a JSON message, validated first (``zswarm replay``)."""
    m = _json_to_wire(obj)
    _validate(m, None)
    return bytes(msgpack.packb(m, use_bin_type=True))


_NUM = {"type": "number"}


def _json_array(shape: tuple[int, ...]) -> dict[str, Any]:
    node: dict[str, Any] = _NUM
    for n in reversed(shape):
        node = {"type": "array", "items": node} | ({} if n < 0 else {"minItems": n, "maxItems": n})
    return node


_ID_KEYS = "^[0-9]+$"
_VALUE = {"anyOf": [_NUM, {"type": "array"}]}  # a number or a (nested) array of numbers


def _json_kind(kind: Any) -> dict[str, Any]:
    if isinstance(kind, tuple):
        return _json_array(kind)
    simple: dict[str, dict[str, Any]] = {"int": {"type": "integer"}, "float": _NUM, "str": {"type": "string"}, "intlist": {"type": "array", "items": {"type": "integer"}}, "counters": {"type": "object"}}
    if kind in simple:
        return simple[kind]
    if kind in ("vecmap", "matmap"):
        return {"type": "object", "patternProperties": {_ID_KEYS: _json_array((3,) if kind == "vecmap" else (3, 3))}, "additionalProperties": False}
    if kind == "floatmap":
        return {"type": "object", "patternProperties": {_ID_KEYS: _NUM}, "additionalProperties": False}
    if kind == "fields":
        return {"type": "object", "additionalProperties": _VALUE}
    if kind == "jumps":
        return {"type": "array", "items": {"type": "array", "items": _NUM, "minItems": 4, "maxItems": 4}}
    raise KeyError(kind)  # pragma: no cover


def json_schema(mtype: str) -> dict[str, Any]:
    """The JSON schema of a message type as :func:`to_json` writes it (titled ``zswarm.<type>``)."""
    props: dict[str, Any] = {
        "v": {"const": VERSION},
        "type": {"const": mtype},
        "src": {"type": "integer", "description": "sender id (0: world or control)"},
        "seq": {"type": "integer", "minimum": 0, "description": "per-key sequence number"},
        "inc": {"type": "integer", "minimum": 0, "description": "the sender's incarnation (a restarted process gets a new one)"},
        "t": {"type": "number", "description": "world time of the content, s"},
    }
    props |= {k: _json_kind(kind) for k, kind in SCHEMAS[mtype].items()}
    required = [*ENVELOPE, *(k for k in SCHEMAS[mtype] if k not in OPTIONAL.get(mtype, ()))]
    return {
        "title": f"zswarm.{mtype}",
        "type": "object",
        "properties": props,
        "required": required,
        "additionalProperties": _VALUE if mtype in OPEN else False,
    }
