"""A minimal Foxglove WebSocket client for the tests, independent of zswarm's code.

It speaks the Foxglove WebSocket protocol (subprotocol ``foxglove.sdk.v1``)
with the ``websockets`` library: reads the server's ``serverInfo`` and
``advertise`` ops, subscribes to topics, and decodes binary ``MessageData``
frames (opcode 1: u32 subscription id, u64 log time, payload) with the
advertised schema, protobuf (a base64 ``FileDescriptorSet``) or JSON.
"""

from __future__ import annotations

import base64
import json
import struct
import time
from typing import Any

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from websockets.sync.client import connect

SUBPROTOCOL = "foxglove.sdk.v1"


def _protobuf_class(schema_name: str, schema_b64: str) -> Any:
    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(schema_b64))
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


class Client:
    def __init__(self, url: str, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while True:
            try:
                # Entered as a context manager (websockets ≥ 16 warns otherwise); left in close().
                self.ws = connect(url, subprotocols=[SUBPROTOCOL], open_timeout=5).__enter__()  # type: ignore[list-item]
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
        assert self.ws.subprotocol == SUBPROTOCOL
        self.channels: dict[int, dict[str, Any]] = {}
        self.by_topic: dict[str, dict[str, Any]] = {}
        self.subs: dict[int, dict[str, Any]] = {}
        self.server_info: dict[str, Any] | None = None
        self._next_sub = 1

    def close(self) -> None:
        self.ws.__exit__(None, None, None)

    def _handle_text(self, text: str) -> None:
        op = json.loads(text)
        if op.get("op") == "serverInfo":
            self.server_info = op
        elif op.get("op") == "advertise":
            for ch in op["channels"]:
                self.channels[ch["id"]] = ch
                self.by_topic[ch["topic"]] = ch

    def _next(self, deadline: float, what: str) -> bytes | None:
        """The next binary frame before ``deadline`` (text ops are handled here: None)."""
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError(what)
        try:
            msg = self.ws.recv(timeout=left)
        except TimeoutError:
            return None
        if isinstance(msg, str):
            self._handle_text(msg)
            return None
        return msg

    def wait_for_topics(self, topics: set[str], timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while not topics <= set(self.by_topic):
            self._next(deadline, f"not advertised within {timeout} s: {sorted(topics - set(self.by_topic))} (have {sorted(self.by_topic)})")

    def subscribe(self, topics: list[str]) -> None:
        subs = []
        for topic in topics:
            ch = self.by_topic[topic]
            sid = self._next_sub
            self._next_sub += 1
            decode: Any
            if ch["encoding"] == "protobuf":
                cls = _protobuf_class(ch["schemaName"], ch["schema"])
                decode = cls.FromString
            elif ch["encoding"] == "json":
                decode = json.loads
            else:
                raise AssertionError(f"{topic}: encoding {ch['encoding']}")
            self.subs[sid] = {"topic": topic, "decode": decode, "schema": ch}
            subs.append({"id": sid, "channelId": ch["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def receive(self, want: int, timeout: float) -> list[tuple[str, int, Any]]:
        """``want`` messages of the subscribed topics as ``(topic, log_time, decoded)``."""
        out: list[tuple[str, int, Any]] = []
        deadline = time.monotonic() + timeout
        while len(out) < want:
            msg = self._next(deadline, f"{len(out)} of {want} messages within {timeout} s")
            if msg is None or msg[0] != 1:  # not MessageData (time, service responses, ...)
                continue
            sid, log_time = struct.unpack_from("<IQ", msg, 1)
            sub = self.subs.get(sid)
            if sub is not None:
                out.append((sub["topic"], log_time, sub["decode"](msg[13:])))
        return out
