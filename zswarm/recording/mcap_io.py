"""Recording of a run into an MCAP file that Foxglove and Lichtblick open.

Every message of the run is written as JSON with a JSON schema per message
type (``zswarm.truth``, ``zswarm.est``, … from :func:`zswarm.transport.wire_json.json_schema`)
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
``recording.mcap`` after the run, reading the run in the same pass (:func:`transcoded`;
``zswarm report`` of such a folder: :func:`transcode`).  Decoding, validating and
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
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import msgpack
import orjson

from zswarm.recording.foxglove import object_schema
from zswarm.recording.mcap_read import Lost, records
from zswarm.recording.write_errors import WRITE_ERRORS, io_problem
from zswarm.scenario import Scenario
from zswarm.transport import wire, wire_json
from zswarm.util.files import RecordingError

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
# What reading the raw recording could not read (a damaged or cut chunk, mcap_read.Lost), kept in
# the viewer recording made from it: the raw file goes, its damage is still told.
LOST_CHANNEL = "events/lost"
EVENTS_PREFIX = "events/"  # the channels of events a run's recording has (alive, malformed, lost)
LOST_SCHEMA = object_schema(
    "zswarm.Lost",
    "A part of the raw recording that could not be read (damage, or a file cut short)",
    {"text": {"type": "string"}, "offset": {"type": "integer"}},
    ("text", "offset"),
)
ALIVE_SCHEMA = object_schema(
    "zswarm.Alive",
    "A process's liveliness token appeared (alive) or went away",
    {"key": {"type": "string"}, "alive": {"type": "boolean"}, "t_wall": {"type": "number"}},
    ("key", "alive", "t_wall"),
)
MALFORMED_SCHEMA = object_schema(
    "zswarm.Malformed",
    "Payloads under the run's keys that are not valid zswarm messages (dropped): one described, or count of them on a key",
    {"stream": {"type": "string"}, "reason": {"type": "string"}, "size": {"type": "integer"}, "count": {"type": "integer"}},
    ("stream", "reason", "size"),
)
# Junk is described one entry a message for the first DESCRIBE_PER_KEY on a key (and
# DESCRIBE_IN_ALL in all), then counted per key: one entry a key every MALFORMED_EVERY_S of log
# time with how many came and their bytes.  A flood of 245 000 junk messages left 245 000
# entries, a recording 3x a clean one's size; keys beyond MAX_JUNK_KEYS share one count.
DESCRIBE_PER_KEY = 10
DESCRIBE_IN_ALL = 1000
MALFORMED_EVERY_S = 1.0
MAX_JUNK_KEYS = 256
OTHER_KEYS = "(other keys)"


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
        self._described: dict[str, int] = {}  # junk described one by one, per key
        self._described_n = 0  # and in all (a sum over the keys for every junk message was O(keys) in a flood)
        self._junk: dict[str, list[Any]] = {}  # key -> [count, bytes, first reason] not yet written
        self._junk_due: int | None = None  # log time to write those counts at
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
        # Set: called with what :func:`read` would give of each entry written on a run's channel
        # (a message as decoded, an ``events/…`` entry as its JSON), in file order; not with the
        # derived viewer channels.  :func:`transcoded` hands the report the run so.
        self.tap: Callable[[str, Any, int], None] | None = None

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
            if self.malformed <= 10 or _tenfold(self.malformed):
                log.warning("dropped a malformed message on %s (%d so far): %s", stream, self.malformed, exc)
            size = wire.size_of(payload) if isinstance(payload, bytes) else len(wire.encode_message(payload)) if isinstance(payload, wire.Message) else len(_dumps(payload))
            self.junk(stream[:256], str(exc)[:256], size, t)
            self.count += 1
            return None
        self.log_json_bytes(stream, m["type"], wire_json.to_json_bytes(m), t)
        self.count += 1
        if self.tap is not None:
            self.tap(stream, m, t)
        self.views.on_message(stream, m, t)
        return m

    def junk(self, stream: str, reason: str, size: int, t: int, count: int = 1) -> None:
        """``count`` malformed messages on ``stream`` at log time ``t``: described on
        /events/malformed while few, else counted per key (see DESCRIBE_PER_KEY)."""
        n = self._described.get(stream, 0)
        if count == 1 and n < DESCRIBE_PER_KEY and self._described_n < DESCRIBE_IN_ALL:
            self._described[stream] = n + 1
            self._described_n += 1
            self.log_json(MALFORMED_CHANNEL, MALFORMED_SCHEMA, {"stream": stream, "reason": reason, "size": size}, t)
            return
        key = stream if stream in self._junk or len(self._junk) < MAX_JUNK_KEYS else OTHER_KEYS
        acc = self._junk.setdefault(key, [0, 0, reason])
        acc[0] += count
        acc[1] += size
        if self._junk_due is None:
            self._junk_due = t + int(MALFORMED_EVERY_S * 1e9)
        elif t >= self._junk_due:
            self.flush_junk(t)

    def flush_junk(self, t: int) -> None:
        """Write the counts of junk not yet written (one entry a key)."""
        for key, (n, size, reason) in self._junk.items():
            self.log_json(MALFORMED_CHANNEL, MALFORMED_SCHEMA, {"stream": key, "reason": f"{n} malformed, the first: {reason}"[:256], "size": size, "count": n}, t)
        self._junk.clear()
        self._junk_due = None

    def close(self) -> None:
        if self._junk:
            self.flush_junk(self._junk_due or 0)
        super().close()

    def alive(self, event: dict[str, Any], t: int) -> None:
        self.log_json(ALIVE_CHANNEL, ALIVE_SCHEMA, event, t)
        self.count += 1

    def log_json(self, stream: str, schema: dict[str, Any] | str, obj: Any, t: int) -> None:
        """``obj`` as JSON on the channel ``/<stream>``, made the first time with
        ``schema`` (a JSON schema, or the message type whose schema it is)."""
        data = _dumps(obj)
        self.log_json_bytes(stream, schema, data, t)
        if self.tap is not None and stream.startswith(EVENTS_PREFIX):
            self.tap(stream, orjson.loads(data), t)  # as read() gives it back

    def log_json_bytes(self, stream: str, schema: dict[str, Any] | str, data: bytes, t: int) -> None:
        """:meth:`log_json` of what is JSON already."""
        ch = self._channels.get(stream)
        if ch is None:
            import foxglove

            js = wire_json.json_schema(schema) if isinstance(schema, str) else schema
            ch = self._channels[stream] = foxglove.Channel("/" + stream, schema=js, context=self.ctx)
        ch.log(data, log_time=t)
        if WRITE_ERRORS.count != self._errors0:
            self._failed(WRITE_ERRORS.first)


RAW_SUFFIX = ".raw.mcap"


@functools.cache
def _raw_schema() -> Any:
    """msgpack is self-describing: the schema of a raw channel only names the wire format."""
    import foxglove

    return foxglove.Schema(name=f"zswarm.transport.wire.v{wire.VERSION}", encoding="", data=b"")


class RawOut(_McapOut):
    """The run's payloads as they came, one msgpack channel per stream, in an MCAP
    file (the format :func:`read` reads as "earlier recordings"); :func:`transcode`
    makes the viewer recording of it."""

    def __init__(self, path: Path, metadata: dict[str, str] | None = None, n_agents: int | None = None) -> None:
        """``n_agents``: a payload over :func:`zswarm.transport.wire.max_payload` of its
        stream is described, not written (None: every payload is written)."""
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
        self.n_agents = n_agents
        self.live_port = None

    def message(self, stream: str, payload: bytes | dict[str, Any], t: int) -> None:
        if isinstance(payload, bytes) and (isinstance(payload, wire.Oversized) or (self.n_agents is not None and wire.over_limit(self.n_agents, stream, len(payload)))):
            size = wire.size_of(payload)
            self.malformed += 1
            if self.malformed <= 10 or _tenfold(self.malformed):
                log.warning("dropped an oversized payload on %s (%d bytes; %d malformed so far)", stream, size, self.malformed)
            most = "" if self.n_agents is None else f", over the {wire.max_payload(self.n_agents, stream)} a message of this run's {stream.split('/', 1)[0]} can be"
            desc = {"stream": stream[:256], "reason": f"payload of {size} bytes{most}", "size": size}
            payload, stream = msgpack.packb(desc), MALFORMED_CHANNEL
        ch = self._channels.get(stream)
        if ch is None:
            import foxglove

            ch = self._channels[stream] = foxglove.Channel(stream, message_encoding="msgpack", schema=_raw_schema(), context=self.ctx)
        if isinstance(payload, wire.Message):  # from the in-process bus
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
    steps = _transcode(raw, out, scenario, None)
    while True:
        try:
            next(steps)
        except StopIteration as done:
            return int(done.value)


def transcoded(raw: Path, out: Path, scenario: Scenario | None) -> Iterator[tuple[str, Any, int]]:
    """:func:`transcode`, yielding as it writes them the run's entries, as :func:`read` of
    ``out`` would give them (a message decoded and validated: :func:`decode` takes it as it
    is): the report reads the run in the same pass as it is transcoded, not from the file
    after it.  Measured 2026-12-07 on a quiet 2-core machine, §3.2 over 40 s: from the
    recorder's end to summary.json 7.8 s reading the file back, 5.6 s in one pass.
    ``out`` is in place (and ``raw`` gone) once the iteration has ended (the last ``next``
    may yield nothing); an error of the transcode is raised from the iteration, and one
    closed before its end leaves ``raw`` as it was and no ``out``."""
    yield from _transcode(raw, out, scenario, [])


def _transcode(raw: Path, out: Path, scenario: Scenario | None, taken: list[tuple[str, Any, int]] | None) -> Iterator[tuple[str, Any, int]]:
    """:func:`transcode`'s steps; with ``taken`` (a list), each entry written on a run's
    channel is yielded after the message that wrote it (none without).  Returns the number
    of malformed messages."""
    from zswarm.recording.mcap_read import metadata

    meta = metadata(raw)  # in file order: a raw file cut by a SIGKILL keeps it too (it has no summary)
    meta["transcoded_from"] = raw.name
    tmp = out.with_name(out.name + ".part")
    try:
        vo = ViewerOut(tmp, None, scenario, meta)
    except RecordingError:
        tmp.unlink(missing_ok=True)
        raise
    if taken is not None:
        vo.tap = lambda stream, obj, t: taken.append((stream, obj, t))
    n_raw = 0
    ok = False
    losses: list[Lost] = []
    try:
        t_last = 0
        for stream, payload, t in read(raw, losses):
            n_raw += 1
            t_last = max(t_last, t)
            if stream == MALFORMED_CHANNEL:  # described by the recorder (RawOut: oversized), as it is
                try:
                    desc = unpack(payload)
                except Exception:  # noqa: BLE001 - a foreign entry: described below as such
                    desc = {"stream": stream, "reason": "not a description", "size": len(payload)}
                if not isinstance(desc, dict):
                    desc = {"stream": stream, "reason": "not a description", "size": len(payload)}
                vo.junk(str(desc.get("stream", stream))[:256], str(desc.get("reason", ""))[:256], _int(desc.get("size")), t)
                vo.malformed += 1
                vo.count += 1
            elif stream == ALIVE_CHANNEL:
                try:
                    event = unpack(payload)
                except Exception as exc:  # noqa: BLE001 - a cut or foreign entry: described, not fatal
                    vo.junk(stream, f"not an event: {exc}"[:256], len(payload), t)
                    vo.malformed += 1
                    vo.count += 1
                else:
                    vo.alive(event, t)
            else:
                vo.message(stream, payload, t)
            if taken:
                yield from taken
                taken.clear()
        for x in losses:  # stamped at the end: the reader names where in the file, not when
            vo.log_json(LOST_CHANNEL, LOST_SCHEMA, {"text": x.text(), "offset": x.offset}, t_last)
            vo.count += 1
        vo.close()  # writes the junk counts not yet written
        ok = True
    finally:
        if not ok:  # a write failed (disk full), or the reader stopped: the raw file stays, the partial copy goes
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
    if taken:
        yield from taken  # the losses and junk counts, written last
        taken.clear()
    return vo.malformed


def _tenfold(n: int) -> bool:
    """100, 1000, 10 000 ...: when a count of dropped messages is worth a log line again
    (a flood of 245 000 logged 245 lines at every thousandth)."""
    while n >= 10 and n % 10 == 0:
        n //= 10
    return n == 1


def _int(x: Any) -> int:
    return x if isinstance(x, int) and not isinstance(x, bool) and 0 <= x < 2**53 else 0


class EmptyRecording(RecordingError):
    """A recording file that holds no complete message."""


def ensure_recording(results: Path, scenario: Scenario | None) -> Path:
    """``results/recording.mcap``, transcoded first from ``recording.raw.mcap`` if that is
    what the recorder left (a recorder killed before the report, or run without one)."""
    rec = results / "recording.mcap"
    raw = results / ("recording" + RAW_SUFFIX)
    if raw.exists():
        transcode(raw, rec, scenario)
    return rec


def recording_entries(results: Path, scenario: Scenario | None) -> Path | Iterator[tuple[str, Any, int]]:
    """What the report reads of ``results``: the entries of the raw recording as
    :func:`transcoded` writes them into ``recording.mcap`` (in the same pass) if the recorder
    left ``recording.raw.mcap``, else the path of ``recording.mcap`` (:func:`read` it)."""
    rec = results / "recording.mcap"
    raw = results / ("recording" + RAW_SUFFIX)
    return transcoded(raw, rec, scenario) if raw.exists() else rec


def read(path: str | Path, lost: list[Lost] | None = None) -> Iterator[tuple[str, Any, int]]:
    """Yield ``(stream, message, log_time_ns)`` of the run's messages in file order.

    ``message`` is the JSON object as written (:func:`zswarm.transport.wire_json.from_json`
    validates it), or the msgpack payload (bytes) of an old recording.  The
    derived viewer channels are left out.

    File order, not log-time order: a recorder writes in arrival order (log times
    out of order by at most the bus thread's hand-over, ~ms), and the streaming
    reader's log-time order sorts the whole file in memory first, so a file cut
    short by a SIGKILL yielded nothing at all (the truncation ended the sort).

    A file cut short or damaged is read past the damage where its format allows
    (:func:`zswarm.recording.mcap_read.records`); each loss goes into ``lost``, or
    without it is printed on stderr as one line.  A file that is not MCAP at all raises
    :class:`~zswarm.recording.mcap_read.NotMcap` (a RecordingError naming it).
    """
    losses: list[Lost] = [] if lost is None else lost
    try:
        for channel, message in records(path, losses):
            topic = channel.topic
            if channel.message_encoding == "msgpack":
                yield topic, message.data, message.log_time
            elif channel.message_encoding == "json" and topic[1:].split("/", 1)[0] in STREAM_TYPES | {"events": 0}:
                try:
                    obj = orjson.loads(message.data)
                except orjson.JSONDecodeError as exc:  # a chunk whose CRC was 0 (unchecked) with damage inside
                    losses.append(Lost(Path(path), -1, f"{topic}: a message that is not JSON ({exc})", "dropped"))
                    continue
                yield topic[1:], obj, message.log_time
    finally:
        if lost is None:
            for x in losses:
                print(f"warning: {x.text()}", file=sys.stderr)


def recorded_run_id(path: Path) -> str | None:
    """The run id the recording was made under (its ``ctl/start``), if any."""
    for stream, payload, _t in read(path, []):  # its losses are told by whoever reads it whole
        if stream == "ctl/start":
            try:
                return str(decode(payload, "start")["run"])
            except wire.MessageError:
                return None
    return None


def decode(message: bytes | dict[str, Any] | wire.Message, expect: str | tuple[str, ...] | None = None) -> wire.Message:
    """A message as :func:`read` (or an in-memory recording) gives it, decoded and validated."""
    if isinstance(message, wire.Message | bytes):  # validated already (sim), or a payload (of this version or an earlier recording's)
        return wire.decode_recorded(message, expect)
    return wire_json.from_json(message, expect)


def unpack(payload: bytes | dict[str, Any]) -> Any:
    """An ``events/…`` entry: JSON as written, or msgpack of an old recording."""
    return payload if isinstance(payload, dict) else msgpack.unpackb(payload, raw=False, strict_map_key=False)
