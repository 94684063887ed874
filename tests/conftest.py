import os
import resource
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from hypothesis import settings

# tests/keepup.py: reruns only for a run this machine could not keep up with (on the exception's
# type), and every skip a failure; pytester: the tests of that plugin run pytest inside pytest.
pytest_plugins = ["tests.keepup", "pytester"]

ROOT = Path(__file__).resolve().parents[1]
TOPO = ROOT / "topologies"

# Hypothesis profiles (HYPOTHESIS_PROFILE; default "pinned").
# - pinned: what `make test` and CI run. The examples are derived from each test's source
#   (derandomize), no example database is read or written, and no per-example wall-clock
#   deadline applies, so a fresh clone runs the same examples every time and a busy
#   machine cannot turn a slow example into a failure. Every failure a random run finds
#   goes into its test as an @example (or a named regression test where the test draws
#   with st.data(), which @example cannot replay).
# - fuzz: what `make fuzz` runs: random draws (the seed is printed by Hypothesis and by
#   the Makefile), FUZZ_FACTOR (10) times each test's examples, failures printed as a
#   blob to reproduce with @reproduce_failure.
FUZZ_FACTOR = 10
settings.register_profile("pinned", derandomize=True, database=None, deadline=None, print_blob=True)
settings.register_profile("fuzz", max_examples=100 * FUZZ_FACTOR, derandomize=False, database=None, deadline=None, print_blob=True)
PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "pinned")
settings.load_profile(PROFILE)


def examples(n: int) -> int:
    """A property test's number of examples: ``n`` in the pinned profile, FUZZ_FACTOR·n under ``make fuzz``."""
    return n * FUZZ_FACTOR if PROFILE == "fuzz" else n


@pytest.fixture
def fixed8_text() -> str:
    return (TOPO / "thesis-3.2-fixed8.toml").read_text()


# The component tests that `make test` runs in the background (marker "background"): beside the
# integration layer, at idle priority (tests/layers.sh).  The integration layer's processes keep real
# time and leave much of the machine idle (a §5.6 run at time scale 1 uses 0.8-1.0 of the two
# cores, the §3 runs less, compose waits on Docker); these files are its opposite: CPU-bound
# `sim` runs (the convergence study's fine steps, the Chapter 3-5 scenarios over their whole
# horizons; 700 s of one core of the component layer's 1080, measured quietly on 2026-12-04)
# that keep no time and have no wall-clock limit, so a starved one is late, never wrong.  At
# SCHED_IDLE a waking process of a run preempts them at once, and the part gets a session's share
# of the CPU (autogroup scheduling, tests/layers.sh), of which each process of a run needs little.
# test_batched.py joined them on 2026-12-04 (57 s quietly: the batched engine against sim, draw by
# draw, no subprocess and no timeout).  test_sweep_engines.py (34 s) was tried here too: the
# background layer then ended with the integration layer (26.3 of 26.5 min beside stress-ng,
# against 23.6 of 25.3 without it) and make test took 31.0 min instead of 30.6, so it stays in
# the component layer.
# test_publications.py and test_publications_more.py joined on 2026-12-07: their re-runs of
# published rows and draws are ~140 s and ~40 s of one core of sim and batched runs, no real time.
# test_basin.py was tried here on 2026-12-07 (with the kill -9 nemesis of test_kill_resume.py):
# the first layer took 9.4 min instead of 9.6 (test_sweep_engines.py alone keeps a worker 8 min),
# and the integration tests that ran in both arrangements took 8 % longer (1207 s against 1117)
# beside the heavier background part, so it stays in the first layer.
BACKGROUND = frozenset(
    {"test_convergence_study.py", "test_sim_sync.py", "test_sim_thesis.py", "test_sim.py", "test_sim_formation.py", "test_batched.py", "test_publications.py", "test_publications_more.py"}
)


# ZSWARM_TEST_CPU=FILE: one line per test appended to FILE, "nodeid wall_s cpu_s": its setup, call
# and teardown's wall time and CPU (this process's and every reaped child's: a run's launcher
# reaps its agents, the procs fixture reaps the launcher).  What decides which tests may share the
# machine (a real-time run that waits on the clock uses a small part of the core it keeps).
CPU_LOG = os.environ.get("ZSWARM_TEST_CPU")


def _cpu_s() -> float:
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    if not CPU_LOG:
        yield
        return
    t0, c0 = time.monotonic(), _cpu_s()
    yield
    with open(CPU_LOG, "a") as f:
        f.write(f"{item.nodeid} {time.monotonic() - t0:.2f} {_cpu_s() - c0:.2f}\n")


# ZSWARM_WORKER_SESSIONS=1 (tests/layers.sh's CPU-bound parts): each pytest-xdist worker starts a
# session of its own.  The kernel's autogroup scheduling (kernel.sched_autogroup_enabled, on in
# Debian's kernels) shares the CPU between sessions first: two workers in pytest's one session
# beside another session's busy process get one core between them, in two sessions two thirds
# of the two cores, as each process of a `zswarm run` (started in its own session) already does.
# Ctrl-C reaches pytest, which stops its workers (by PID) as it always does.
def pytest_configure(config):
    if hasattr(config, "workerinput") and os.environ.get("ZSWARM_WORKER_SESSIONS") == "1" and os.getsid(0) != os.getpid():
        os.setsid()


# The first layer's longest files, first: with --no-loadscope-reorder (tests/layers.sh)
# pytest-xdist hands the files to its workers in collection order, the next one to a worker as
# it nears the end of those it holds, so a long file collected late is a tail that one worker
# runs alone (xdist's own order is by the number of tests in a file, largest first: the 3 tests
# of the kill -9 nemeses came among the last).  Wall times beside stress-ng --cpu 1 on
# 2026-12-07, largest first: test_sweep_engines 427 s, test_kill_resume 418 s, test_basin 169 s,
# test_cluster 116 s, test_fuzz_zenoh 95 s (the rest at most 80 s each).
LONG_FIRST = ("test_sweep_engines.py", "test_kill_resume.py", "test_basin.py", "test_cluster.py", "test_fuzz_zenoh.py")


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.name in BACKGROUND and item.path.parent.name == "component":
            item.add_marker(pytest.mark.background)
    rank = {name: n for n, name in enumerate(LONG_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: the order otherwise kept


def interrupt_when(cmd: list[str], ready: Callable[[], bool], timeout: float = 300.0) -> tuple[int, str]:
    """Run ``cmd`` (a zswarm command) in its own process group, send the group SIGINT once
    ``ready()`` (Ctrl-C in a terminal reaches the whole group), and return its exit code and
    stderr once nothing of the group is left (its pool's workers and resource tracker
    included; the tracker exits after its parent, so init reaps it: a few seconds are allowed).
    The group is killed and reaped if anything fails on the way."""
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + timeout
        while not ready():
            assert p.poll() is None, p.communicate()
            assert time.monotonic() < deadline, f"not ready in {timeout:g} s"
            time.sleep(0.2)
        os.killpg(p.pid, signal.SIGINT)
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    deadline = time.monotonic() + 15
    while True:
        try:
            os.killpg(p.pid, 0)
        except ProcessLookupError:
            break
        assert time.monotonic() < deadline, subprocess.run(["ps", "-o", "pid,stat,args", "-g", str(p.pid)], capture_output=True, text=True, check=False).stdout
        time.sleep(0.1)
    return p.returncode, err
