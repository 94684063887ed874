"""ZenohBus over real sessions: the recorder's subscription (subscribe_polled)."""

from __future__ import annotations

import threading
import time

import pytest

from tests.integration.conftest import wait_for
from zswarm.engines.launch import free_port
from zswarm.transport.bus import ZenohBus, zenoh_config

pytestmark = pytest.mark.integration


def _pumps() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("zenoh-fifo")]


def test_polled_samples_are_copied_and_stamped_on_arrival_and_bounded():
    """Samples are taken off Zenoh as they arrive (stamped then, not when the owner polls;
    a sample left in Zenoh's FIFO held its 64 KiB receive batch), at most ``capacity``
    wait, none is lost while the owner catches up, and the thread ends with the bus.

    Past ``capacity`` the thread stops taking samples, Zenoh's FIFO (bus._POLLED_FIFO, 16)
    fills and Zenoh stops reading the link: a blocking publisher (zswarm replay's) then
    waits, which is how none of t/slow's 500 is lost (sent from a thread of its own: it
    waits until the owner polls); a run's publishers drop instead (congestion control
    DROP: the router drops for that subscriber only).  A link not read for longer than the
    lease (1 s) is closed, keep-alives unread: the owner polls t/slow within 0.3 s here.
    (With the FIFO at 1024 the 400 waited in it: a flood's payloads did too, bus.py.)"""
    ep = f"tcp/127.0.0.1:{free_port()}"
    with ZenohBus(zenoh_config("peer", listen=[ep])) as rx, ZenohBus(zenoh_config("peer", connect=[ep])) as tx:
        fast = rx.subscribe_polled("t/fast", time.time_ns)
        slow = rx.subscribe_polled("t/slow", time.time_ns, capacity=100)
        assert len(_pumps()) == 2
        pf, ps = tx.publisher("t/fast"), tx.publisher("t/slow", block=True)
        wait_for(lambda: (pf.put(b"probe"), fast())[1], 30, "the peers connected")  # type: ignore[func-returns-value]
        time.sleep(0.2)
        fast()
        for i in range(3000):
            pf.put(i.to_bytes(4, "big"))
        sent = time.time_ns()
        time.sleep(1.5)  # the owner busy elsewhere
        polled = time.time_ns()
        got = fast()
        assert [int.from_bytes(p, "big") for _, p, _ in got] == list(range(3000))
        # Stamped on arrival: within 1 s of the last put (a core kept busy by another
        # process delays the thread by scheduler slices of ms), so at least 0.5 s before
        # the poll.  Stamped at the poll (the old way) they would all read `polled`.
        assert max(t for _, _, t in got) < sent + 1_000_000_000 < polled - 400_000_000
        sender = threading.Thread(target=lambda: [ps.put(i.to_bytes(4, "big")) for i in range(500)])
        sender.start()
        time.sleep(0.3)  # well within the lease
        first = slow()
        assert len(first) == 100  # capacity: the rest waits in Zenoh, not in our memory
        rest: list = []
        wait_for(lambda: rest.extend(slow()) or len(rest) >= 400, 30, "the rest of t/slow")
        assert [int.from_bytes(p, "big") for _, p, _ in first + rest] == list(range(500))  # none lost
        sender.join(30)
    wait_for(lambda: not _pumps(), 5, "the threads ended with the bus")


def test_the_recorder_confirms_the_final_stats_it_has_and_only_those():
    """A process asks (ZenohBus.confirm, a query on keys.recorded) before it closes its
    session: the recorder answers once it has that process's final stats, holds the
    question until then, and never answers for stats it does not have.  Without a
    recorder the question ends at once."""
    from zswarm.recording.capture import Recorder
    from zswarm.transport import keys, wire

    def final(i: int) -> bytes:
        return wire.encode("stats", i, 0, 1.0, role="agent", counters={"final": True})

    ep = f"tcp/127.0.0.1:{free_port()}"
    with ZenohBus(zenoh_config("peer", listen=[ep])) as rb, ZenohBus(zenoh_config("peer", connect=[ep])) as pb:
        rec = Recorder(rb, "r", None)
        polling = threading.Event()

        def poll() -> None:  # the recorder's loop (zswarm record polls every 10 ms)
            while not polling.wait(0.01):
                rec.poll()

        poller = threading.Thread(target=poll)
        poller.start()
        try:
            probe = pb.publisher(keys.stats("r", "agent", 9), block=True)
            wait_for(lambda: (probe.put(final(9)), pb.confirm(keys.recorded("r", "agent", 9), 1.0))[1], 30, "the peers connected")  # type: ignore[func-returns-value]
            answer: dict[str, bool] = {}
            asker = threading.Thread(target=lambda: answer.update(ok=pb.confirm(keys.recorded("r", "agent", 1), 20.0)))
            asker.start()
            asker.join(0.5)
            assert asker.is_alive(), answer  # held: agent 1's final stats have not come
            pb.publisher(keys.stats("r", "agent", 1), block=True).put(final(1))
            asker.join(10.0)
            assert answer == {"ok": True}
            t0 = time.monotonic()
            assert not pb.confirm(keys.recorded("r", "agent", 2), 1.0)  # never sent: not confirmed
            # Ended by the asker's 1 s timeout, not by an answer or a let-go (one round trip, ms):
            # Zenoh ends the query at its timeout, not before; 0.1 s is for the timer's granularity.
            assert time.monotonic() - t0 >= 0.9
            t0 = time.monotonic()
            assert not pb.confirm("zswarm/r/recorded/someone/1", 5.0)  # not a process of a run: let go at once
            assert time.monotonic() - t0 < 2.5  # one round trip (ms) vs the 5 s timeout: split at the midpoint
            assert rec.confirmed == 2
        finally:
            polling.set()
            poller.join()
            rec.close()
    ep = f"tcp/127.0.0.1:{free_port()}"
    with ZenohBus(zenoh_config("peer", listen=[ep])) as a, ZenohBus(zenoh_config("peer", connect=[ep])) as b:
        got: list = []
        a.subscribe("t/x", lambda k, p: got.append(p))
        wait_for(lambda: (b.publisher("t/x").put(b"1"), got)[1], 30, "the peers connected")  # type: ignore[func-returns-value]
        t0 = time.monotonic()
        assert not b.confirm(keys.recorded("r", "agent", 1), 5.0)  # no recorder: nothing serves the key
        assert time.monotonic() - t0 < 2.5  # one round trip (ms) vs the 5 s timeout: split at the midpoint
