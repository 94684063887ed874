"""The reader of version-4 messages, kept for the recordings made before version 5.

Version 4 was a msgpack map per message, arrays as ``[shape, bytes]`` as now, with an open
kind's fields beside its envelope and an estimate's ``extra``, ``xi``, ``jumps`` and
``agent_jumps`` named by the wire.  A version-4 message is read into this version's Struct
(zswarm.transport.messages) and validated by it:

- ``edge``, ``cmd``: every field but the envelope and ``t_local`` becomes one of its ``values``;
- ``est``: ``extra`` becomes ``values``, ``xi`` ({k: ξ_k}) ``edges["xi"]``, each ``jumps``
  entry (k, t, ξ before, after) a jump of ``"xi"`` owned by edge k and each ``agent_jumps``
  entry (i, t, ζ before, after) a jump of ``"zeta"`` owned by agent i (the only hybrid
  variables version 4 carried: the thesis' §4/§5 schemes);
- the other kinds keep their fields.
"""

from __future__ import annotations

from typing import Any, Union

import msgpack
import msgspec

from zswarm.transport.message_checks import ENVELOPE, MAX_COUNTER_ITEMS, VERSION, MessageError
from zswarm.transport.messages import FIELDS, KINDS, Msg, dec_hook, readable

V4 = 4
_OPEN = ("edge", "cmd")
_CONVERTER = Union[tuple(KINDS.values())]  # noqa: UP007 - a runtime union of the kinds


def _unpack(payload: bytes) -> Any:
    try:
        return msgpack.unpackb(payload, raw=False, strict_map_key=False, max_bin_len=1 << 20, max_str_len=1 << 16, max_array_len=MAX_COUNTER_ITEMS, max_map_len=MAX_COUNTER_ITEMS)
    except Exception as exc:  # msgpack raises a zoo of types on garbage
        raise MessageError(f"not msgpack ({type(exc).__name__})") from None


def upgrade(m: Any) -> dict[str, Any]:
    """A version-4 map (as msgpack or JSON gives it) as this version's fields (unvalidated)."""
    if type(m) is not dict:
        raise MessageError("not a map")
    if m.get("v") != V4:
        raise MessageError(f"schema version {m.get('v')!r}, expected {V4}")
    mtype = m.get("type")
    if type(mtype) is not str or mtype not in KINDS:
        raise MessageError(f"unknown type {mtype!r}")
    out: dict[str, Any] = {k: m[k] for k in ENVELOPE if k in m}
    out["v"] = VERSION
    if mtype in _OPEN:
        out["t_local"] = m.get("t_local")
        out["values"] = {k: x for k, x in m.items() if k not in ENVELOPE and k != "t_local"}
    elif mtype == "est":
        for k in ("t_local", "R_hat", "p_hat"):
            if k in m:
                out[k] = m[k]
        if "extra" in m:
            out["values"] = m["extra"]
        if "xi" in m:
            out["edges"] = {"xi": m["xi"]}
        jumps = []
        for key, var, owner in (("jumps", "xi", "edge"), ("agent_jumps", "zeta", "agent")):
            es = m.get(key, [])
            if type(es) is not list or not all(type(e) is list and len(e) == 4 for e in es):
                raise MessageError(f"{key}: expected a list of [owner, t, before, after]")
            jumps += [[var, owner, *e] for e in es]
        if jumps:
            out["jumps"] = jumps
    else:  # the same fields (version 4 let a closed kind's unknown fields pass: so does its reader)
        out |= {k: x for k, x in m.items() if k in FIELDS[mtype]}
    return out


def convert(fields: dict[str, Any], dec_hook: Any, strict: bool = True) -> Msg:
    """This version's message of ``fields`` (as :func:`upgrade` or JSON give them), validated as
    a decoded payload is (``strict=False``: ids as JSON's strings)."""
    try:
        m: Msg = msgspec.convert(fields, _CONVERTER, dec_hook=dec_hook, strict=strict)
    except msgspec.ValidationError as exc:
        raise MessageError(readable(str(exc))) from None
    return m


def decode(payload: bytes) -> Msg:
    """A version-4 payload as this version's message (MessageError: not a valid one)."""
    return convert(upgrade(_unpack(payload)), dec_hook)
