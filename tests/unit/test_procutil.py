"""What every process does around its run: stopping on SIGINT/SIGTERM without a lock in the
signal handler (procutil.SignalEvent), and paying one-time costs before the start (warm_up)."""

import subprocess
import sys
import textwrap

import pytest

# The child lands a SIGINT while its main thread holds the stop event's lock, which is
# where an agent's main thread spends much of its time (Event.wait between ticks): a handler
# that calls Event.set there waits for a lock its own frame holds, forever (seen over
# ``zswarm run``: an agent hung in Event.set <- handler <- Event.wait, SIGKILLed at Ctrl-C).
CHILD = textwrap.dedent(
    """
    import os, signal, sys
    from zswarm.transport import procutil
    stop = procutil.stop_on_signals()
    with stop._cond:  # what Event.wait holds around its checks
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(10000):  # the handler runs here, in this thread, between bytecodes
            pass
        print("handler returned", flush=True)
    sys.exit(0 if stop.wait(10.0) else 3)
    """
)


def test_a_signal_landing_inside_event_wait_sets_the_stop_event():
    p = subprocess.run([sys.executable, "-c", CHILD], check=False, capture_output=True, text=True, timeout=30)
    assert p.returncode == 0, p.stderr
    assert "handler returned" in p.stdout


def test_the_signal_handlers_are_put_back_on_close():
    import signal
    import threading

    from zswarm.transport.procutil import SignalEvent

    before = signal.getsignal(signal.SIGTERM)
    ev = threading.Event()
    h = SignalEvent(ev)
    assert signal.getsignal(signal.SIGTERM) is not before
    h.close()
    assert signal.getsignal(signal.SIGTERM) is before
    assert not h._thread.is_alive()


def test_warm_up_leaves_what_the_start_up_made_to_no_collection():
    # gc.freeze(): a collection during the run walks only what the run allocated (the
    # imports' objects took 75-170 ms per full pass, all processes at the same moment).
    code = "import gc; from zswarm.transport import procutil; procutil.warm_up(); print(gc.get_freeze_count())"
    p = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert int(p.stdout) > 10000  # numpy and zswarm's modules: tens of thousands of objects


def _rss_anon_mib() -> float:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("RssAnon:")) / 1024


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc_trim and /proc: Linux")
def test_trim_heap_gives_back_what_a_burst_freed():
    """What a burst allocated and freed stays in glibc's heap (the recorder's RSS ratchet)
    until trim_heap.  64 MiB of 1000-byte objects (malloc'd by glibc, not pymalloc: over
    512 bytes), one in 64 kept so that the pages stay mapped, 63 in 64 freed: without
    the trim RSS keeps nearly all of it (glibc only trims the top of a heap); the trim
    frees every page without a live object, about 62 MiB.  Asserted: at least half."""
    from zswarm.transport import procutil

    burst = [bytes(1000) for _ in range(64 << 10)]
    kept = burst[::64]
    before = _rss_anon_mib()
    del burst
    freed = _rss_anon_mib()
    assert procutil.trim_heap()
    after = _rss_anon_mib()
    # Without a trim glibc gives back only the top of its heap, above the last kept object:
    # at most one 64 KiB stride plus the 0.5 MiB list of pointers; 16 MiB is far above that
    # and far below the 64 MiB a free() that returned the burst would show.
    assert before - freed < 16, "glibc gave the burst back by itself: the test shows nothing"
    # The trim frees every page without a live object: 63 of every 64 KiB stride less the
    # pages a kept object straddles (1-2 of 16), about 56-60 MiB; at least half is asserted
    # (32 MiB), which a no-op trim (0 MiB) cannot pass.
    assert freed - after > 32, (before, freed, after)
    assert len(kept) == 1024
