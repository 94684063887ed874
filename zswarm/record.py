"""Recording of a run into an MCAP file: one channel per stream, raw msgpack payloads.

Channels are the keys without the ``zswarm/<run>/`` prefix (``truth``,
``est/3``, ``sense/3``, ``edge/1/3``, ``stats/agent/3``, ``ctl/start``, …) plus
``events/alive`` (liveliness changes, msgpack ``{"key", "alive", "t_wall"}``).
Message ``log_time`` is the receive time in ns: Unix time for ``run``, world
time for ``sim``.  Read it back with :func:`read` (or any MCAP reader).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import msgpack
from mcap.reader import NonSeekingReader
from mcap.writer import CompressionType, Writer

from zswarm import keys
from zswarm.bus import Bus

ENCODING = "msgpack"
ALIVE_CHANNEL = "events/alive"


class Recorder:
    """Subscribes to everything of a run and writes it to ``path``.

    Callbacks only append to a buffer; :meth:`flush` (called by the owner's
    loop, at least every second) writes the buffer and ends an MCAP chunk, so
    a file cut short by a crash is readable up to the last flush.
    """

    def __init__(
        self,
        bus: Bus,
        run: str,
        path: Path | None,
        now_ns: Callable[[], int] | None = None,
        metadata: dict[str, str] | None = None,
        skip: tuple[str, ...] = (),
    ) -> None:
        self.run = run
        # Keys of the stream prefixes not written (e.g. "sense/", "edge/" for a lean recording).
        self._skip_keys = tuple(keys.stream_key(run, s) for s in skip)
        # path None: keep the messages in memory (``messages``) instead of writing a file.
        self.path = None if path is None else Path(path)
        self.messages: list[tuple[str, bytes, int]] = []
        self.now_ns = now_ns or time.time_ns
        self._buf: list[tuple[str, bytes, int]] = []
        self._lock = threading.Lock()
        self._f = None if self.path is None else open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self._w = None if self._f is None else Writer(self._f, compression=CompressionType.ZSTD, chunk_size=4 << 20)
        if self._w is not None:
            self._w.start(profile="zswarm", library="zswarm")
            if metadata:
                self._w.add_metadata("zswarm", metadata)
        self._channels: dict[str, int] = {}
        self.count = 0
        self.alive: dict[str, bool] = {}
        self.stopped = threading.Event()
        self._closed = False
        bus.subscribe(keys.everything(run), self._on_data)
        bus.watch_alive(keys.alive_all(run), self._on_alive)

    def _on_data(self, key: str, payload: bytes) -> None:
        if self._skip_keys and key.startswith(self._skip_keys):
            return
        t = self.now_ns()
        stream = keys.stream_of(self.run, key)
        with self._lock:
            self._buf.append((stream, payload, t))
        if key.endswith("/ctl/stop"):
            self.stopped.set()

    def _on_alive(self, key: str, alive: bool) -> None:
        t = self.now_ns()
        payload = msgpack.packb({"key": key, "alive": alive, "t_wall": time.time()})
        with self._lock:
            self.alive[key] = alive
            self._buf.append((ALIVE_CHANNEL, payload, t))

    def flush(self) -> None:
        with self._lock:
            buf, self._buf = self._buf, []
            if self._closed:
                return
            if self._w is None:
                self.messages.extend(buf)
                self.count += len(buf)
                return
            for topic, payload, t in buf:
                ch = self._channels.get(topic)
                if ch is None:
                    ch = self._w.register_channel(topic, ENCODING, 0)
                    self._channels[topic] = ch
                self._w.add_message(ch, log_time=t, data=payload, publish_time=t)
                self.count += 1
            self._w.flush()

    def close(self) -> None:
        self.flush()
        with self._lock:
            if self._closed:
                return
            self._closed = True
            if self._w is not None and self._f is not None:
                self._w.finish()
                self._f.close()


def read(path: str | Path) -> Iterator[tuple[str, bytes, int]]:
    """Yield ``(channel, payload, log_time_ns)`` in file order.

    Uses the streaming reader, so a file cut short (no summary section) is read
    up to its last complete chunk instead of failing.
    """
    with open(path, "rb") as f:
        reader = NonSeekingReader(f)
        try:
            for _schema, channel, message in reader.iter_messages():
                yield channel.topic, message.data, message.log_time
        except Exception as exc:  # noqa: BLE001 - a truncated tail ends the stream
            if not _is_truncation(exc):
                raise


def _is_truncation(exc: Exception) -> bool:
    name = type(exc).__name__
    return name in ("EndOfFile", "InvalidMagic", "RecordLengthLimitExceeded") or isinstance(exc, (EOFError, ValueError))


def unpack(payload: bytes) -> Any:
    return msgpack.unpackb(payload, raw=False, strict_map_key=False)
