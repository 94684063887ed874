"""Transport behind a small protocol: ``ZenohBus`` (real) and ``MemoryBus`` (in-process).

Callbacks receive ``(key, payload)`` and must only store what they get: they
run on Zenoh's threads (ZenohBus) or inside ``put`` (MemoryBus).  This is the
only module that imports zenoh.
"""

from __future__ import annotations

import json
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any, Protocol

from zswarm.transport import wire

DataCallback = Callable[[str, Any], None]  # (key, payload bytes, or a wire.Message on MemoryBus)
AliveCallback = Callable[[str, bool], None]


class Publisher(Protocol):
    def put(self, payload: bytes) -> None: ...

    def publish(self, mtype: str, src: int, seq: int, t: float, *, inc: int = 0, **fields: Any) -> None:
        """Send a message (``wire.encode``'s arguments): over Zenoh its bytes, on a
        MemoryBus the validated message itself (``wire.message``)."""
        ...


class Bus(Protocol):
    def publisher(self, key: str, block: bool = False) -> Publisher: ...
    def subscribe(self, key_expr: str, callback: DataCallback, direct: bool = False, exclude: tuple[str, ...] = ()) -> None: ...
    def declare_token(self, key: str) -> None: ...
    def watch_alive(self, key_expr: str, callback: AliveCallback) -> None: ...
    def close(self) -> None: ...


# --------------------------------------------------------------------------- key expressions


def key_matches(key_expr: str, key: str) -> bool:
    """Zenoh-style matching of a concrete ``key`` by ``key_expr`` (``*`` one chunk, ``**`` any)."""
    pat = key_expr.split("/")
    ks = key.split("/")

    def m(a: int, b: int) -> bool:
        if a == len(pat):
            return b == len(ks)
        if pat[a] == "**":
            return any(m(a + 1, c) for c in range(b, len(ks) + 1))
        if b == len(ks):
            return False
        return (pat[a] == "*" or pat[a] == ks[b]) and m(a + 1, b + 1)

    return m(0, 0)


# --------------------------------------------------------------------------- in-process


class MemoryBus:
    """In-process bus: ``put`` delivers synchronously to every matching subscriber.

    Deterministic: subscribers are called in the order they subscribed.  Used by
    ``zswarm sim`` and the component tests; never a stand-in for Zenoh in
    integration tests.
    """

    def __init__(self, objects: bool = True) -> None:
        """``objects``: :meth:`Publisher.publish` delivers the validated message (``wire.message``),
        decoded and checked once for every subscriber, instead of bytes each decodes
        (``objects=False``, what a Zenoh subscriber gets: the reference the tests compare
        the two with, bit for bit)."""
        self.objects = objects
        self._subs: list[tuple[str, DataCallback, tuple[str, ...]]] = []
        self._watchers: list[tuple[str, AliveCallback]] = []
        self._tokens: set[str] = set()
        self._cache: dict[str, list[DataCallback]] = {}

    def publisher(self, key: str, block: bool = False) -> Publisher:
        return _MemoryPub(self, key)

    def put(self, key: str, payload: Any) -> None:
        """Deliver ``payload`` (bytes, or a ``wire.Message``) to every subscriber of ``key``."""
        cbs = self._cache.get(key)
        if cbs is None:
            cbs = [cb for ke, cb, ex in self._subs if key_matches(ke, key) and not (ex and key.startswith(ex))]
            self._cache[key] = cbs
        for cb in cbs:
            cb(key, payload)

    def subscribe(self, key_expr: str, callback: DataCallback, direct: bool = False, exclude: tuple[str, ...] = ()) -> None:
        """``exclude``: keys starting with one of these are not delivered to ``callback`` (a
        lean recording's sensor and edge streams: one call less per message, decided once
        per key)."""
        self._subs.append((key_expr, callback, exclude))
        self._cache.clear()

    def declare_token(self, key: str) -> None:
        self._tokens.add(key)
        for ke, cb in self._watchers:
            if key_matches(ke, key):
                cb(key, True)

    def undeclare_token(self, key: str) -> None:
        """Withdraw a token, as a killed process's session would."""
        if key in self._tokens:
            self._tokens.discard(key)
            for ke, cb in self._watchers:
                if key_matches(ke, key):
                    cb(key, False)

    def watch_alive(self, key_expr: str, callback: AliveCallback) -> None:
        self._watchers.append((key_expr, callback))
        for key in sorted(self._tokens):
            if key_matches(key_expr, key):
                callback(key, True)

    def close(self) -> None:
        self._subs.clear()
        self._watchers.clear()
        self._cache.clear()

    def session(self) -> MemorySession:
        """A process's own view of the bus: closing it withdraws its subscriptions, watches
        and tokens, as a killed process's Zenoh session would (``zswarm sim``'s faults)."""
        return MemorySession(self)


class _MemoryPub:
    """A MemoryBus publisher: ``put`` delivers bytes, ``publish`` a validated message."""

    __slots__ = ("bus", "key", "make")

    def __init__(self, bus: MemoryBus, key: str) -> None:
        self.bus, self.key = bus, key
        self.make = wire.message if bus.objects else wire.encode

    def put(self, payload: bytes) -> None:
        self.bus.put(self.key, payload)

    def publish(self, mtype: str, src: int, seq: int, t: float, *, inc: int = 0, **fields: Any) -> None:
        self.bus.put(self.key, self.make(mtype, src, seq, t, inc=inc, **fields))


class _ZenohPub:
    """A Zenoh publisher behind :class:`Publisher`: ``put`` is the publisher's own."""

    __slots__ = ("put",)

    def __init__(self, pub: Any) -> None:
        self.put = pub.put

    def publish(self, mtype: str, src: int, seq: int, t: float, *, inc: int = 0, **fields: Any) -> None:
        self.put(wire.encode(mtype, src, seq, t, inc=inc, **fields))


class MemorySession:
    """One process's session on a :class:`MemoryBus` (see :meth:`MemoryBus.session`)."""

    def __init__(self, bus: MemoryBus) -> None:
        self.bus = bus
        self._cbs: list[Any] = []
        self._tokens: set[str] = set()
        self.closed = False

    def publisher(self, key: str, block: bool = False) -> Publisher:
        return self.bus.publisher(key, block)

    def put(self, key: str, payload: Any) -> None:
        self.bus.put(key, payload)

    def subscribe(self, key_expr: str, callback: DataCallback, direct: bool = False, exclude: tuple[str, ...] = ()) -> None:
        self._cbs.append(callback)
        self.bus.subscribe(key_expr, callback, direct, exclude)

    def declare_token(self, key: str) -> None:
        self._tokens.add(key)
        self.bus.declare_token(key)

    def undeclare_token(self, key: str) -> None:
        self._tokens.discard(key)
        self.bus.undeclare_token(key)

    def watch_alive(self, key_expr: str, callback: AliveCallback) -> None:
        self._cbs.append(callback)
        self.bus.watch_alive(key_expr, callback)

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        mine = {id(cb) for cb in self._cbs}
        self.bus._subs = [(k, cb, ex) for k, cb, ex in self.bus._subs if id(cb) not in mine]
        self.bus._watchers = [(k, cb) for k, cb in self.bus._watchers if id(cb) not in mine]
        self.bus._cache.clear()
        for key in sorted(self._tokens):
            self.bus.undeclare_token(key)
        self._tokens.clear()


# --------------------------------------------------------------------------- Zenoh

MAX_MESSAGE = 8 << 20  # bytes: what wire.max_payload allows a message of a run of 8000 agents
# Samples in Zenoh's FIFO of subscribe_polled (its thread empties it as they come).  They wait
# there only while that thread gets no CPU or no GIL, or has max_bytes waiting; a full FIFO
# makes Zenoh stop reading the link (the kernel's socket buffer and the router's queue take
# the backlog: ~5000 messages of a run), nothing is lost for it unless that lasts past the
# lease (1 s: keep-alives unread, the link is closed).  With up to MAX_MESSAGE a sample, it
# bounds what a flood can pile up there: 16 x 8 MiB.  It was 1024: with a core kept busy,
# 200 KB junk payloads piled up there (the recorder's RSS +131 MiB) before the thread could
# reduce them to their size.
_POLLED_FIFO = 16
POLLED_MAX_BYTES = 64 << 20  # payload bytes subscribe_polled's thread holds at most before it stops taking samples
LEASE_MS = 1000  # Zenoh's session lease here (Zenoh's default is 10 s): see zenoh_config


def zenoh_config(
    mode: str = "client",
    connect: Sequence[str] = (),
    listen: Sequence[str] = (),
    config_file: str | None = None,
    lease_ms: int = LEASE_MS,
    secure: tuple[str, str] | None = None,
    acl: dict[str, Any] | None = None,
) -> Any:
    """A ``zenoh.Config`` for zswarm: no multicast scouting, explicit endpoints, short lease.

    The lease bounds how long a hung (not killed) process's liveliness token
    survives; 1 s instead of Zenoh's default 10 s.
    """
    import zenoh

    conf = zenoh.Config.from_file(config_file) if config_file else zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", "false")
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
        # Processes may be started in any order (README's manual way): a client
        # retries for 30 s before giving up on a router that is not up yet.
        conf.insert_json5("connect/timeout_ms", "{router: -1, peer: -1, client: 30000}")
        conf.insert_json5("connect/exit_on_failure", "{router: false, peer: false, client: true}")
        conf.insert_json5("connect/retry", "{period_init_ms: 100, period_max_ms: 1000, period_increase_factor: 2}")
    # Never let Zenoh pick its default tcp/[::] listener: only what we were told.
    conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("transport/link/tx/lease", str(lease_ms))
    conf.insert_json5("transport/link/tx/keep_alive", "4")
    # Zenoh's default TX queue is 2 batches per priority with a 1 ms wait before
    # dropping: on 2 cores shared by ~11 processes, a receiver descheduled for a
    # few ms then loses samples (measured: ~1.5 % of sensor packets).  16
    # batches (the maximum) absorb such stalls; DROP still bounds the latency.
    for prio in ("real_time", "data"):
        conf.insert_json5(f"transport/link/tx/queue/size/{prio}", "16")
    # A message over MAX_MESSAGE is dropped by Zenoh while it reassembles it (by default it
    # would reassemble up to 1 GiB).  Zenoh's shared memory off: no message of a run comes
    # near its 3 KiB threshold (truth at 20 agents would), and with it on a peer's big
    # payloads made the recorder map the peer's 16 MiB pools (34 MiB of /dev/shm in its RSS
    # after 300 junk payloads of 1 MiB, measured 2026-12-07); it is no use across hosts or
    # containers either.
    conf.insert_json5("transport/link/rx/max_message_size", str(MAX_MESSAGE))
    conf.insert_json5("transport/shared_memory/enabled", "false")
    if secure is not None:  # (certificate folder, this process's name): zswarm/transport/secure.py
        from pathlib import Path

        from zswarm.transport import secure as sec

        sec.apply(conf, Path(secure[0]), secure[1], acl)
    return conf


class ZenohBus:
    """A real Zenoh session behind the :class:`Bus` protocol (a context manager).

    Publishers use ``CongestionControl.DROP`` and ``Priority.REAL_TIME``
    (DESIGN.md: never BLOCK on a control path).  They are not ``express``:
    express sends every message as its own batch, so a burst queued for a
    briefly descheduled receiver overflows the TX queue; batching only
    delays a message when a backlog already exists.
    Everything declared is closed with the session in :meth:`close`.
    """

    def __init__(self, conf: Any) -> None:
        import zenoh

        self._z = zenoh
        self.session = zenoh.open(conf)
        self._objs: list[Any] = []
        self._tokens: dict[str, Any] = {}
        self._threads: list[threading.Thread] = []  # subscribe_polled's
        self._lock = threading.Lock()
        self._closed = False

    def __enter__(self) -> ZenohBus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def publisher(self, key: str, block: bool = False) -> Publisher:
        """``block``: ``CongestionControl.BLOCK`` and data priority, for what is not
        a control path and must lose nothing (``zswarm replay``)."""
        z = self._z
        pub = self.session.declare_publisher(
            key,
            congestion_control=z.CongestionControl.BLOCK if block else z.CongestionControl.DROP,
            priority=z.Priority.DATA if block else z.Priority.REAL_TIME,
            express=False,
        )
        self._objs.append(pub)
        return _ZenohPub(pub)

    def subscribe(self, key_expr: str, callback: DataCallback, direct: bool = False, exclude: tuple[str, ...] = ()) -> None:
        """``exclude``: keys starting with one of these are not passed to ``callback``.
        ``direct``: run ``callback`` on Zenoh's receiving thread instead of handing each
        sample to a Python thread of its own (zenoh-python's default).  Cheaper (no thread
        wake-up per sample) but the receiving thread then waits for the GIL for every
        sample, holding up the link: on an overloaded machine long enough to miss the
        lease (see ``agent.inbox.Inbox.handler``)."""

        def _cb(sample: Any) -> None:
            key = str(sample.key_expr)
            if not (exclude and key.startswith(exclude)):
                callback(key, sample.payload.to_bytes())

        handler = self._z.handlers.Callback(_cb, indirect=False) if direct else _cb
        self._objs.append(self.session.declare_subscriber(key_expr, handler))

    def subscribe_polled(
        self, key_expr: str, stamp: Callable[[], int], capacity: int = 1 << 18, max_bytes: int = POLLED_MAX_BYTES, too_big: Callable[[str, int], bool] | None = None
    ) -> Callable[[], list[tuple[str, bytes, int]]]:
        """Samples of ``key_expr`` as ``(key, payload, stamp())``, copied off Zenoh's receive
        buffers as they arrive by a thread of this bus; the returned function takes what
        has arrived.

        For a subscriber that does real work per message (the recorder).  Not a callback:
        Zenoh's receive task would wait for the GIL (up to the 5 ms switch interval per
        sample) while the owner computes.  The thread waits in the FIFO channel's ``recv``
        with the GIL released and holds it only to copy a sample out.  Not the owner
        polling the FIFO either (as this did up to 2026-12-02): a sample waiting in
        Zenoh's FIFO keeps the 64 KiB receive batch it arrived in, and Zenoh allocates a
        fresh batch for every read meanwhile; a recorder 1 s behind held ~14 MiB of them
        (heaptrack), memory glibc kept after the catch-up, and the recorder's RSS
        ratcheted up over a soak.  Stamped on arrival, not when the owner gets round to
        the sample.

        At most ``capacity`` samples, or ``max_bytes`` of payload, wait: then the thread
        stops taking them, Zenoh's FIFO (a few batches) fills, Zenoh waits, and the router
        drops for this subscriber only (DROP congestion control).  (300 junk payloads of
        1 MB in a second took the recorder from 72 to 338 MB.)

        A payload ``too_big(key, size)`` is not copied: a :class:`zswarm.transport.wire.Oversized`
        (its size) stands for it, so junk bigger than any message of its kind costs nothing
        while it waits and never stops the thread.
        """
        sub = self.session.declare_subscriber(key_expr, self._z.handlers.FifoChannel(_POLLED_FIFO))
        self._objs.append(sub)
        fifo = sub.handler  # recv on the handler: undeclaring the subscriber closes it and ends the thread
        arrived: deque[tuple[str, bytes, int]] = deque()
        size = [0, 0]  # payload bytes appended (by the thread), taken (by drain): each written by one thread only

        def pump() -> None:
            while True:
                try:
                    sample = fifo.recv()
                except Exception:  # noqa: BLE001 - ZError "channel is empty and closed": the bus closed
                    return
                key, n = str(sample.key_expr), len(sample.payload)
                payload = wire.Oversized(n) if too_big is not None and too_big(key, n) else sample.payload.to_bytes()
                arrived.append((key, payload, stamp()))
                size[0] += len(payload)
                del sample  # its receive batch goes back to Zenoh now, not at the next sample
                while (len(arrived) >= capacity or size[0] - size[1] >= max_bytes) and not self._closed:
                    time.sleep(0.001)

        thread = threading.Thread(target=pump, name=f"zenoh-fifo {key_expr}", daemon=True)
        thread.start()
        self._threads.append(thread)

        def drain(limit: int = 100_000) -> list[tuple[str, bytes, int]]:
            out = [arrived.popleft() for _ in range(min(limit, len(arrived)))]
            size[1] += sum(len(p) for _, p, _ in out)
            return out

        return drain

    def queryable_polled(self, key_expr: str, capacity: int = 256) -> Callable[[], list[Any]]:
        """Queries on ``key_expr`` waiting in a FIFO; the returned function takes them (Zenoh
        ``Query`` objects: the owner replies and then ``drop()``s each, which ends it for the
        querier).  Polled like :meth:`subscribe_polled`: the owner answers from its own loop."""
        q = self.session.declare_queryable(key_expr, self._z.handlers.FifoChannel(capacity))
        self._objs.append(q)

        def take() -> list[Any]:
            out = []
            while (query := q.try_recv()) is not None:
                out.append(query)
            return out

        return take

    def confirm(self, key: str, timeout: float) -> bool:
        """Ask ``key`` (a Zenoh query) and wait up to ``timeout`` s for a reply: True if one
        came.  False at once when nothing serves ``key`` (Zenoh ends such a query
        immediately).  The query goes after everything this session has sent on the same
        priority, and the session stays open meanwhile (see
        :func:`zswarm.transport.keys.recorded`)."""
        replies = self.session.get(key, timeout=timeout)
        return any(reply.ok is not None for reply in replies)

    def declare_token(self, key: str) -> None:
        token = self.session.liveliness().declare_token(key)
        self._objs.append(token)
        self._tokens[key] = token

    def undeclare_token(self, key: str) -> None:
        token = self._tokens.pop(key, None)
        if token is not None:
            self._objs.remove(token)
            token.undeclare()

    def watch_alive(self, key_expr: str, callback: AliveCallback) -> None:
        z = self._z

        def _cb(sample: Any) -> None:
            callback(str(sample.key_expr), sample.kind == z.SampleKind.PUT)

        self._objs.append(self.session.liveliness().declare_subscriber(key_expr, _cb, history=True))

    def close(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
        for obj in reversed(self._objs):
            try:
                obj.undeclare()
            except Exception:  # noqa: BLE001 - best effort; the session close below is what matters
                pass
        self._objs.clear()
        for thread in self._threads:  # their channels closed with the subscribers: they end
            thread.join(timeout=2.0)  # before the interpreter (a thread inside Zenoh at exit aborts it)
        self.session.close()
