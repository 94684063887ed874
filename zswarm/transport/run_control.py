"""Run-control messages (start, stop, progress on ctl/...): signed with the run's secret when
there is one, and checked beyond their schema on receipt (only the world controls a run)."""

from __future__ import annotations

import functools
import typing
from collections.abc import Mapping
from typing import Any

from zswarm.transport import keys
from zswarm.transport.message_checks import ENVELOPE, MessageError
from zswarm.transport.messages import KINDS
from zswarm.transport.wire import decode, encode


@functools.cache
def _signed_fields(mtype: str) -> tuple[tuple[str, bool], ...]:
    """The fields of a run-control kind its signature covers, sorted: (name, a float field)."""
    hints = typing.get_type_hints(KINDS[mtype])
    return tuple((k, hints[k] is float) for k in sorted(KINDS[mtype].__struct_fields__) if k not in ENVELOPE and k != "mac")


def ctl_mac(secret: bytes, m: Mapping[str, Any]) -> str:
    """The signature of a run-control message: HMAC-SHA256 with the run's secret over its
    envelope and fields (floats by their exact hex), 32 hex digits."""
    import hashlib
    import hmac

    parts = [str(m["type"]), str(m["src"]), str(m["seq"]), str(m["inc"]), float(m["t"]).hex()]
    for k, is_float in _signed_fields(str(m["type"])):
        v = m[k]  # a float field is signed as the float the receiver decodes (1 and 1.0 alike)
        parts.append(f"{k}={float(v).hex() if is_float else v}")
    return hmac.new(secret, "|".join(parts).encode(), hashlib.sha256).hexdigest()[:32]


def encode_ctl(mtype: str, src: int, seq: int, t: float, *, inc: int = 0, **fields: Any) -> bytes:
    """A run-control message, signed (``mac``) with the run's secret when there is one
    (keys.run_secret)."""
    secret = keys.run_secret()
    if secret is not None:
        fields["mac"] = ctl_mac(secret, {"type": mtype, "src": src, "seq": seq, "inc": inc, "t": float(t), **fields})
    return encode(mtype, src, seq, t, inc=inc, **fields)


def decode_ctl(payload: bytes, expect: str) -> Any:
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


def check_ctl(m: Any, expect: str) -> Any:
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
