"""Helpers for tests that start real processes over Zenoh on 127.0.0.1.

Every process is started in its own session (process group) and reaped by
PID at teardown, whatever the test's outcome; children that ``zswarm run``
spawned are found in its ``processes.json`` and reaped by PID as well.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import ROOT
from tests.keepup import MachineDidNotKeepUp

pytestmark = pytest.mark.integration


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # A zombie still answers kill(0); treat it as gone (its parent reaps it).
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def kill_group(p: subprocess.Popen, timeout: float) -> bool:
    """SIGKILL to ``p``'s process group (started with ``start_new_session``) if it still
    runs, then reap ``p`` by PID, waiting at most ``timeout`` s.  True if it had to kill."""
    killed = p.poll() is None
    if killed:
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    p.wait(timeout)
    return killed


class Procs:
    def __init__(self) -> None:
        self.started: list[subprocess.Popen[bytes]] = []
        self.extra_pids: set[int] = set()

    def start(self, args: list[str], log: Path | None = None) -> subprocess.Popen[bytes]:
        out = open(log, "wb") if log else subprocess.DEVNULL  # noqa: SIM115
        p = subprocess.Popen(args, cwd=ROOT, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        self.started.append(p)
        return p

    def adopt(self, results: Path) -> list[dict]:
        """Remember the PIDs a launcher wrote in results/processes.json (to reap them at the end)."""
        f = results / "processes.json"
        kids = json.loads(f.read_text())["children"] if f.exists() else []
        self.extra_pids |= {c["pid"] for c in kids}
        return kids

    def reap(self) -> list[int]:
        """Kill what is still running; return the launcher-spawned PIDs that were left.

        Processes the test started itself are killed quietly (a failing test
        may leave them); processes a launcher spawned must have been reaped by
        the launcher, so any of those still alive is reported.
        """
        leftovers = []
        killed = [kill_group(p, 10) for p in self.started]
        if any(killed):
            # A launcher killed here (a failed test) could not reap its children: they die
            # with it (the group's SIGKILL, PR_SET_PDEATHSIG), which takes a moment.  A
            # launcher that ended by itself must have reaped them already: no grace then.
            deadline = time.monotonic() + 10
            while any(pid_alive(pid) for pid in self.extra_pids) and time.monotonic() < deadline:
                time.sleep(0.05)
        for pid in self.extra_pids:
            if pid_alive(pid):
                leftovers.append(pid)
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        return leftovers


def _children(pid: int) -> list[int]:
    """PIDs whose parent is ``pid`` (from /proc), alive (zombies excluded)."""
    out = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid and fields[0] != "Z":
                out.append(int(d))
    return out


COMPOSE_MODULE = "test_compose.py"
COMPOSE_IMAGE_TEST = "test_compose_run_converges_in_a_real_engine"


def pytest_collection_modifyitems(session, config, items):
    """The compose tests run last: the base root of their image is built while the other
    tests run (tests/integration/dockerbase.py)."""
    items.sort(key=lambda item: item.path.name == COMPOSE_MODULE)  # stable: the order otherwise kept


@pytest.fixture(scope="session", autouse=True)
def base_rootfs(request, tmp_path_factory, no_process_left):
    """The base image's root (dockerbase.Rootfs), started at the session's start when the
    compose image test is to run and no base image exists; None otherwise.  Stopped (its
    processes reaped) before ``no_process_left`` looks."""
    from tests.integration import dockerbase

    wanted = any(item.name == COMPOSE_IMAGE_TEST for item in request.session.items)
    build = dockerbase.Rootfs(tmp_path_factory.mktemp("rootfs")) if wanted and not dockerbase.image_exists(dockerbase.BASE_IMAGE) else None
    try:
        yield build
    finally:
        if build is not None:
            build.stop()


@pytest.fixture(scope="session", autouse=True)
def no_process_left():
    """After the session (the integration layer, or a first-layer worker that ran a file of
    this folder), no process this test session started is left (the
    per-test ``procs`` fixture checks each launcher's children by PID as well)."""
    yield
    left = [p for p in _children(os.getpid()) if pid_alive(p)]
    for p in left:
        try:
            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert not left, f"processes left after the integration tests: {left}"


@pytest.fixture
def procs():
    ps = Procs()
    try:
        yield ps
    finally:
        left = ps.reap()
    assert not left, f"processes left behind: {left}"


class StallMeter:
    """How long this machine stopped running a thread that asked to run: a thread of the
    test process sleeps ``period`` at a time and keeps each wake-up's lateness.

    A sleeping thread woken by its timer is run soon by the scheduler on a loaded
    machine (it has used little CPU): with 11 busy-looping processes beside it, late
    by milliseconds; squeezed into 0.45 of a core by a CPU quota with 16 agents,
    late by up to 0.28 s (measured 2026-12-02).  Lateness near a second means the
    machine itself stopped (a virtual machine's vCPU descheduled by its host, a
    freeze), which stops every zswarm process too: a Zenoh link silent for its lease
    is then a true "gone" by the lease's own definition, and a test may tell that
    from a runtime fault with this.
    """

    def __init__(self, period: float = 0.01) -> None:
        self.period = period
        self.stalls: list[tuple[float, float]] = []  # (monotonic time of the wake-up, lateness s), lateness > 0.1 s
        self.max_late = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="stall-meter", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        due = time.monotonic() + self.period
        while not self._stop.wait(max(0.0, due - time.monotonic())):
            now = time.monotonic()
            late = now - due
            self.max_late = max(self.max_late, late)
            # listed for a failure message only: 0.1 s is 30 times the lateness beside 11
            # busy loops (3 ms), so the list holds stops, not scheduling noise
            if late > 0.1:
                self.stalls.append((now, late))
            due = now + self.period

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)


@pytest.fixture
def stall_meter():
    m = StallMeter()
    try:
        yield m
    finally:
        m.stop()


def wait_for(pred, timeout: float, what: str, step: float = 0.05, fail=None):
    """Poll ``pred`` until true; past ``timeout`` fail naming ``what`` (and ``fail()``: what was seen)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        v = pred()
        if v:
            return v
        time.sleep(step)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}" + (f"; last seen: {fail()}" if fail is not None else ""))


def world_started(out: Path, timeout: float = 60) -> None:
    """Wait until the world of the run in results folder ``out`` has started (its log's "start:")."""
    log = out / "logs" / "world.log"
    wait_for(lambda: log.exists() and "start:" in log.read_text(), timeout, "world started")


def not_alive(out: Path, s: dict) -> str:
    """Why an agent of the run in ``out`` (summary ``s``) reads as not alive at the end, for
    an assertion's message: "" when every agent is alive.  "Alive at the
    end" is the final stats in the recording and exit code 0 (report.summarize); which of
    the two failed, and the logs' last lines, tell a crash from stats the recorder missed."""
    bad = [i for i, a in s["agents"].items() if not a["alive_at_end"]]
    if not bad:
        return ""
    lines = [f"not alive at the end: agents {bad}; exit codes {s.get('exit_codes')}"]
    for name in [f"agent-{i}" for i in bad] + ["recorder"]:
        log = out / "logs" / f"{name}.log"
        tail = log.read_text(errors="replace").splitlines()[-8:] if log.exists() else ["(no log)"]
        lines += [f"--- {name}.log, last lines:", *tail]
    return "\n".join(lines)


def unconfirmed(out: Path) -> list[str]:
    """The processes of the run in ``out`` whose logs do not say the recorder confirmed
    their final stats (procutil.confirm_final) before they closed their session."""
    logs = [p for p in sorted((out / "logs").glob("*.log")) if p.stem == "world" or p.stem.startswith("agent-")]
    assert logs, out
    return [p.stem for p in logs if "final stats recorded (confirmed" not in p.read_text(errors="replace")]


def zswarm(*args: str) -> list[str]:
    return [sys.executable, "-m", "zswarm", *args]


# The tail of a link when a run stops: messages a sender put after its receiver read its
# last ones (counted sent, neither delivered nor dropped: "dropped" counts gaps in the
# sequence numbers).  Each process reacts to the world's stop within its scheduling
# latency: with one core kept busy and ~14 runnable processes CFS gives each a slice
# about every 14 × 3 ms ≈ 40 ms, and the sender may stop a few such turns after the
# receiver (60 ms measured under stress-ng --cpu 1).  0.2 s of messages bounds it; a
# process that misses the stop sends for seconds.
STOP_SKEW_S = 0.2


def stop_tail(rate_hz: float) -> int:
    """The most messages a link of ``rate_hz`` may leave undelivered at the stop."""
    return max(1, round(rate_hz * STOP_SKEW_S))


SIM_RUN_TOL = 3.0
FLOOR = 1e-5  # final errors both below it are converged (assert_run_matches_sim)
"""``run`` ends within a factor 3 of ``sim`` on the final errors when it kept up.

Both engines run the same objects on the same sensor samples, and every step
ends at a measurement on both (agent/runtime.py, AgentNode.tick), so the
gyro, bearings and relative attitudes a step uses are the same.  What still
differs over Zenoh: a neighbour's data are 0–15 ms old instead of 0 or 10 ms,
and the world skips a few samples when it is late (5–15 in 8000).  On a
weakly observable direction (§3.3's agent 4, collinear neighbours) such a
perturbation decays over tens of seconds, so the floors differ by a factor:
measured 1.0–1.7 on the six noise-free scenarios (quiet 2-core machine).
Three allows that; the timing faults this guards against gave 10–1000
(§3.2 before steps ended at measurements: ×10; a 35 ms stall on §3.3: ×14).

When the run did not keep up (summary.json ``overload``), its errors are not the
algorithm's alone: a test that exists to check the equations then fails, saying so
(:func:`fail_if_overloaded`), instead of passing on a check it did not make.  Measured
beside ``stress-ng --cpu 1`` (2026-12-03/05), the runs that call it keep up."""


def fail_if_overloaded(s: dict, what: str) -> None:
    """Raise :class:`~tests.keepup.MachineDidNotKeepUp` when the run ``s`` (summary.json) did not
    keep up: ``what`` (the equations' checks the test exists for) cannot be judged on it.  The
    test runs again (tests/keepup.py) and fails, naming ``what``, if it never keeps up."""
    ov = s["overload"]
    if ov["overloaded"]:
        raise MachineDidNotKeepUp(f"this machine did not keep up with the run ({'; '.join(ov['reasons'])}), so {what} could not be checked against the equations")


def not_kept_up(s: dict) -> list[str]:
    """Why the run ``s`` (summary.json) did not keep up: its overload reasons (missed ticks, skipped
    samples) and its late sensor data (``overload.late``: agents idle for want of a packet, which
    the world's and the packets' measured lateness account for).  Idle ticks the lateness does
    not account for are no machine's doing: a defect, failed at once (results.overload,
    ``late_explained``)."""
    ov = s["overload"]
    assert ov["late_explained"], ov
    return ov["reasons"] + ov["late"]


@contextmanager
def judged_if_kept_up(s: dict, what: str):
    """Checks of the equations on a run whose sensor data came late: they are made, and one that
    fails raises :class:`~tests.keepup.MachineDidNotKeepUp` (its message carrying the failure's) when the run
    did not keep up, since older data than configured take damping off every law here (a delay τ
    takes ≈ k·τ off the decay rate).  On a run that kept up a failure fails at once.  A passing
    check passes on any run: it held on data older than the equations assume."""
    try:
        yield
    except AssertionError as e:
        if why := not_kept_up(s):
            # Not chained: the rerun rule (tests/keepup.py) fails at once on any other type in a
            # failure's causes; the assertion's text is in the message.
            raise MachineDidNotKeepUp(f"this machine did not keep up with the run ({'; '.join(why)}), and {what} failed on it: {e}") from None
        raise


def _machine_problems_only(problems: list[str]) -> bool:
    """Every problem of a run is one a machine that stood still makes: a hole in the recording or
    a recording that ends short (the recorder or the world not run for longer than 0.1 s)."""
    return bool(problems) and all(("the recording has " in p and " hole" in p) or "recording ends at" in p for p in problems)


def assert_run_exit_ok(code: int | None, out: Path, log: Path) -> dict:
    """A ``zswarm run`` with results in ``out`` and its output in ``log`` exited 0; its summary.

    A run that did not keep up (its own overload figures or late sensor data) may have stood still long enough for
    a hole in its recording, which the run rightly calls a problem (exit 1): the test's checks
    cannot be made on it, and it raises :class:`~tests.keepup.MachineDidNotKeepUp` (a rerun).
    Any other non-zero exit, overloaded or not, fails at once."""
    text = log.read_text(errors="replace") if log.exists() else "(no launcher log)"
    f = out / "summary.json"
    s = json.loads(f.read_text()) if f.exists() else None
    if code == 1 and s is not None and _machine_problems_only(s["problems"]) and (why := not_kept_up(s)):
        raise MachineDidNotKeepUp(f"this machine did not keep up with the run ({'; '.join(why)}), which exited 1 on what that leaves: {'; '.join(s['problems'])}")
    assert code == 0, text[-3000:]
    assert s is not None, f"exit 0 and no summary.json in {out}"
    return s


def require_kept_up(s: dict, what: str) -> None:
    """Raise :class:`~tests.keepup.MachineDidNotKeepUp` when the run ``s`` did not keep up or its
    sensor packets came late (``overload.late``: the world's and the packets' measured lateness
    account for the agents' idle ticks, a machine short of CPU): ``what``, a check
    of the machine's capacity (a publishing rate, a command's age), could not be made on it.  Call
    it after the checks that hold on any run, so that a real failure among them is not rerun."""
    if why := not_kept_up(s):
        raise MachineDidNotKeepUp(f"this machine did not keep up with the run ({'; '.join(why)}), so {what} could not be checked")


def assert_run_matches_sim(s: dict, ss: dict, keys: tuple[str, ...], launcher_log: Path) -> None:
    """``run`` summary ``s`` against ``sim`` summary ``ss`` on ``keys`` (see SIM_RUN_TOL)."""
    ov = s["overload"]
    assert not ov["overloaded"] or ("OVERLOADED" in launcher_log.read_text() and ov["reasons"]), ov  # said where the user reads it
    fail_if_overloaded(s, f"the final errors {keys} against sim")
    with judged_if_kept_up(s, f"the final errors {keys} against sim"):
        _matches_sim(s, ss, keys)


def _matches_sim(s: dict, ss: dict, keys: tuple[str, ...]) -> None:
    ov = s["overload"]
    for k in keys:
        a, b = s[k], ss[k]
        assert a is not None and b is not None and np.isfinite(a) and np.isfinite(b), (k, a, b)
        # Below FLOOR both have converged to a floor that is not the observer's transient, where
        # a ratio means nothing: round-off (a leader-like zero, 1e-16) on sim; on run, what its
        # data's ages (0-15 ms) and the world's sample timing leave (measured: the §4.5 hybrid
        # pose observer's mean attitude error 9.5e-7 on sim, 1.1e-6 to 4.8e-6 over runs that
        # kept up).  The convergence study takes the same 1e-5 (test_convergence_study).
        assert max(a, b) < FLOOR or max(a, b) / max(min(a, b), 1e-300) <= SIM_RUN_TOL, (k, a, b, ov)


# A run's ``sim`` reference, computed while the run runs.  The real-time run leaves most of
# the machine idle (a §5.6 run at time scale 1 uses 0.8-1.0 of the two cores, the §3 runs
# less), and its reference sim is CPU-bound work of 7-37 s (measured quietly, 2026-12-04:
# §5.6 hybrid 150 s 37 s, §4.5 hybrid pose 60 s 25 s, §3.2 40 s 9 s, §3.3 30 s 7.5 s).
# The reference process runs at SCHED_IDLE: a waking process of the run preempts it at once.
# It is in a session of its own, as each of the run's processes is, and the kernel shares the
# CPU between sessions first (autogroup scheduling, tests/layers.sh), so over time it gets a
# session's share, which each of the run's processes needs only a small part of (the run's own
# overload figures stay the judge of that).  When the run
# is over, the reference is raised back to the normal policy and the test waits for it.
SIM_REFERENCE_TIMEOUT_S = 900.0  # 37 s quietly for the longest; ×20 for a loaded machine


class SimReference:
    """``zswarm sim`` of a scenario (with ``--set`` overrides) and its report, in a process
    of its own at SCHED_IDLE (tests/integration/simref.py); :meth:`summary` waits for the
    report's summary (its files are in ``out``)."""

    def __init__(self, topo: Path, out: Path, duration: float | None = None, sets: tuple[str, ...] = (), lean: bool = False, record: bool = False) -> None:
        self.out = out
        args = {"topo": str(topo), "sets": list(sets), "duration": duration, "out": str(out), "lean": lean, "record": record}
        self.log = out.parent / f"{out.name}-reference.log"
        with open(self.log, "wb") as log:
            self.proc = subprocess.Popen([sys.executable, "-m", "tests.integration.simref", json.dumps(args)], cwd=ROOT, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            os.sched_setscheduler(self.proc.pid, os.SCHED_IDLE, os.sched_param(0))
        except OSError:
            pass  # exited already: summary() says how

    def summary(self) -> dict:
        try:  # the run is over: the reference may now have the CPU the others have
            os.sched_setscheduler(self.proc.pid, os.SCHED_OTHER, os.sched_param(0))
        except OSError:
            pass  # it has exited already
        try:
            code = self.proc.wait(SIM_REFERENCE_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"the sim reference did not finish in {SIM_REFERENCE_TIMEOUT_S:g} s") from None
        assert code == 0, f"the sim reference exited {code}:\n{self.log.read_text(errors='replace')[-3000:]}"
        return json.loads((self.out / "reference.json").read_text())

    def kill(self) -> None:
        kill_group(self.proc, 30)


@pytest.fixture
def sim_reference():
    """Start :class:`SimReference` s; every one still running is killed (by PID) at the end."""
    made: list[SimReference] = []

    def start(*args, **kw) -> SimReference:
        made.append(SimReference(*args, **kw))
        return made[-1]

    try:
        yield start
    finally:
        for r in made:
            r.kill()
