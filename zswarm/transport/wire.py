"""The wire: one encoder and one decoder of the typed messages (zswarm.transport.messages).

:func:`encode` builds a message of a kind from its fields and packs it (msgpack, arrays as
``[shape, bytes]``); :func:`decode` unpacks and validates a payload into its Struct, raising
:class:`MessageError` (never anything else) on anything that is not a well-formed message.
:func:`message` is what the in-process bus (``zswarm sim``) delivers instead of bytes: the
Struct itself, validated once at the sender.  :func:`decode_recorded` also reads the payloads
of recordings made before version 5 (zswarm.transport.wire_v4).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Union

import msgspec

from zswarm.transport import keys, wire_v4
from zswarm.transport.message_checks import (  # the bounds and the error, which users read as wire.X
    ENVELOPE,
    MAX_COUNTER_ITEMS,
    MAX_ID,
    MAX_IDS,
    MAX_OPEN,
    MAX_SEQ,
    MAX_VALUE_LEN,
    UNIT_TOL,
    VERSION,
    MessageError,
)
from zswarm.transport.messages import (  # the types
    DEC_HOOK,
    ENC_HOOK,
    FIELDS,
    KINDS,
    Cmd,
    Edge,
    Est,
    Msg,
    Sense,
    Stats,
    Truth,
    readable,
    version_of,
)

Message = Msg  # a decoded, validated message (any kind)

__all__ = [
    "ENVELOPE",
    "FIELDS",
    "KINDS",
    "MAX_COUNTER_ITEMS",
    "MAX_ID",
    "MAX_IDS",
    "MAX_OPEN",
    "MAX_SEQ",
    "MAX_VALUE_LEN",
    "UNIT_TOL",
    "VERSION",
    "Cmd",
    "Edge",
    "Est",
    "Message",
    "MessageError",
    "Msg",
    "Sense",
    "Stats",
    "Truth",
    "build",
    "check_stream",
    "decode",
    "decode_recorded",
    "decoder",
    "encode",
    "encode_message",
    "message",
    "version_of",
]


_ENCODER = msgspec.msgpack.Encoder(enc_hook=ENC_HOOK)
_DECODER = msgspec.msgpack.Decoder(Union[tuple(KINDS.values())], dec_hook=DEC_HOOK)  # type: ignore[arg-type]  # noqa: UP007 - a runtime union of the kinds


def build(mtype: str, src: int, seq: int, t: float, *, inc: int = 0, **fields: Any) -> Msg:
    """A message of kind ``mtype`` with these fields, validated (MessageError, or TypeError for
    a field the kind does not have).  ``edge`` and ``cmd``: every field but ``t_local`` is one
    of its ``values``."""
    cls = KINDS.get(mtype)
    if cls is None:
        raise MessageError(f"unknown type {mtype!r}")
    if cls.OPEN and "values" not in fields:
        t_local = fields.pop("t_local", None)
        fields = {"values": fields} if t_local is None else {"t_local": t_local, "values": fields}
    return cls(v=VERSION, src=src, seq=seq, t=t, inc=inc, **fields)  # __post_init__ raises MessageError


def encode(mtype: str, src: int, seq: int, t: float, *, inc: int = 0, **fields: Any) -> bytes:
    """The payload of :func:`build`'s message, the same bytes (``encode_message(build(...))``),
    without building it: the fields are packed in the kind's order, its defaults left out, and
    not checked.  Every receiver decodes and checks what it receives, so a check at the sender
    as well cost each message twice (hot: an edge 19 µs packed through its Struct, 6 µs so; in
    the processes, cache-cold: an edge 30-46 -> 22-35 µs of CPU, the world's sense packet 44 ->
    15 µs, 2026-12-06).  Arrays may be numpy arrays
    or nested lists.  A message :func:`build` refuses is packed as it is, for every receiver
    to count, drop and name its problem as it would off the network: a sender never fails on
    what it sends (:func:`build` says what is wrong with it)."""
    mirror = _MIRRORS.get(mtype)
    if mirror is not None:
        if mirror.OPEN and "values" not in fields:
            t_local = fields.pop("t_local", _NONE)
            fields = {"values": fields} if t_local is _NONE else {"t_local": t_local, "values": fields}
        try:
            return _ENCODER.encode(mirror(v=VERSION, src=src, seq=seq, t=t, inc=inc, **fields))
        except (TypeError, ValueError, NotImplementedError, OverflowError):  # a field not the kind's, or not encodable
            pass
    return _pack(mtype, src, seq, t, inc, fields)


def encode_message(m: Msg) -> bytes:
    """The payload of a message (``decode(encode_message(m)) == m``): how a message that travelled
    in-process is written to a raw recording."""
    return _ENCODER.encode(m)


def message(mtype: str, src: int, seq: int, t: float, *, inc: int = 0, **fields: Any) -> Msg | bytes:
    """What :func:`decode` makes of :func:`encode`'s payload for the same arguments, without the
    bytes: the message the in-process bus delivers (validated once, at the sender).  A message
    :func:`build` refuses comes back as its payload (:func:`encode`)."""
    try:
        return build(mtype, src, seq, t, inc=inc, **fields)
    except (MessageError, TypeError):
        return _pack(mtype, src, seq, t, inc, fields)


def _omit_none(x: Any) -> bool:
    return x is None


def _omit_empty(x: Any) -> bool:
    return (type(x) is dict or type(x) is list) and not x


def _omit_zero(x: Any) -> bool:
    return type(x) is int and x == 0


def _omit_never(x: Any) -> bool:
    return False


def _layout(cls: type[Msg]) -> tuple[tuple[str, Callable[[Any], bool]], ...]:
    """A kind's fields in the order its Struct encodes them (after the tag: its own, then the
    envelope's), each with the test of the default ``omit_defaults`` leaves out (None, 0, or an
    empty map or list)."""
    names = cls.__struct_encode_fields__
    defaults = dict(zip(cls.__struct_fields__[len(cls.__struct_fields__) - len(cls.__struct_defaults__) :], cls.__struct_defaults__, strict=True))
    out = []
    for n in names:
        d = defaults.get(n, msgspec.NODEFAULT)
        out.append((n, _omit_never if d is msgspec.NODEFAULT else _omit_none if d is None else _omit_zero if d == 0 else _omit_empty))
    return tuple(out)


def _mirror(cls: type[Msg]) -> Any:
    """A Struct that encodes as ``cls`` does (its tag, its fields in their order, the same
    defaults left out) and checks nothing: what :func:`encode` packs through (msgspec's own
    encoder, in C: an edge 6.0 -> 3.8 µs, an estimate 5.4 -> 3.6 µs hot against :func:`_pack`'s loop over the fields,
    2026-12-06)."""
    n_req = len(cls.__struct_fields__) - len(cls.__struct_defaults__)
    defaults = dict(zip(cls.__struct_fields__[n_req:], cls.__struct_defaults__, strict=True))
    fields: list[Any] = [(n, Any) if n not in defaults else (n, Any, defaults[n]) for n in cls.__struct_encode_fields__]
    m = msgspec.defstruct(f"Packed{cls.__name__}", fields, kw_only=True, tag_field="type", tag=cls.__struct_config__.tag, omit_defaults=True)
    m.OPEN = cls.OPEN  # type: ignore[attr-defined]
    return m


_NONE = object()
_MIRRORS = {mtype: _mirror(cls) for mtype, cls in KINDS.items()}
_LAYOUT = {mtype: _layout(cls) for mtype, cls in KINDS.items()}
_NAMES = {mtype: frozenset(k for k, _ in layout) for mtype, layout in _LAYOUT.items()}


def _pack(mtype: str, src: Any, seq: Any, t: Any, inc: Any, fields: dict[str, Any]) -> bytes:
    """The fields packed as the kind's Struct encodes them (unchecked; a field the kind does not
    have comes after its own), or a map that says it was not encodable."""
    layout = _LAYOUT.get(mtype)
    if layout is None:
        d = {"type": mtype, "v": VERSION, "src": src, "seq": seq, "inc": inc, "t": t, **fields}
    else:
        if KINDS[mtype].OPEN and "values" not in fields:
            values = {k: x for k, x in fields.items() if k != "t_local"}
            fields = ({"t_local": fields["t_local"]} if "t_local" in fields else {}) | {"values": values}
        given = {"v": VERSION, "src": src, "seq": seq, "inc": inc, "t": t, **fields}
        d = {"type": mtype}
        for k, omit in layout:
            if k in given:
                x = given[k]
                if not omit(x):
                    d[k] = x
        own = _NAMES[mtype]
        if not given.keys() <= own:  # a field not the kind's: after its own, for the receiver to refuse
            d.update((k, x) for k, x in fields.items() if k not in own)
    try:
        return _ENCODER.encode(d)
    except (TypeError, ValueError, NotImplementedError, OverflowError):
        return _ENCODER.encode({"type": mtype, "v": VERSION, "refused": "not encodable"})


def decode(payload: bytes | Msg, expect: str | tuple[str, ...] | None = None) -> Msg:
    """Decode and validate a payload of this version; arrays come back as read-only float64
    numpy arrays.

    Raises
    ------
    MessageError
        For anything that is not a well-formed message (of type ``expect``).
    """
    if isinstance(payload, Msg):  # decoded and validated already (the in-process bus)
        _check_expect(payload.type, expect)
        return payload
    try:
        m: Msg = _DECODER.decode(payload)
    except msgspec.ValidationError as exc:
        v = version_of(payload)
        if v is not None and v != VERSION:
            raise MessageError(f"schema version {v!r}, expected {VERSION}") from None
        raise MessageError(readable(str(exc))) from None
    except msgspec.DecodeError as exc:
        raise MessageError(f"not msgpack ({str(exc)[:80]})") from None
    except (TypeError, ValueError, OverflowError, RecursionError) as exc:
        raise MessageError(f"not a message ({type(exc).__name__})") from None
    _check_expect(m.type, expect)
    return m


def decode_recorded(payload: bytes | Msg, expect: str | tuple[str, ...] | None = None) -> Msg:
    """:func:`decode`, and the payloads of recordings made before version 5 (read by
    zswarm.transport.wire_v4 into this version's messages)."""
    try:
        return decode(payload, expect)
    except MessageError:
        if isinstance(payload, bytes | bytearray | memoryview):
            if version_of(bytes(payload)) == wire_v4.V4:
                m = wire_v4.decode(bytes(payload))
                _check_expect(m.type, expect)
                return m
        raise


def decoder(mtype: str) -> Callable[[bytes | Msg], Msg]:
    """``decode(payload, mtype)``: what a receiver of one kind of message calls."""

    def dec(payload: bytes | Msg) -> Msg:
        return decode(payload, mtype)

    return dec


def _check_expect(mtype: str, expect: str | tuple[str, ...] | None) -> None:
    """A message of type ``mtype`` where ``expect`` (a type, or any of several) was expected."""
    if expect is not None and mtype != expect and (isinstance(expect, str) or mtype not in expect):
        raise MessageError(f"type {mtype!r} where {expect!r} was expected")


def check_stream(stream: str, m: Mapping[str, Any] | Msg) -> None:
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


class Oversized(bytes):
    """What :meth:`zswarm.transport.bus.ZenohBus.subscribe_polled` hands on for a payload
    its ``too_big`` refuses: no bytes (the payload is never copied out of Zenoh's buffers,
    which go back at once), only its :attr:`size`.  Empty, so it decodes as nothing: a
    malformed message."""

    size: int

    def __new__(cls, size: int) -> Oversized:
        o = super().__new__(cls, b"")
        o.size = size
        return o


def size_of(payload: bytes) -> int:
    """A payload's size in bytes, an :class:`Oversized` one's as it came."""
    return payload.size if isinstance(payload, Oversized) else len(payload)


# The largest payload of a message, by kind.  In the shipped schemes (measured on the shipped
# scenarios, 5-8 agents, 2026-12-07) an estimate is under 350 bytes, an edge message under 300,
# a command under 120, run control under 110; truth about 160 bytes an agent, a sensor packet
# under 360, stats under 1.4 KB (their counters grow with the links into an agent).
SMALL_PAYLOAD = 16 << 10  # est, edge, cmd, ctl, events: 45x the largest seen
PER_AGENT_PAYLOAD = 1 << 10  # truth, sense, stats: SMALL_PAYLOAD + this an agent
SCALED_KINDS = frozenset({"truth", "sense", "stats"})


def max_payload(n_agents: int, stream: str | None = None) -> int:
    """The largest payload (bytes) of ``stream`` (``est/3``, ``truth``, …; None: of any stream)
    in a run of ``n_agents``: what the run recorder writes as it came.  A bigger payload is
    junk: described on ``/events/malformed`` (its size), counted, never written, and never
    copied out of Zenoh (:class:`Oversized`).  Until 2026-12-07 one limit of 256 KiB held for
    every stream: 3000 junk payloads of 200 KB on est/3 were written (1.8 GB of raw
    recording) and took the recorder to 490 MiB."""
    if stream is None or stream.split("/", 1)[0] in SCALED_KINDS:
        return SMALL_PAYLOAD + PER_AGENT_PAYLOAD * max(n_agents, 1)
    return SMALL_PAYLOAD


def over_limit(n_agents: int, stream: str, size: int) -> bool:
    """Is a payload of ``size`` bytes on ``stream`` over :func:`max_payload`?  (Most are far
    under SMALL_PAYLOAD: the stream is looked at only past it.)"""
    return size > SMALL_PAYLOAD and size > max_payload(n_agents, stream)
