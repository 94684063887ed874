"""Messages as JSON, as recordings store them (Foxglove and Lichtblick decode JSON with a JSON
schema): to_json, from_json, and the JSON schema of each message type."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import msgpack
import numpy as np

from zswarm.transport.wire import _validate
from zswarm.transport.wire_schema import _F8, ENVELOPE, OPEN, OPTIONAL, SCHEMAS, VERSION, MessageError, _counters

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
