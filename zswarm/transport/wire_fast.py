"""A decoder per message type and field set (:func:`decoder`): msgspec's typed decoding of the
common shapes, falling back to :func:`zswarm.transport.wire.decode` for anything else, with the
same result and the same errors."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any, Literal

import numpy as np

from zswarm.math.limits import MAX_ABS  # (ROT_TOL: see _check_semantic)
from zswarm.transport.wire import _D_ARR, _D_MAP, _D_NUM, _SEMANTIC, decode
from zswarm.transport.wire_schema import _F8, MAX_ID, MAX_IDS, MAX_SEQ, OPEN, OPTIONAL, SCHEMAS, VERSION, Message, MessageError, _Slow


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
