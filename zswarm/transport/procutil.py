"""What every zswarm process shares: Zenoh flags, logging, signals, scenario loading."""

from __future__ import annotations

import argparse
import atexit
import errno
import functools
import logging
import math
import os
import signal
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

from zswarm.scenario import Override, Scenario, ScenarioError, load
from zswarm.util.files import RecordingError
from zswarm.util.quoting import one_line

EXIT_USAGE = 2


def add_zenoh_args(p: argparse.ArgumentParser, default_mode: str = "client") -> None:
    """The Zenoh flags, defined once for every entry point."""
    g = p.add_argument_group("zenoh")
    g.add_argument("--connect", action="append", default=[], metavar="ENDPOINT", help="endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)")
    g.add_argument("--listen", action="append", default=[], metavar="ENDPOINT", help="endpoint to listen on (repeatable)")
    g.add_argument("--config", metavar="FILE", help="a Zenoh JSON5 config file (endpoints above override it)")
    g.add_argument("--mode", choices=("client", "peer", "router"), default=default_mode, help=f"Zenoh session mode (default {default_mode})")
    g.add_argument("--secure", metavar="DIR", default=None, help="mutual TLS with this process's certificate from DIR (made by zswarm certs or zswarm run --secure; endpoints tls/...)")


def zenoh_conf(args: argparse.Namespace, name: str | None = None, acl: dict[str, Any] | None = None) -> Any:
    """The Zenoh config of the flags; ``name``: this process's certificate name (--secure);
    ``acl``: the access control a router enforces (zswarm/transport/secure.py)."""
    from zswarm.transport.bus import zenoh_config

    if not args.connect and not args.listen and not args.config and args.mode == "client":
        fail_usage("a client needs --connect ENDPOINT (or --config FILE)")
    secure = None
    if getattr(args, "secure", None):
        if name is None:
            fail_usage("--secure: this command has no certificate of its own (zswarm run --secure makes them for its processes)")
        for f in ("ca.pem", f"{name}.pem", f"{name}.key"):
            if not os.path.isfile(os.path.join(args.secure, f)):
                fail_usage(f"--secure {args.secure}: {f} is missing (zswarm certs or zswarm run --secure make a run's certificates)")
        secure = (args.secure, name)
    return zenoh_config(args.mode, args.connect, args.listen, args.config, secure=secure, acl=acl)


def add_run_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--run-id", default="default", help="run id shared by every process of a run (default: default)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: the scenario's)")


def fail_usage(msg: str) -> NoReturn:
    """``error: msg`` on one line of stderr (user text in it escaped), exit 2."""
    print(f"error: {one_line(msg)}", file=sys.stderr)
    sys.exit(EXIT_USAGE)


# Errors of the results folder (a full disk, a read-only or foreign folder): one line naming
# the path and the problem, exit 1, never a traceback.
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EROFS, errno.EACCES, errno.EPERM, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.ENOTDIR, errno.EISDIR, errno.ENAMETOOLONG})


def write_problem(exc: BaseException) -> str | None:
    """``path: problem`` for an error writing results (an OSError of WRITE_ERRNOS, or the
    recording's RecordingError, which names its file), else None."""
    if isinstance(exc, RecordingError):
        return str(exc)
    if isinstance(exc, OSError) and exc.errno in WRITE_ERRNOS:
        return f"{exc.filename}: {exc.strerror}" if exc.filename else str(exc.strerror or exc)
    return None


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose usage errors stay on one line: argparse echoes what it did
    not recognise as it was typed (``unrecognized arguments: a<newline>b``)."""

    def error(self, message: str) -> NoReturn:
        super().error(one_line(message))


def load_or_exit(path: str, overrides: Sequence[Override] = ()) -> Scenario:
    """Load a scenario or exit 2 with its one-line ``file: field: problem``."""
    try:
        return load(path, overrides)
    except ScenarioError as exc:
        fail_usage(str(exc))


def setup_logging(name: str, level: str = "INFO") -> logging.Logger:
    logging.basicConfig(level=level, format=f"%(asctime)s {name} %(levelname)s %(message)s", stream=sys.stderr)
    return logging.getLogger(name)


class SignalEvent:
    """SIGINT and SIGTERM set ``event``, without taking a lock in the signal handler.

    ``Event.set`` from a Python signal handler deadlocks when the signal lands while the
    main thread holds that event's lock, i.e. inside ``Event.wait`` (the handler runs in
    the main thread, between two of its bytecodes, and waits for a lock its own frame
    holds).  Agents wait on their stop event between ticks, 100-200 times a second: a
    ``zswarm run`` stopped by Ctrl-C left one of 8 agents hung in
    ``Event.set`` <- handler <- ``Condition.__enter__`` <- ``Event.wait`` (py-spy) in 2 of
    20 runs with a core kept busy, and the launcher SIGKILLed it.  Here the handler only
    writes a byte to a pipe (no lock; a full pipe means a wake-up is already pending) and
    a daemon thread reading it sets the event.  :meth:`close` puts the previous handlers
    back and ends the thread.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, event: threading.Event) -> None:
        self.event = event
        self._r, self._w = os.pipe()
        os.set_blocking(self._w, False)
        self._thread = threading.Thread(target=self._watch, name="zswarm-signals", daemon=True)
        self._thread.start()
        self._prev = {s: signal.signal(s, self._handler) for s in self.SIGNALS}

    def _handler(self, signum: int, _frame: object) -> None:
        global _FIRST_STOP_SIGNAL
        if _FIRST_STOP_SIGNAL is None:
            _FIRST_STOP_SIGNAL = signum
        try:
            os.write(self._w, b"\0")
        except (BlockingIOError, InterruptedError):
            pass  # a byte is already waiting to be read: the event will be set
        except OSError:
            self.event.set()  # closed: no thread to hand over to (after close(), which puts the old handlers back)

    def _watch(self) -> None:
        while True:
            try:
                data = os.read(self._r, 64)
            except InterruptedError:
                continue
            except OSError:
                return
            if not data:
                os.close(self._r)
                return
            self.event.set()

    def close(self) -> None:
        for s, h in self._prev.items():
            signal.signal(s, h)
        os.close(self._w)  # the thread reads EOF and ends
        self._thread.join(1.0)


_FIRST_STOP_SIGNAL: int | None = None  # the signal that stopped this process first (SignalEvent)


def interrupted_code() -> int:
    """The exit code of a command stopped by a signal it caught, by the shell's convention
    128 + the signal's number: 130 for SIGINT (Ctrl-C), 143 for SIGTERM (``kill``, a
    container's stop)."""
    return 128 + (_FIRST_STOP_SIGNAL or signal.SIGINT)


PARENT_ENV = "ZSWARM_PARENT_PID"  # set by a launcher for its children: see die_with_parent


def die_with_parent() -> None:
    """End this process (SIGTERM: its own clean stop) when the launcher that started it dies,
    however it dies.

    A launcher that was SIGKILLed left its children running (their own sessions, so no
    terminal signal reaches them): the world to the end of its duration, processes still
    starting for up to 120 s.  The launcher names itself in ``ZSWARM_PARENT_PID``; the child
    asks the kernel for SIGTERM on its parent's death (``PR_SET_PDEATHSIG``, Linux) and then
    checks that parent is still the one it was started by (it may have died before the ask).
    Without the variable (a process started by hand) nothing changes.
    """
    want = os.environ.pop(PARENT_ENV, None)
    if want is None or not sys.platform.startswith("linux"):
        return
    import ctypes

    PR_SET_PDEATHSIG = 1
    if ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0:
        logging.getLogger("zswarm").warning("prctl(PR_SET_PDEATHSIG) failed: errno %d", ctypes.get_errno())
    if str(os.getppid()) != want:
        print(f"{os.path.basename(sys.argv[0])}: the launcher (pid {want}) is gone; exiting", file=sys.stderr)
        os._exit(1)


def child_env(env: dict[str, str] | None = None) -> dict[str, str]:
    """The environment of a child this process launches (see :func:`die_with_parent`)."""
    return dict(os.environ if env is None else env, **{PARENT_ENV: str(os.getpid())})


def incarnation() -> int:
    """This process's incarnation (wire.py's ``inc``): its start time in µs since the epoch,
    under 2**53 until the year 2255, new for every (re)start of a process."""
    import time

    return time.time_ns() // 1000


def trim_heap() -> bool:
    """Give the memory the C heap holds free back to the system (glibc's ``malloc_trim(0)``,
    every arena); False where there is none (another libc).

    For a process whose work comes in bursts (the recorder, when it falls behind and
    catches up): glibc keeps what a burst freed, so RSS climbs to the highest burst so far
    and stays.  In the 1-hour soak of 2026-12-02 (bench/soak.py) the recorder jumped from
    70 to 79 MiB at minute 41 and stayed there; ``malloc_trim(0)``, called by hand (gdb) at
    minute 54, took it from 80.2 to 69.3 MiB: the 11 MiB were free memory, not a leak.
    """
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)  # 1 if memory was given back, 0 if none was free: either is fine
    return True


@functools.cache
def _malloc_trim() -> Any:
    """glibc's ``malloc_trim`` (looked up once), or None under another libc."""
    import ctypes

    return getattr(ctypes.CDLL(None), "malloc_trim", None)


def warm_up() -> None:
    """Pay a process's one-time costs before its run starts, not in the middle of it.

    * numpy's first ``percentile`` (the link counters' p50/p99) takes 13 ms on this
      machine (lazy set-up inside ``np.unique``; 0.2 ms after).  Every agent and the world
      paid it at their first stats, all at world t = 1 s: the world skipped 5 samples
      (25 ms at time scale 0.25, 100-200 ms of wall time with 8 agents on 2 cores) and
      every relative-yaw estimate of De Carli's run jumped to 0.06-0.18 at t = 1.03 s
      (sim: settled below 0.05 at 0.46 s);
    * a garbage collection walks every object the imports left (numpy, zenoh, the
      scenario): 75-170 ms per full pass here.  ``gc.freeze()`` moves what exists now
      out of the collector's way, so a collection during the run walks only what the
      run allocated since.
    """
    import gc

    import numpy as np

    np.percentile(np.arange(4.0), [50, 99])
    gc.collect()
    gc.freeze()


# How long a process that sent its final stats waits for the recorder to confirm them
# before it closes its session.  Closing at once lost them: with the recorder frozen for
# 0.5 s as the run ended (cgroup freezer, 2026-12-02), 4 of 8 agents' final stats never
# left the router, seen neither by the recorder nor by a second subscriber that was not
# frozen, while the router delivered the world's stop to that subscriber 60 ms late.
# `zswarm run` gives its processes 6 s after the world's end before it kills them: 3 s
# leaves the rest for an agent behind its schedule.
FINAL_CONFIRM_S = 3.0


def confirm_final(bus: Any, key: str, log: logging.Logger, timeout: float = FINAL_CONFIRM_S) -> bool:
    """After a process's final stats: wait until the recorder has them (``key``, a
    :func:`zswarm.transport.keys.recorded` key) before the session closes, at most ``timeout`` s.
    False at once when no recorder serves the run (then nothing was lost by closing)."""
    t0 = time.monotonic()
    ok = bool(bus.confirm(key, timeout))
    waited = time.monotonic() - t0
    if ok:
        log.info("final stats recorded (confirmed in %.3f s)", waited)
    elif waited >= 0.9 * timeout:
        log.warning("final stats not confirmed by the recorder within %.1f s", timeout)
    else:
        log.info("final stats not confirmed: no recorder answered")
    return ok


def stop_on_signals() -> threading.Event:
    """An event set by SIGINT or SIGTERM (:class:`SignalEvent`): the process then stops
    cleanly and exits 0.

    Also while the interpreter finalizes, after the process has done its work: Python
    puts back the default handlers then, so a signal in that window (the launcher
    nudging a process that stops a little late on a loaded machine) killed the process
    with -15 instead of letting it exit 0, and an agent read as dead at the end.  An
    exit hook, which runs before that, ignores them instead (SIG_IGN stays; SIGKILL
    still ends the process)."""
    stop = threading.Event()
    SignalEvent(stop)
    atexit.register(_ignore_signals)
    return stop


def _ignore_signals() -> None:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)


def stop_on_signals_into(stop: threading.Event) -> None:
    """SIGINT and SIGTERM set ``stop`` (the owner winds down and reaps its children)."""
    SignalEvent(stop)


def positive_int(s: str) -> int:
    try:
        v = int(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {s!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1 (got {s})")
    return v


LIVE_DEFAULT = "127.0.0.1:8765"
RERUN_DEFAULT = "rerun+http://127.0.0.1:9876/proxy"  # where the rerun viewer program listens by default (zswarm --rerun)


def host_port(s: str) -> tuple[str, int]:
    """``HOST:PORT`` (``[v6]:PORT`` too) for a server to listen on; port 0 picks a free one."""
    host, sep, port = s.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise argparse.ArgumentTypeError(f"expected HOST:PORT, e.g. {LIVE_DEFAULT} (got {s!r})")
    return host, int(port)


def positive_float_or_inf(s: str) -> float:
    return math.inf if s.strip().lower() in ("inf", "max") else positive_float(s)


def positive_float(s: str) -> float:
    try:
        v = float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {s!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0 (got {s})")
    return v


# --------------------------------------------------------------------------- the commands' shared helpers
# (each command's run function lives with its module: zswarm.engines.sim.command, zswarm.studies.sweep_command.command, ...)


def load_args(args: Any) -> Any:
    """The scenario of ``args.topology`` with the ``--set`` overrides (exit 2 on any error)."""
    from zswarm.scenario import ScenarioError, fault_override, parse_override

    try:
        overrides = [parse_override(o) for o in args.overrides] + [fault_override(f) for f in getattr(args, "faults", [])]
    except ScenarioError as exc:
        fail_usage(str(exc))
    return load_or_exit(args.topology, overrides)


def check_faults_in_run(sc: Any, duration: float, given: bool) -> None:
    """Exit 2 with one line when a fault of ``sc`` (``[[faults]]`` or ``--fault``) would begin, or
    its agent restart, at or after the run's end: a mistake in the command, not a run to make
    (``given``: the duration came from ``--duration``, not the scenario)."""
    where = f"--duration {duration:g}" if given else f"scenario.duration = {duration:g} s"
    for n, f in enumerate(sc.faults):
        when = "restart_at" if f.restart_at is not None and f.at < duration <= f.restart_at else "at"
        t = f.at if when == "at" else f.restart_at
        if t >= duration:
            fail_usage(f"faults[{n}] ({f.describe()}): {when} = {t:g} s is not within the run ({where}): it would never happen")


def write_output(text: str, output: Path | None, what: str) -> None:
    """``text`` to standard output, or to ``output`` (its folder made) with "wrote FILE<what>" on stderr."""
    if output is None:
        sys.stdout.write(text)
        return
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(text, encoding="utf-8")
    print(f"wrote {output}{what}", file=sys.stderr)


def warn_notes(sc: object) -> None:
    for w in getattr(sc, "warnings", ()):
        print(f"{getattr(sc, 'path', '')}: note: {w}", file=sys.stderr)


def number_arg(s: str, flag: str) -> float:
    """A number or an expression such as ``0.08pi`` / ``0.08*pi`` / ``pi/2``."""
    import math
    import re

    from zswarm.scenario.expr import ExprError, parse

    text = s.strip()
    text = re.sub(r"^([0-9.eE+-]+)\s*pi$", r"\1*pi", text)
    try:
        x = float(parse(text)(0.0))
    except ExprError as exc:
        fail_usage(f"{flag}: {exc} (got {s!r})")
    if not math.isfinite(x):
        fail_usage(f"{flag}: must be finite (got {s!r})")
    return x
