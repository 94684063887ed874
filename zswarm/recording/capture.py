"""The recorder's capture: everything of a run taken from the bus and written to an MCAP file
(zswarm.recording.mcap_io) as it arrives, or kept in memory, or served live."""

from __future__ import annotations

import functools
import logging
import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgpack

from zswarm.recording.mcap_io import ALIVE_CHANNEL, HOLD_RECORDED_S, RECENT_STATS_S, RawOut, ViewerOut, decode, unpack
from zswarm.scenario import Scenario
from zswarm.transport import keys, run_control, wire
from zswarm.transport.bus import Bus

log = logging.getLogger("zswarm.recording.capture")


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
            self.out = RawOut(self.path, meta, None if scenario is None else len(scenario.ids))
        elif self.path is not None or live is not None:
            self.out = ViewerOut(self.path, live, scenario, meta, server_name=f"zswarm {run}")
        # A real bus: samples copied and stamped on arrival by the bus's thread, taken by
        # poll() (no callback contending for the GIL with the decoding); in-process: callbacks,
        # stamped at the virtual time they are delivered.
        # A payload bigger than any message of its kind is junk: only its size is kept.
        too_big = None if scenario is None else functools.partial(_too_big, run, len(scenario.ids))
        self._drain = bus.subscribe_polled(keys.everything(run), self.now_ns, too_big=too_big) if hasattr(bus, "subscribe_polled") else None
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
                m = run_control.decode_ctl(payload, "stop")  # only the world's stop ends the recording
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


def _too_big(run: str, n_agents: int, key: str, size: int) -> bool:
    """Is a payload of ``size`` bytes on ``key`` over :func:`zswarm.transport.wire.max_payload` of its stream?"""
    return wire.over_limit(n_agents, keys.stream_of(run, key), size)


def _drop(query: Any) -> None:
    """End a Zenoh query for its asker (it is finalized when every copy is dropped)."""
    try:
        query.drop()
    except Exception as exc:  # noqa: BLE001 - dropped already, or the session is closing
        log.debug("query drop: %s", exc)
