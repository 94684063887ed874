"""Recording of a run into an MCAP file that Foxglove and Lichtblick open.

Every message of the run is written as JSON with a JSON schema per message
type (``zswarm.truth``, ``zswarm.est``, … from :func:`zswarm.transport.wire.json_schema`)
on a channel named after its key without the ``zswarm/<run>`` prefix:
``/truth``, ``/est/3``, ``/sense/3``, ``/edge/1/3``, ``/cmd/3``,
``/stats/agent/3``, ``/ctl/start``, … plus ``/events/alive`` (liveliness
changes) and ``/events/malformed`` (what arrived under the run's keys and was
not a valid message: counted and described, never written raw).  Beside them,
:class:`zswarm.recording.foxglove.Views` derives the viewer channels: ``/tf``
(``foxglove.FrameTransforms``), ``/scene`` (``foxglove.SceneUpdate``),
``/errors/…``, ``/hybrid/…`` and ``/links/…``.  The same channels can be
served live on a Foxglove WebSocket server (``live=(host, port)``).

Log times (MCAP ``log_time``) are the receive time in ns: Unix time for
``zswarm run``, world time for ``zswarm sim`` (so a sim recording starts at
1970-01-01 in a viewer); the header metadata ``zswarm.log_time`` says which.
Every message also carries its world time ``t`` (s).

During ``zswarm run`` the recorder does no per-message work but a copy: it
writes the payloads as they came (msgpack, one channel per stream) into
``recording.raw.mcap``, flushed every 0.5 s, and the report turns that into
``recording.mcap`` after the run (:func:`transcode`).  Decoding, validating and
writing JSON for every message took a quarter of a core at 8 agents; under
load the recorder then fell behind and the router dropped what it could not
take.  With ``--live`` the recorder writes JSON as it goes (the viewer needs it).
``zswarm sim`` holds the validated messages its in-process bus delivers and
writes the viewer file after the run (``defer``), and its report reads them
from memory.

Read it back with :func:`read` (or any MCAP reader with a protobuf decoder and
a JSON parser).  Earlier recordings (msgpack payloads, topics without the
leading slash) are read too.
"""

from __future__ import annotations

import functools
import logging
import math
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import msgpack
import orjson
from mcap.reader import NonSeekingReader

from zswarm.transport import keys, wire
from zswarm.transport.bus import Bus
from zswarm.util.files import RecordingError
from zswarm.scenario import Scenario
from zswarm.recording.foxglove import object_schema

log = logging.getLogger("zswarm.recording.mcap_io")

ALIVE_CHANNEL = "events/alive"
# After the world's stop, the final stats of a process that sent stats this recently (in
# world time) before the stop's time are waited for even if its token is gone
# (Recorder.awaiting_finals): every process sends stats once a second of world time, so
# one that ran to the end sent some within the last second; 2 s allows a late one.
RECENT_STATS_S = 2.0
# A process's question "are my final stats recorded?" (keys.recorded) is held this long
# for them to arrive, then let go; the asker gives up earlier (procutil.FINAL_CONFIRM_S).
HOLD_RECORDED_S = 5.0
MALFORMED_CHANNEL = "events/malformed"
# The message type(s) each stream kind carries.
STREAM_TYPES: dict[str, str | tuple[str, ...]] = {
    "truth": "truth",
    "est": "est",
    "sense": "sense",
    "edge": "edge",
    "cmd": "cmd",
    "stats": "stats",
    "ctl": ("start", "stop", "progress"),
}
ALIVE_SCHEMA = object_schema(
    "zswarm.Alive",
    "A process's liveliness token appeared (alive) or went away",
    {"key": {"type": "string"}, "alive": {"type": "boolean"}, "t_wall": {"type": "number"}},
    ("key", "alive", "t_wall"),
)
MALFORMED_SCHEMA = object_schema(
    "zswarm.Malformed",
    "A payload under the run's keys that is not a valid zswarm message (dropped)",
    {"stream": {"type": "string"}, "reason": {"type": "string"}, "size": {"type": "integer"}},
    ("stream", "reason", "size"),
)


class _WriteErrors(logging.Filter):
    """The Foxglove SDK logs each message it could not write (``error logging message:
    McapError(Io(Os { code: 28, ... }))`` on the ``foxglove.log_sink_set`` logger) and goes
    on: a full disk printed 19 000 such lines before a traceback.  Counted and kept here
    (the first), not printed; the writers check :attr:`count` and raise RecordingError."""

    def __init__(self) -> None:
        super().__init__()
        self.count = 0
        self.first = ""

    def filter(self, record: logging.LogRecord) -> bool:
        msg = record.getMessage()
        if not msg.startswith("error logging message"):
            return True
        if not self.first:
            self.first = msg
        self.count += 1
        return False


WRITE_ERRORS = _WriteErrors()
logging.getLogger("foxglove.log_sink_set").addFilter(WRITE_ERRORS)


def io_problem(text: str, path: Path | None = None) -> str:
    """The OS's words for an I/O error in the SDK's text (``os error 28`` / ``code: 28``); a
    text without the OS's number ("I/O error from writing", from a flush) is told by the
    state of ``path``'s file system: full or read-only."""
    import errno
    import os
    import re

    m = re.search(r"(?:os error |code: )(\d+)", text)
    if m:
        return os.strerror(int(m.group(1)))
    if path is not None:
        try:
            st = os.statvfs(Path(path).parent)
        except OSError:
            return text
        if st.f_flag & os.ST_RDONLY:
            return os.strerror(errno.EROFS)
        if st.f_bavail * st.f_frsize < (1 << 20):
            return f"{os.strerror(errno.ENOSPC)} ({st.f_bavail * st.f_frsize} bytes free)"
    return text


def run_streams(sc: Scenario) -> frozenset[str]:
    """Every stream a run of ``sc`` publishes (the recorder's channels)."""
    per_agent = [f"{kind}/{i}" for i in sc.ids for kind in ("sense", "est", "cmd", "stats/agent")]
    edges = [f"edge/{s}/{i}" for s, i in sc.edges]
    return frozenset(["truth", "ctl/start", "ctl/stop", "ctl/progress", "stats/world/0", *per_agent, *edges])


def _dumps(obj: Any) -> bytes:
    return orjson.dumps(obj, option=orjson.OPT_SERIALIZE_NUMPY | orjson.OPT_NON_STR_KEYS)


class _McapOut:
    """What the two recordings' writers share (:class:`ViewerOut`, :class:`RawOut`): an MCAP
    writer (``writer``, None once closed) and maybe a live server (``server``), closed
    together; a failed write (disk full, read-only) closes them and raises RecordingError
    naming ``path`` and the problem."""

    path: Path | None
    writer: Any
    server: Any = None
    _errors0: int = 0

    def _write_metadata(self, metadata: dict[str, str]) -> None:
        try:
            self.writer.write_metadata("zswarm", metadata)
        except RuntimeError as exc:
            self._failed(WRITE_ERRORS.first or str(exc))

    def _failed(self, text: str) -> None:
        """Stop writing (and serving) and raise RecordingError naming the file and the problem."""
        writer, self.writer = self.writer, None
        self._errors0 = WRITE_ERRORS.count
        WRITE_ERRORS.first = ""  # told now: the next failure's own words are kept
        if self.server is not None:
            self.server.stop()
            self.server = None
        if writer is not None:
            try:
                writer.close()
            except Exception:  # noqa: BLE001, S110 - it failed already: the first error is the one to tell
                pass
        if self.path is not None and Path(self.path).exists() and Path(self.path).stat().st_size == 0:
            Path(self.path).unlink()  # nothing of it reached the disk: no 0-byte file is left
        raise RecordingError(f"{self.path}: cannot write the recording: {io_problem(text, self.path)}")

    def flush(self) -> None:
        if self.writer is not None:
            try:
                self.writer.flush()
            except RuntimeError as exc:
                self._failed(WRITE_ERRORS.first or str(exc))

    def close(self) -> None:
        if self.server is not None:
            self.server.stop()
            self.server = None
        if self.writer is not None:
            writer, self.writer = self.writer, None
            try:
                writer.close()
            except RuntimeError as exc:
                self._failed(WRITE_ERRORS.first or str(exc))
            if WRITE_ERRORS.count != self._errors0:
                self._failed(WRITE_ERRORS.first)


class ViewerOut(_McapOut):
    """A run's channels on a ``foxglove.Context`` whose sinks are an MCAP file
    (``path``) and/or a Foxglove WebSocket server (``live``): each message as
    JSON on its stream's channel, plus :class:`zswarm.recording.foxglove.Views`.

    Not thread-safe: one thread feeds it (the recorder's loop, ``zswarm replay``).
    """

    def __init__(
        self,
        path: Path | None,
        live: tuple[str, int] | None,
        scenario: Scenario | None,
        metadata: dict[str, str] | None = None,
        server_name: str = "zswarm",
    ) -> None:
        import foxglove
        from foxglove.mcap import MCAPCompression, MCAPWriteOptions

        from zswarm.recording.foxglove import FoxgloveSink, Views

        self.ctx = foxglove.Context()
        self.writer: Any = None
        self.server: Any = None
        self.count = 0
        self.malformed = 0
        self._channels: dict[str, Any] = {}
        self.path = path
        self._errors0 = WRITE_ERRORS.count
        if path is not None:
            opts = MCAPWriteOptions(compression=MCAPCompression.Zstd, chunk_size=4 << 20, profile="")
            self.writer = _open_mcap(path, self.ctx, opts)
            if metadata:
                self._write_metadata(metadata)
        if live is not None:
            self.server = foxglove.start_server(name=server_name, host=live[0], port=live[1], context=self.ctx)
        self.views = Views(FoxgloveSink(self.ctx, self.log_json), scenario)
        self._streams = None if scenario is None else run_streams(scenario)

    @property
    def live_port(self) -> int | None:
        return None if self.server is None else int(self.server.port)

    def message(self, stream: str, payload: bytes | dict[str, Any], t: int) -> dict[str, Any] | None:
        """Decode, validate and write one message of ``stream`` (msgpack bytes, or
        JSON as :func:`read` gives it); a malformed one is counted, described on
        ``/events/malformed`` and dropped.  Returns the decoded message or None."""
        expect = STREAM_TYPES.get(stream.split("/", 1)[0])
        try:
            if expect is None:
                raise wire.MessageError("not a zswarm stream")
            if self._streams is not None and stream not in self._streams:
                # A channel per key would be made for it: 20 000 junk keys, 20 000 channels.
                raise wire.MessageError("not a stream of this run's scenario")
            m = decode(payload, expect)
            wire.check_stream(stream, m)  # filed under its key's process, or not at all
        except wire.MessageError as exc:
            self.malformed += 1
            if self.malformed <= 10 or self.malformed % 1000 == 0:
                log.warning("dropped a malformed message on %s (%d so far): %s", stream, self.malformed, exc)
            size = len(payload) if isinstance(payload, bytes) else len(_dumps(payload))
            self.log_json(MALFORMED_CHANNEL, MALFORMED_SCHEMA, {"stream": stream[:256], "reason": str(exc)[:256], "size": size}, t)
            self.count += 1
            return None
        self.log_json(stream, m["type"], wire.to_json(m), t)
        self.count += 1
        self.views.on_message(stream, m, t)
        return m

    def alive(self, event: dict[str, Any], t: int) -> None:
        self.log_json(ALIVE_CHANNEL, ALIVE_SCHEMA, event, t)
        self.count += 1

    def log_json(self, stream: str, schema: dict[str, Any] | str, obj: Any, t: int) -> None:
        """``obj`` as JSON on the channel ``/<stream>``, made the first time with
        ``schema`` (a JSON schema, or the message type whose schema it is)."""
        ch = self._channels.get(stream)
        if ch is None:
            import foxglove

            js = wire.json_schema(schema) if isinstance(schema, str) else schema
            ch = self._channels[stream] = foxglove.Channel("/" + stream, schema=js, context=self.ctx)
        ch.log(_dumps(obj), log_time=t)
        if WRITE_ERRORS.count != self._errors0:
            self._failed(WRITE_ERRORS.first)


RAW_SUFFIX = ".raw.mcap"


def max_payload(n_agents: int) -> int:
    """The largest payload the run recorder writes as it came (bytes) for a run of
    ``n_agents``: 256 KiB plus 512 bytes per agent.  A message of the shipped schemes is far
    smaller (an estimate or an edge message under 2 KB, truth and the sensor maps under 300
    bytes per agent, stats counters under 200 bytes per link); a bigger payload is described
    on ``/events/malformed`` (its size) and not written: 300 junk payloads of 1 MB on est/3
    had grown the raw file by 300 MB in a second."""
    return (256 << 10) + 512 * max(n_agents, 1)


@functools.cache
def _raw_schema() -> Any:
    """msgpack is self-describing: the schema of a raw channel only names the wire format."""
    import foxglove

    return foxglove.Schema(name=f"zswarm.transport.wire.v{wire.VERSION}", encoding="", data=b"")


class RawOut(_McapOut):
    """The run's payloads as they came, one msgpack channel per stream, in an MCAP
    file (the format :func:`read` reads as "earlier recordings"); :func:`transcode`
    makes the viewer recording of it."""

    def __init__(self, path: Path, metadata: dict[str, str] | None = None, max_bytes: int | None = None) -> None:
        import foxglove
        from foxglove.mcap import MCAPCompression, MCAPWriteOptions

        self.ctx = foxglove.Context()
        # No chunk or message indexes: the writer keeps every chunk's index in memory
        # until it writes the summary at close, and the recorder ends a chunk every 0.5 s
        # (a file cut short stays readable up to there).  Measured with the writer alone,
        # 56 channels and a chunk per flush: +10.9 MiB of RSS over 6900 chunks (an hour of
        # the recorder) with the indexes, +0.9 MiB without.  Nothing needs them: this file
        # is read front to back (:func:`read`, by :func:`transcode`), and the viewer
        # recording made from it has its indexes.  (What else grew in the 1-hour soak,
        # bench/soak.py, was Zenoh's receive batches held by samples waiting for the
        # recorder's poll, see ZenohBus.subscribe_polled, and the free memory glibc kept
        # after a catch-up, which zswarm.engines.recorder.command gives back with procutil.trim_heap.)
        opts = MCAPWriteOptions(compression=MCAPCompression.Lz4, chunk_size=4 << 20, profile="", emit_chunk_indexes=False, emit_message_indexes=False)
        self.path = path
        self._errors0 = WRITE_ERRORS.count
        self.writer: Any = _open_mcap(path, self.ctx, opts)
        if metadata:
            self._write_metadata(metadata)
        self._channels: dict[str, Any] = {}
        self.count = 0
        self.malformed = 0  # oversized ones here; the others are counted when transcoded
        self.max_bytes = max_bytes
        self.live_port = None

    def message(self, stream: str, payload: bytes | dict[str, Any], t: int) -> None:
        if self.max_bytes is not None and isinstance(payload, bytes) and len(payload) > self.max_bytes:
            self.malformed += 1
            if self.malformed <= 10 or self.malformed % 1000 == 0:
                log.warning("dropped an oversized payload on %s (%d bytes; %d malformed so far)", stream, len(payload), self.malformed)
            desc = {"stream": stream[:256], "reason": f"payload of {len(payload)} bytes, over the {self.max_bytes} a message of this run can be", "size": len(payload)}
            payload, stream = msgpack.packb(desc), MALFORMED_CHANNEL
        ch = self._channels.get(stream)
        if ch is None:
            import foxglove

            ch = self._channels[stream] = foxglove.Channel(stream, message_encoding="msgpack", schema=_raw_schema(), context=self.ctx)
        if type(payload) is wire.Message:  # from the in-process bus
            payload = wire.encode_message(payload)
        ch.log(payload if isinstance(payload, bytes) else msgpack.packb(payload), log_time=t)
        self.count += 1
        if WRITE_ERRORS.count != self._errors0:
            self._failed(WRITE_ERRORS.first)

    def alive(self, event: dict[str, Any], t: int) -> None:
        self.message(ALIVE_CHANNEL, msgpack.packb(event), t)


def _open_mcap(path: Path, ctx: Any, opts: Any) -> Any:
    import foxglove

    try:
        return foxglove.open_mcap(path, allow_overwrite=True, context=ctx, writer_options=opts)
    except OSError as exc:  # the SDK's OSError has no errno: its text has the OS's number
        raise RecordingError(f"{path}: cannot write the recording: {io_problem(str(exc), path)}") from None


def transcode(raw: Path, out: Path, scenario: Scenario | None) -> int:
    """Write the viewer recording ``out`` (JSON with schemas, viewer channels) of the
    raw recording ``raw`` (:class:`RawOut`), then delete ``raw`` if ``out`` holds an
    entry for each of its messages (a malformed one as its description); returns the
    number of malformed messages (described on ``/events/malformed`` in ``out``).

    A raw file with no message is kept and nothing is written (:class:`EmptyRecording`):
    an empty viewer file in its place would lose what a better reader could still get."""
    from mcap.reader import make_reader

    with open(raw, "rb") as f:
        try:
            meta = {k: v for m in make_reader(f).iter_metadata() if m.name == "zswarm" for k, v in m.metadata.items()}
        except Exception:  # noqa: BLE001 - a file cut short has no summary: read it without metadata
            meta = {}
    meta["transcoded_from"] = raw.name
    tmp = out.with_name(out.name + ".part")
    try:
        vo = ViewerOut(tmp, None, scenario, meta)
    except RecordingError:
        tmp.unlink(missing_ok=True)
        raise
    n_raw = 0
    ok = False
    try:
        for stream, payload, t in read(raw):
            n_raw += 1
            if stream == MALFORMED_CHANNEL:  # described by the recorder (RawOut: oversized), as it is
                try:
                    desc = unpack(payload)
                except Exception:  # noqa: BLE001 - a foreign entry: described below as such
                    desc = {"stream": stream, "reason": "not a description", "size": len(payload)}
                vo.log_json(MALFORMED_CHANNEL, MALFORMED_SCHEMA, desc, t)
                vo.malformed += 1
                vo.count += 1
                continue
            if stream == ALIVE_CHANNEL:
                try:
                    event = unpack(payload)
                except Exception as exc:  # noqa: BLE001 - a cut or foreign entry: described, not fatal
                    vo.log_json(MALFORMED_CHANNEL, MALFORMED_SCHEMA, {"stream": stream, "reason": f"not an event: {exc}"[:256], "size": len(payload)}, t)
                    vo.malformed += 1
                    vo.count += 1
                    continue
                vo.alive(event, t)
            else:
                vo.message(stream, payload, t)
        vo.close()
        ok = True
    finally:
        if not ok:  # a write failed (disk full): the raw file stays, the partial copy goes
            try:
                vo.close()
            except RecordingError:
                pass
            tmp.unlink(missing_ok=True)
    if n_raw == 0:
        tmp.unlink(missing_ok=True)
        raise EmptyRecording(f"{raw}: no complete message in the file ({raw.stat().st_size} bytes); kept as it is")
    if vo.count < n_raw:  # cannot happen unless a write was lost: keep the source
        raise RecordingError(f"{raw}: transcoded {vo.count} of its {n_raw} messages into {tmp}; both kept")
    tmp.replace(out)
    raw.unlink()
    return vo.malformed


class EmptyRecording(RecordingError):
    """A recording file that holds no complete message."""


def ensure_recording(results: Path, scenario: Scenario | None) -> Path:
    """``results/recording.mcap``, transcoded first from ``recording.raw.mcap`` if that is
    what the recorder left (a run, or a recorder killed before the report)."""
    rec = results / "recording.mcap"
    raw = results / ("recording" + RAW_SUFFIX)
    if raw.exists():
        transcode(raw, rec, scenario)
    return rec


class Recorder:
    """Subscribes to everything of a run and writes it to ``path`` (and/or serves it live).

    Over Zenoh, samples are copied and stamped as they arrive by the bus's thread
    (:meth:`ZenohBus.subscribe_polled`); :meth:`poll` (the owner's loop, every
    ~10 ms) takes them, decodes and writes them; :meth:`flush` (at least every
    second) also ends the MCAP chunk, so a file cut short by a crash is readable
    up to the last flush.  ``path``
    None and no ``live``: keep the raw messages in memory (``messages``)
    instead (``zswarm sweep``, the step-size study).
    """

    def __init__(
        self,
        bus: Bus,
        run: str,
        path: Path | None,
        now_ns: Callable[[], int] | None = None,
        metadata: dict[str, str] | None = None,
        skip: tuple[str, ...] = (),
        scenario: Scenario | None = None,
        live: tuple[str, int] | None = None,
        raw: bool = False,
        defer: int = 0,
        rerun: Any = None,
    ) -> None:
        """``raw``: write ``path`` as :class:`RawOut` (payloads as they came; a run's
        recorder, whose report transcodes it); otherwise JSON as it goes.

        ``rerun``: also hand every message, as it is taken, to this
        :class:`zswarm.recording.rerun_view.RerunViewer` (streaming to a viewer: decoded here, in the
        recorder, off the agents' and the world's loops); finished at :meth:`close`.

        ``defer`` (``zswarm sim``): keep up to that many messages in :attr:`messages` and
        write them to ``path`` at :meth:`close`, not as they come: the viewer file's JSON
        and derived channels are then made after the run, off its loop, and the report
        reads the messages from memory instead of decoding the file back.  Past that many
        (a long run) the held ones are written out and the recorder goes on writing as
        they come (:attr:`complete` turns False: :attr:`messages` no longer holds them all)."""
        self.run = run
        # Keys of the stream prefixes not written (e.g. "sense/", "edge/" for a lean recording).
        self._skip_keys = tuple(keys.stream_key(run, s) for s in skip)
        self.path = None if path is None else Path(path)
        self.messages: list[tuple[str, Any, int]] = []  # (stream, payload bytes / Message / event, log time)
        self._defer = defer if path is not None and live is None else 0
        self.complete = True  # messages holds every message recorded (see defer)
        self.now_ns = now_ns or time.time_ns
        self._buf: list[tuple[str, bytes | dict[str, Any], int]] = []
        self._lock = threading.Lock()
        self.count = 0
        self.alive: dict[str, bool] = {}
        self.finals: set[str] = set()  # stats keys whose final counters have arrived
        self.stats_t: dict[str, float] = {}  # stats key -> world time of its latest stats
        self.stop_t: float | None = None  # world time of the world's stop
        self.stopped = threading.Event()
        self._closed = False
        self.out: ViewerOut | RawOut | None = None
        self.rerun = rerun
        meta = dict(metadata or {})
        meta.setdefault("log_time", "world time (ns from 0)" if now_ns is not None else "Unix time (ns), at the recorder's arrival")
        if raw and self.path is not None and live is None:
            self.out = RawOut(self.path, meta, None if scenario is None else max_payload(len(scenario.ids)))
        elif self.path is not None or live is not None:
            self.out = ViewerOut(self.path, live, scenario, meta, server_name=f"zswarm {run}")
        # A real bus: samples copied and stamped on arrival by the bus's thread, taken by
        # poll() (no callback contending for the GIL with the decoding); in-process: callbacks,
        # stamped at the virtual time they are delivered.
        self._drain = bus.subscribe_polled(keys.everything(run), self.now_ns) if hasattr(bus, "subscribe_polled") else None
        if self._drain is None:
            # In-process: the skipped streams are not even delivered (MemoryBus's exclude).
            bus.subscribe(keys.everything(run), self._on_data, exclude=self._skip_keys)
        # Processes asking whether their final stats are recorded (keys.recorded): answered
        # once they are, from poll(); held at most HOLD_RECORDED_S.
        self._queries = bus.queryable_polled(keys.recorded_all(run)) if hasattr(bus, "queryable_polled") else None
        self._held: list[tuple[Any, str, float]] = []  # (query, stats key, time.monotonic() to give up)
        self.confirmed = 0  # finals confirmed to their senders
        bus.watch_alive(keys.alive_all(run), self._on_alive)

    @property
    def malformed(self) -> int:
        return 0 if self.out is None else self.out.malformed

    @property
    def live_port(self) -> int | None:
        return None if self.out is None else self.out.live_port

    def _on_data(self, key: str, payload: bytes, t: int | None = None) -> None:
        if self._skip_keys and key.startswith(self._skip_keys):
            return
        t = self.now_ns() if t is None else t
        stream = keys.stream_of(self.run, key)
        with self._lock:
            self._buf.append((stream, payload, t))
        if key.endswith("/ctl/stop"):
            try:
                m = wire.decode_ctl(payload, "stop")  # only the world's stop ends the recording
                if self.stop_t is None:
                    self.stop_t = m["t"]
                self.stopped.set()
            except wire.MessageError:
                pass  # recorded as it came, counted as malformed where it is written
        elif "/stats/" in key and key not in self.finals:  # once a second per process: decoding is cheap
            try:
                m = decode(payload, "stats")
                final = m["counters"].get("final")
            except (wire.MessageError, AttributeError):
                return  # counted as malformed where it is written
            with self._lock:
                self.stats_t[key] = max(m["t"], self.stats_t.get(key, -math.inf))
                if final:
                    self.finals.add(key)

    def awaiting_finals(self, procs: list[tuple[str, int]], recent_s: float = RECENT_STATS_S) -> list[tuple[str, int]]:
        """The processes (role, id) whose final stats have not arrived and that are still up
        (liveliness token present) or, once the world's stop has come, sent stats less
        than ``recent_s`` of world time before it: each sends them as it stops, and the
        report's "alive at the end" and what the recording lacks rest on them.

        Why not the token alone: a process sends its final stats and then closes its
        session, but the token's going can be seen here first.  It is a declaration,
        which Zenoh sends ahead of data (control priority; the final stats are data
        priority, behind every real-time sample queued for this recorder when it lags),
        and it is handled on Zenoh's thread at once while a sample waits for the bus's
        thread and for :meth:`poll` (a §3.2 run of 2026-12-02 had the final stats stamped
        0.1 ms after the token went, for 2 of its 8 agents).  The stats' world time is on
        the data path itself, behind any backlog like the final stats, so a lagging
        recorder still tells a process that ran to the end from one killed mid-run."""
        with self._lock:
            recent = math.inf if self.stop_t is None else self.stop_t - recent_s  # no stop yet: the tokens alone
            return [
                (r, i)
                for r, i in procs
                if (k := keys.stats(self.run, r, i)) not in self.finals
                and (self.alive.get(keys.alive(self.run, r, i), False) or self.stats_t.get(k, -math.inf) >= recent)
            ]

    def missing_finals(self, procs: list[tuple[str, int]]) -> list[tuple[str, int]]:
        """The processes (role, id) seen up at some time whose final stats never came."""
        with self._lock:
            return [(r, i) for r, i in procs if keys.stats(self.run, r, i) not in self.finals and keys.alive(self.run, r, i) in self.alive]

    def _on_alive(self, key: str, alive: bool) -> None:
        t = self.now_ns()
        event = {"key": key, "alive": alive, "t_wall": time.time()}
        with self._lock:
            self.alive[key] = alive
            self._buf.append((ALIVE_CHANNEL, event if self.out is not None else msgpack.packb(event), t))

    def poll(self) -> None:
        """Take what has arrived (call it every ~10 ms) and write it to the outputs,
        without ending the MCAP chunk."""
        self._take(flush=False)

    def flush(self) -> None:
        """:meth:`poll`, then end the MCAP chunk: the file is readable up to here."""
        self._take(flush=True)

    def _take(self, flush: bool) -> None:
        if self._drain is not None:
            for key, payload, t in self._drain():
                self._on_data(key, payload, t)
        if self._queries is not None:
            self._answer(self._queries())
        with self._lock:
            buf, self._buf = self._buf, []
            if self._closed:
                return
            if self.rerun is not None:
                for stream, payload, t in buf:
                    self.rerun.message(stream, payload, t)
            if self.out is None or self._defer:
                self.messages.extend(buf)  # raw payloads (or events) as they came
                self.count += len(buf)
                if self.out is None or len(self.messages) <= self._defer:
                    return
                buf, self.messages, self._defer, self.complete = self.messages, [], 0, False  # a long run: write as they come from here
            for stream, payload, t in buf:
                if stream == ALIVE_CHANNEL:
                    self.out.alive(payload, t)  # type: ignore[arg-type]  # an event dict
                else:
                    self.out.message(stream, payload, t)
            if flush:
                self.out.flush()
            self.count = self.out.count

    def _answer(self, new: list[Any]) -> None:
        """Reply to each process that asked whether its final stats are recorded and whose
        final stats are in (taken by this poll or an earlier one); let go of a question
        held HOLD_RECORDED_S (its sender stops asking first, procutil.FINAL_CONFIRM_S) or
        foreign."""
        now = time.monotonic()
        for query in new:
            who = keys.parse_recorded(self.run, str(query.key_expr))
            if who is None:
                _drop(query)
                continue
            self._held.append((query, keys.stats(self.run, *who), now + HOLD_RECORDED_S))
        keep = []
        for query, key, give_up in self._held:
            if key in self.finals:
                try:
                    query.reply(query.key_expr, b"1")
                    self.confirmed += 1
                except Exception as exc:  # noqa: BLE001 - the asker may be gone: nothing to answer
                    log.debug("could not confirm %s: %s", key, exc)
                _drop(query)
            elif now >= give_up or self._closed:
                _drop(query)
            else:
                keep.append((query, key, give_up))
        self._held = keep

    def close(self) -> None:
        self.flush()
        for query, _key, _t in self._held:
            _drop(query)
        self._held = []
        with self._lock:
            if self._closed:
                return
            self._closed = True
            if self.rerun is not None:
                self.rerun.finish(self.rerun.horizon)
            if self.out is not None:
                if self._defer:
                    for stream, payload, t in self.messages:
                        if stream == ALIVE_CHANNEL:
                            self.out.alive(payload if isinstance(payload, dict) else unpack(payload), t)
                        else:
                            self.out.message(stream, payload, t)
                    self.count = self.out.count
                self.out.close()


def _drop(query: Any) -> None:
    """End a Zenoh query for its asker (it is finalized when every copy is dropped)."""
    try:
        query.drop()
    except Exception as exc:  # noqa: BLE001 - dropped already, or the session is closing
        log.debug("query drop: %s", exc)


def read(path: str | Path) -> Iterator[tuple[str, Any, int]]:
    """Yield ``(stream, message, log_time_ns)`` of the run's messages in file order.

    ``message`` is the JSON object as written (:func:`zswarm.transport.wire.from_json`
    validates it), or the msgpack payload (bytes) of an old recording.  The
    derived viewer channels are left out.  Uses the streaming reader, so a
    file cut short (no summary section) is read up to its last complete chunk
    instead of failing.

    File order, not log-time order: a recorder writes in arrival order (log times
    out of order by at most the bus thread's hand-over, ~ms), and the streaming
    reader's log-time order sorts the whole file in memory first, so a file cut
    short by a SIGKILL yielded nothing at all (the truncation ended the sort).
    """
    with open(path, "rb") as f:
        reader = NonSeekingReader(f)
        try:
            for _schema, channel, message in reader.iter_messages(log_time_order=False):
                topic = channel.topic
                if channel.message_encoding == "msgpack":
                    yield topic, message.data, message.log_time
                elif channel.message_encoding == "json" and topic[1:].split("/", 1)[0] in STREAM_TYPES | {"events": 0}:
                    yield topic[1:], orjson.loads(message.data), message.log_time
        except Exception as exc:  # a truncated tail ends the stream
            if not _is_truncation(exc):
                raise


def recorded_run_id(path: Path) -> str | None:
    """The run id the recording was made under (its ``ctl/start``), if any."""
    for stream, payload, _t in read(path):
        if stream == "ctl/start":
            try:
                return str(decode(payload, "start")["run"])
            except wire.MessageError:
                return None
    return None


def _is_truncation(exc: Exception) -> bool:
    name = type(exc).__name__
    return name in ("EndOfFile", "InvalidMagic", "RecordLengthLimitExceeded") or isinstance(exc, (EOFError, ValueError))


def decode(message: bytes | dict[str, Any], expect: str | tuple[str, ...] | None = None) -> dict[str, Any]:
    """A message as :func:`read` (or an in-memory recording) gives it, decoded and validated."""
    if type(message) is wire.Message or isinstance(message, bytes):  # validated already (sim), or a payload
        return wire.decode(message, expect)
    return wire.from_json(message, expect)


def unpack(payload: bytes | dict[str, Any]) -> Any:
    """An ``events/…`` entry: JSON as written, or msgpack of an old recording."""
    return payload if isinstance(payload, dict) else msgpack.unpackb(payload, raw=False, strict_map_key=False)
