"""Messages as JSON, as recordings store them (Foxglove and Lichtblick decode JSON with a JSON
schema): :func:`to_json`, :func:`from_json` and the JSON schema of each kind.

Arrays are nested lists, maps keyed by agent or edge id have the id as a string.
``from_json(to_json(m)) == m``, floats exactly (JSON numbers written with the shortest repr
round-trip).  :func:`from_json` reads the JSON of version-4 recordings too
(zswarm.transport.wire_v4).
"""

from __future__ import annotations

from typing import Any

import msgspec
import numpy as np

from zswarm.transport import wire_v4
from zswarm.transport.message_checks import _F8, MAX_ARRAY, VERSION, MessageError, _array
from zswarm.transport.messages import KINDS, Msg, enc_hook
from zswarm.transport.wire import _check_expect, encode_message


def _tolist(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return enc_hook(obj)


def to_json(m: Msg) -> dict[str, Any]:
    """A message as a JSON-ready dict (ids as strings).  An open kind's (edge, cmd) values are
    written beside its fields, where a viewer plots them as they are named (``/cmd/4.tau[0]``)."""
    out: dict[str, Any] = msgspec.to_builtins(m, enc_hook=_tolist, str_keys=True)
    if m.OPEN:
        out |= out.pop("values", {})
    return out


_JSON = msgspec.json.Encoder(enc_hook=_tolist)


def to_json_bytes(m: Msg) -> bytes:
    """:func:`to_json` written as JSON: the bytes the recordings hold (the same bytes orjson
    writes of :func:`to_json`'s dict, tested).  A closed kind is written from its Struct in one
    pass of msgspec's encoder (a stats message 3.4 -> 1.0 µs, 2026-12-06); an open kind's values
    go beside its fields, through :func:`to_json`."""
    return _JSON.encode(to_json(m) if m.OPEN else m)


def _json_hook(tp: type, obj: Any) -> Any:
    """An array field from JSON: a (nested) list of numbers."""
    if tp is np.ndarray:
        try:
            a = np.asarray(obj, dtype=_F8)
        except (TypeError, ValueError):
            raise MessageError("expected a (nested) array of numbers") from None
        if a.ndim > 4 or a.size > MAX_ARRAY:
            raise MessageError("expected a (nested) array of numbers")
        return _array(a, "array")
    raise NotImplementedError(tp)


def from_json(obj: Any, expect: str | tuple[str, ...] | None = None) -> Msg:
    """A message read back from JSON (this version's, or a version-4 recording's), validated
    exactly as a decoded payload is.

    Raises
    ------
    MessageError
        For anything that is not a well-formed message (of type ``expect``).
    """
    if type(obj) is not dict:
        raise MessageError("not a map")
    if obj.get("v") == wire_v4.V4:
        fields = wire_v4.upgrade(obj)
    elif obj.get("type") in _OPEN_KINDS and "values" not in obj:  # to_json's open kind: its values beside its fields
        fields = {k: x for k, x in obj.items() if k in _OPEN_FIELDS} | {"values": {k: x for k, x in obj.items() if k not in _OPEN_FIELDS}}
    else:
        fields = obj
    m = wire_v4.convert(fields, _json_hook, strict=False)
    _check_expect(m.type, expect)
    return m


def payload_from_json(obj: Any) -> bytes:
    """The wire payload of a JSON message, validated first (``zswarm replay``)."""
    return encode_message(from_json(obj))


_OPEN_KINDS = frozenset(k for k, c in KINDS.items() if c.OPEN)
_OPEN_FIELDS = frozenset({"type", "v", "src", "seq", "inc", "t", "t_local"})

_NUM = {"type": "number"}
_INT = {"type": "integer"}
_STR = {"type": "string"}
_ID_KEYS = "^[0-9]+$"
_VALUE = {"anyOf": [_NUM, {"type": "array"}]}  # a number or a (nested) array of numbers


def _array_schema(shape: tuple[int, ...]) -> dict[str, Any]:
    node: dict[str, Any] = _NUM
    for n in reversed(shape):
        node = {"type": "array", "items": node} | ({} if n < 0 else {"minItems": n, "maxItems": n})
    return node


def _by_id(node: dict[str, Any]) -> dict[str, Any]:
    return {"type": "object", "patternProperties": {_ID_KEYS: node}, "additionalProperties": False}


_VEC, _MAT = _array_schema((3,)), _array_schema((3, 3))
_NAMED = {"type": "object", "additionalProperties": _VALUE}
# Each kind's fields (beyond the envelope) as JSON schemas, and which of them it must have.
_FIELDS: dict[str, tuple[dict[str, Any], tuple[str, ...]]] = {
    "sense": ({"gyro": _VEC, "bearings": _by_id(_VEC), "rel_att": _by_id(_MAT), "velocity": _VEC, "velocity_body": _VEC, "attitude": _MAT, "position": _VEC, "rel_pos": _by_id(_VEC)}, ()),
    "edge": ({"t_local": _NUM}, ("t_local",)),  # and its values beside (additionalProperties)
    "cmd": ({"t_local": _NUM}, ("t_local",)),
    "est": (
        {
            "t_local": _NUM,
            "R_hat": _MAT,
            "p_hat": _VEC,
            "values": _NAMED,
            "edges": {"type": "object", "additionalProperties": _by_id(_NUM)},
            "jumps": {"type": "array", "items": {"type": "array", "prefixItems": [_STR, {"enum": ["edge", "agent"]}, _INT, _NUM, _NUM, _NUM], "minItems": 6, "maxItems": 6}},
        },
        ("t_local",),
    ),
    "truth": ({"ids": {"type": "array", "items": _INT}, "R": _array_schema((-1, 3, 3)), "p": _array_schema((-1, 3)), "w": _array_schema((-1, 3)), "tau": _array_schema((-1, 3)), "u": _array_schema((-1, 4))}, ("ids", "R", "p", "w")),
    "stats": ({"role": _STR, "counters": {"type": "object"}}, ("role", "counters")),
    "start": ({"epoch": _NUM, "time_scale": _NUM, "duration": _NUM, "seed": _INT, "run": _STR, "mac": _STR}, ("epoch", "time_scale", "duration", "seed", "run")),
    "stop": ({"reason": _STR, "mac": _STR}, ("reason",)),
    "progress": ({"duration": _NUM, "mac": _STR}, ("duration",)),
}
assert set(_FIELDS) == set(KINDS), "a kind without its JSON schema"


def json_schema(mtype: str) -> dict[str, Any]:
    """The JSON schema of a message kind as :func:`to_json` writes it (titled ``zswarm.<type>``)."""
    fields, required = _FIELDS[mtype]
    props: dict[str, Any] = {
        "type": {"const": mtype},
        "v": {"const": VERSION},
        "src": {"type": "integer", "description": "sender id (0: world or control)"},
        "seq": {"type": "integer", "minimum": 0, "description": "per-key sequence number"},
        "inc": {"type": "integer", "minimum": 0, "description": "the sender's incarnation (a restarted process gets a new one)"},
        "t": {"type": "number", "description": "world time of the content, s"},
    } | fields
    extra: Any = _VALUE if KINDS[mtype].OPEN else False
    return {"title": f"zswarm.{mtype}", "type": "object", "properties": props, "required": ["type", "v", "src", "seq", "t", *required], "additionalProperties": extra}
