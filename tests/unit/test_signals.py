"""Stopping on SIGINT/SIGTERM without a lock in the signal handler (procutil.SignalEvent)."""

import subprocess
import sys
import textwrap

# The child lands a SIGINT while its main thread holds the stop event's lock, which is
# where an agent's main thread spends much of its time (Event.wait between ticks): a handler
# that calls Event.set there waits for a lock its own frame holds, forever (seen over
# ``zswarm run``: an agent hung in Event.set <- handler <- Event.wait, SIGKILLed at Ctrl-C).
CHILD = textwrap.dedent(
    """
    import os, signal, sys
    from zswarm import procutil
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

    from zswarm.procutil import SignalEvent

    before = signal.getsignal(signal.SIGTERM)
    ev = threading.Event()
    h = SignalEvent(ev)
    assert signal.getsignal(signal.SIGTERM) is not before
    h.close()
    assert signal.getsignal(signal.SIGTERM) is before
    assert not h._thread.is_alive()
