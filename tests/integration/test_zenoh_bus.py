"""ZenohBus over real sessions: the recorder's subscription (subscribe_polled)."""

from __future__ import annotations

import threading
import time

import pytest

from tests.integration.conftest import wait_for
from zswarm.bus import ZenohBus, zenoh_config
from zswarm.launch import free_port

pytestmark = pytest.mark.integration


def _pumps() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("zenoh-fifo")]


def test_polled_samples_are_copied_and_stamped_on_arrival_and_bounded():
    """Samples are taken off Zenoh as they arrive (stamped then, not when the owner polls;
    a sample left in Zenoh's FIFO held its 64 KiB receive batch), at most ``capacity``
    wait, none is lost while the owner catches up, and the thread ends with the bus."""
    ep = f"tcp/127.0.0.1:{free_port()}"
    with ZenohBus(zenoh_config("peer", listen=[ep])) as rx, ZenohBus(zenoh_config("peer", connect=[ep])) as tx:
        fast = rx.subscribe_polled("t/fast", time.time_ns)
        slow = rx.subscribe_polled("t/slow", time.time_ns, capacity=100)
        assert len(_pumps()) == 2
        pf, ps = tx.publisher("t/fast"), tx.publisher("t/slow")
        wait_for(lambda: (pf.put(b"probe"), fast())[1], 30, "the peers connected")  # type: ignore[func-returns-value]
        time.sleep(0.2)
        fast()
        for i in range(3000):
            pf.put(i.to_bytes(4, "big"))
        for i in range(500):
            ps.put(i.to_bytes(4, "big"))
        sent = time.time_ns()
        time.sleep(1.5)  # the owner busy elsewhere
        polled = time.time_ns()
        got = fast()
        assert [int.from_bytes(p, "big") for _, p, _ in got] == list(range(3000))
        # Stamped on arrival: within 1 s of the last put (a core kept busy by another
        # process delays the thread by scheduler slices of ms), so at least 0.5 s before
        # the poll.  Stamped at the poll (the old way) they would all read `polled`.
        assert max(t for _, _, t in got) < sent + 1_000_000_000 < polled - 400_000_000
        first = slow()
        assert len(first) == 100  # capacity: the rest waits in Zenoh, not in our memory
        rest: list = []
        wait_for(lambda: rest.extend(slow()) or len(rest) >= 400, 30, "the rest of t/slow")
        assert [int.from_bytes(p, "big") for _, p, _ in first + rest] == list(range(500))  # none lost
    wait_for(lambda: not _pumps(), 5, "the threads ended with the bus")
