"""An agent's inbox: what the bus's callbacks hand over (decoded, validated, counted, stamped
at arrival), held per source behind its link model until released, and the newest of each
kept for the tick (agent/runtime.py); and the steps a tick takes on the packets it holds."""

from __future__ import annotations

import copy
import heapq
import logging
import statistics
from collections import deque
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any, TypeVar

import numpy as np

from zswarm.scenario.links import LinkCounter, LinkModel
from zswarm.transport import wire
from zswarm.transport.messages import Msg, Sense

log = logging.getLogger("zswarm.agent")

# Edge messages kept per link: 160 ms at 100 Hz, more than the data age of any
# step that is not already stale (the default max_age of the §3/§4 observers is 0.2 s).
RECENT_EDGE_MESSAGES = 16
MAX_NEIGHBOR_EVENTS = 256  # liveliness changes of in-neighbours kept for the stats
MAX_LOGGED_KEYS = 16  # keys whose malformed messages are logged (once each); the rest are counted only
# Arrivals waiting for the agent's thread (Inbox._pending): a tick normally finds a few (200 Hz
# sensors and 100 Hz neighbours), a 1 s stall ~400.  Past this many, an arrival is dropped and
# counted (inbox_overflow): a flood of junk grew the queue without bound (+26 MB).
MAX_PENDING = 4096
_SENSE_FIELDS = frozenset(Sense.__struct_fields__) - frozenset(wire.ENVELOPE)  # what a sensor packet holds besides its envelope
SERIES = ("gyro", "velocity", "velocity_body", "attitude", "position")  # the sense packet's arrays, kept as time series


class Inbox:
    """Newest decoded message per source key, with per-link counters and malformed counts."""

    def __init__(self, log_name: str, now: Callable[[], float], link_model: Callable[[str], LinkModel] | None = None) -> None:
        # Arrivals not yet processed: (processor, key, payload, arrival stamp), appended by
        # the bus callbacks (any thread), taken by drain() on the agent's thread.
        self._pending: deque[tuple[Callable[[str, bytes, float], None], str, bytes, float]] = deque()
        self.now = now  # the receiver's own clock, stamps every arrival as "rx"
        # Link emulation (zswarm/scenario/links.py): each arrival is lost or held until its release time.
        self._link_model = link_model
        self.models: dict[str, LinkModel] = {}
        self._held: list[tuple[float, int, str, str, Msg]] = []
        self._held_n = 0
        self.latest: dict[str, Msg] = {}
        # Recent messages per edge, oldest first (sequence order): a step at time t
        # reads the newest one stamped at or before t (see :meth:`at_or_before`).
        self.recent: dict[str, deque[Msg]] = {}
        # Recent sensor packets, oldest first (in sequence order): the histories the
        # timing library integrates and interpolates over.
        self.packets: deque[Msg] = deque(maxlen=64)
        self._series: dict[str, deque[tuple[float, np.ndarray]]] = {}  # per array field: (t, value), as packets
        self.links: dict[str, LinkCounter] = {}
        self.malformed = 0
        self.overflow = [0]  # arrivals dropped because MAX_PENDING were waiting (bumped by the callbacks)
        self._logged: set[str] = set()
        self._log = logging.getLogger(log_name)

    def handler(
        self,
        expect: str,
        link_of: Callable[[str], str | None],
        validate: Callable[[Msg], object] | None = None,
        decode: Callable[[bytes], Msg] | None = None,
        sender: Callable[[str], int] | None = None,
    ) -> Callable[[str, bytes], None]:
        """A bus callback for messages of type ``expect``; ``validate`` raises ValueError
        on a message that decodes but is not what this agent's algorithm reads;
        ``decode``: ``wire.decode(payload, expect)`` (the default) or its equivalent.

        The callback only stamps the arrival on the receiver's clock and queues the
        payload (one deque append, thread-safe): decoding, validation, link emulation
        and storage happen on the agent's own thread when it next reads the inbox
        (:meth:`drain`).  So the callback holds the GIL for microseconds, no lock is
        taken, and nothing it does waits for a tick in progress.  Over Zenoh it runs on
        zenoh-python's own thread, not on Zenoh's receiving thread (``direct=False``):
        there, each sample's wait for the GIL held up the whole link, and on an
        overloaded machine (16 agents on 2 cores) a batch of them outlasted the 1 s
        lease, so an agent saw every token go and come back (measured: 5 of 16 agents
        "lost the world's token" in a 20 s run; since, 0 or 1, and fewer missed deadlines).
        """
        process = partial(self._process, expect, link_of, validate, decode or partial(wire.decode, expect=expect), sender)
        pending, now, overflow = self._pending, self.now, self.overflow

        def on_message(key: str, payload: bytes) -> None:
            if len(pending) >= MAX_PENDING:
                overflow[0] += 1  # only ever incremented here, under the GIL: a lost count at worst
                return
            pending.append((process, key, payload, now()))

        return on_message

    def drain(self) -> None:
        """Process every queued arrival, in arrival order (the readers below call this)."""
        pending = self._pending
        while pending:
            process, key, payload, rx = pending.popleft()
            process(key, payload, rx)

    def _process(
        self,
        expect: str,
        link_of: Callable[[str], str | None],
        validate: Callable[[Msg], object] | None,
        decode: Callable[[bytes], Msg],
        sender: Callable[[str], int] | None,
        key: str,
        payload: bytes,
        rx: float,
    ) -> None:
        """Decode, validate, emulate the link and store one arrival (stamped ``rx`` on arrival)."""
        link = link_of(key)
        try:
            if link is None:
                raise wire.MessageError("key is not one of this agent's links")
            msg = decode(payload)
            if sender is not None and msg.src != sender(link):
                raise wire.MessageError(f"from src {msg.src} on {link}'s key")
            if validate is not None:
                validate(msg)
        except ValueError as exc:
            self.malformed += 1
            # Once per key, for at most MAX_LOGGED_KEYS keys: 20 000 junk keys were 20 000 lines.
            if key not in self._logged and len(self._logged) < MAX_LOGGED_KEYS:
                self._logged.add(key)
                self._log.warning("dropped malformed message on %s: %s (logged once per key)", key, exc)
            return
        if msg is payload:  # the in-process bus shares one validated message among its receivers
            msg = copy.copy(msg)
        msg.rx_net = rx  # off the network, before any emulated delay (not sent: Msg's dict)
        if self._held:
            # Held messages due by now go first: a message released on arrival
            # must not overtake one held on the same link (FIFO links), nor be
            # stored before older data that is already due.
            self._release(rx)
        if self._link_model is not None:
            model = self.models.get(link)
            if model is None:
                model = self.models[link] = self._link_model(link)
            release = model.admit(rx)
            if release is None:
                return  # lost on the emulated link (counted by the model)
            if release > rx:
                heapq.heappush(self._held, (release, self._held_n, link, expect, msg))
                self._held_n += 1
                return
        self._deliver(link, expect, msg, rx)

    def _deliver(self, link: str, expect: str, msg: Msg, rx: float) -> None:
        """Store a message that has reached this agent."""
        msg.rx = rx
        sent = msg.t_local if expect != "sense" else msg.t
        counter = self.links.get(link)
        if counter is None:
            counter = self.links[link] = LinkCounter()
        restarts = counter.restarts
        if counter.see(msg.seq, msg.inc, rx - sent):
            if counter.restarts != restarts and expect != "sense":
                self.recent.pop(link, None)  # the dead incarnation's messages mean nothing now
            self.latest[link] = msg
            if expect == "sense":
                self.packets.append(msg)
                t = msg.t
                for name in SERIES:
                    v = getattr(msg, name)
                    if v is not None:
                        series = self._series.get(name)
                        if series is None:
                            series = self._series[name] = deque(maxlen=self.packets.maxlen)
                        series.append((t, v))
            else:
                recent = self.recent.get(link)
                if recent is None:
                    recent = self.recent[link] = deque(maxlen=RECENT_EDGE_MESSAGES)
                recent.append(msg)

    def release_due(self) -> None:
        """Process the arrivals, then deliver every held message whose release time has
        come (the agent calls this each tick)."""
        self.drain()
        if self._held:
            self._release(self.now())

    def _release(self, now: float) -> None:
        """Deliver the held messages due at ``now``, in release order."""
        while self._held and self._held[0][0] <= now:
            release, _, link, expect, msg = heapq.heappop(self._held)
            self._deliver(link, expect, msg, release)

    def get(self, link: str) -> Msg | None:
        """The newest message on ``link`` (arrivals queued so far processed first)."""
        if self._pending:
            self.drain()
        return self.latest.get(link)

    def sensor_transit(self, local: Callable[[float], float], n: int = 16) -> float:
        """Median transit of the last ``n`` sensor packets (arrival off the network, before any
        emulated delay, minus the stamp, on this agent's clock); 0 when none or negative."""
        ps = list(self.packets)[-n:]
        if not ps:
            return 0.0
        return max(0.0, statistics.median([p.rx_net - local(p.t) for p in ps]))

    def recent_packets(self, after: float) -> list[Msg]:
        """Sensor packets acquired after world time ``after`` (oldest first), with the
        newest one at or before it first when there is one."""
        return since(self.packets, after, lambda p: p.t)

    def at_or_before(self, link: str, t_world: float) -> Msg | None:
        """The newest message on an edge stamped at or before ``t_world``; if every
        recent one is newer, the oldest of them (None: nothing received yet)."""
        recent = self.recent.get(link)
        if not recent:
            return None
        for m in reversed(recent):
            if m.t <= t_world:
                return m
        return recent[0]

    def samples(self, name: str, j: int | None = None) -> list[tuple[float, np.ndarray]]:
        """``(acquisition world time, value)`` of a field of recent sensor packets ("gyro",
        "velocity"), or with ``j``, of a per-neighbour field's entry for j (``rel_att``)."""
        if j is None:
            series = self._series.get(name)
            return list(series) if series is not None else []
        if name in _SENSE_FIELDS:  # a field of the packets' Struct: read as attributes, not through the Mapping view (378 calls a tick on §4.5)
            out = []
            for p in self.packets:
                m = getattr(p, name)
                if m is not None and j in m:
                    out.append((p.t, m[j]))
            return out
        return [(p.t, p[name][j]) for p in self.packets if j in p.get(name, ())]

    def vectors(self, key: int | str) -> list[tuple[float, np.ndarray, np.ndarray]]:
        """``(acquisition world time, body-frame vector, gyro)`` of recent sensor packets: the
        bearing toward agent ``key`` (int) or the packet field ``key`` ("velocity_body")."""
        if isinstance(key, int):
            return [(p.t, p.bearings[key], p.gyro) for p in self.packets if p.bearings is not None and key in p.bearings]
        if key in _SENSE_FIELDS:
            return [(p.t, v, p.gyro) for p in self.packets if (v := getattr(p, key)) is not None]
        return [(p.t, p[key], p.gyro) for p in self.packets if key in p]

    def counters(self) -> dict[str, Any]:
        self.drain()
        links = {k: v.as_dict() for k, v in self.links.items()}
        for k, m in self.models.items():
            if m.spec.active:
                links.setdefault(k, {"delivered": 0, "dropped": 0, "reordered": 0}).update(m.counters())
        return {"links": links, "malformed": self.malformed} | ({"inbox_overflow": self.overflow[0]} if self.overflow[0] else {})


P = TypeVar("P")


def since(items: Sequence[P], after: float, time: Callable[[P], float]) -> list[P]:
    """The items of a time-ordered sequence acquired after ``after`` (oldest first), with the
    newest one at or before it first when there is one (Inbox.recent_packets; the batched
    engine's sensor-delay plan reads its packets the same way)."""
    out: list[P] = []
    for p in reversed(items):
        out.append(p)
        if time(p) <= after:
            break
    out.reverse()
    return out


def step_ends(packets: Sequence[tuple[float, P]], t_step: float, t_end: float, period: float, newest_before: P) -> list[tuple[float, P]]:
    """Where the steps from the last one (``t_step``) to ``t_end`` end, each with the newest
    sensor packet at or before it: ``packets`` are ``(time, packet)`` of the packets after
    ``t_step``, oldest first, with the newest at or before it first when there is one
    (``Inbox.recent_packets``); ``newest_before``: the packet to read when none is newer.

    Normally one step (sensors at 200 Hz, ticks at 100 Hz: the packet of the
    tick or 5 ms before it).  After a stall, one step per clock period, each
    ending at the last packet within a period of the previous end, or a
    period on when the world skipped samples there (the view then reads
    the history around that time).  The batched engine plans its delayed
    sensor links' steps with it too (agent/batched.py).
    """
    ends: list[tuple[float, P]] = []
    last, k = t_step, 0
    while last < t_end - 1e-12:
        limit = min(last + period * (1.0 + 1e-6), t_end)
        best = None
        while k < len(packets) and packets[k][0] <= limit + 1e-12:
            best = packets[k]
            k += 1
        if best is not None and best[0] > last:
            last, newest_before = best
        else:
            last = min(last + period, t_end)
        ends.append((last, newest_before))
    return ends
