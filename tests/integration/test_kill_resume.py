"""``kill -9`` at seeded moments, then resume (issue 50; in the style of Jepsen's nemesis).

A sweep and a basin check are each killed at 20 moments drawn from a seeded generator (listed
below), resumed by the same command each time, and finally let finish.  Ten moments are seconds
after the command's start (its start-up or its work, as fast as the machine is), ten are a
fraction of a second after it saved its next row: at work by construction, on any machine.  Every run must then be
in the results file once, whole, and equal to its row in an uninterrupted run of the same
command (the wall-clock column aside).  ``zswarm record`` is killed at 20 moments of a live run:
each recording it leaves reads (no exception), and ``zswarm report`` on it says what happened in
one line per problem, without a traceback.

Every process is reaped by PID: the commands here directly; what they started dies with them
(procutil.die_with_parent, cluster.worker_init), which each kill checks in /proc: the killed
command's descendants must end by themselves within 60 s (``_kill_at``).
"""

from __future__ import annotations

import os
import random
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.conftest import ROOT, TOPO
from tests.integration.conftest import _children, pid_alive, wait_for, zswarm
from zswarm.engines.launch import free_port
from zswarm.recording import mcap_io
from zswarm.transport import keys
from zswarm.transport.bus import ZenohBus, zenoh_config
from zswarm.util import rows

# Real processes, no real time (marker "processes"): make test runs the file in its first layer,
# in a pytest worker of normal priority beside the component tests (tests/layers.sh), not in the
# integration layer, whose real-time runs it used to lengthen by 7 min (2026-12-07, beside
# stress-ng --cpu 1: 418 s of the layer's 1885).  Each check here waits on the command's own
# progress, never on the clock: the odd kills come after a saved row (or message), the even ones
# at seconds after the start find it wherever the machine's speed has brought it, and a wait
# that does not end is a hang's deadline.  The nemesis needs the CPU of a normal process: at
# idle priority (make test's background part, 2026-12-07, when all 20 kills came at seconds after
# the start) only 0-4 of the 20 came after the command had saved a row; beside the real-time integration
# tests at normal priority (2026-12-07, with the Dask tests, beside stress-ng --cpu 1) the runs
# beside it were slowed by 15-30 % (three ran again, late sensor data; the killed agent's team
# reconverged in 10.9 s against a bound of 7.4).
pytestmark = pytest.mark.processes

T32, T56 = TOPO / "thesis-3.2-fixed8.toml", TOPO / "thesis-5.6-hybrid7.toml"
N_KILLS = 20


def moments(seed: int, lo: float, hi: float) -> list[float]:
    """The seconds after its start at which each of the N_KILLS commands is killed."""
    rng = random.Random(seed)
    return [round(rng.uniform(lo, hi), 3) for _ in range(N_KILLS)]


def plan(seed: int, lo: float, hi: float) -> list[tuple[str, float]]:
    """Each kill's moment: ("start", s) for ``s`` seconds after the command's start (the even
    kills, moments(seed, lo, hi)), ("row", s) for ``s`` seconds (0-0.3) after the command's next
    row is in the file (the odd kills).  The first kind finds the command wherever the machine's
    speed has brought it by then (a starved one is still starting up, 2026-12-07: 0-4 of 20 kills
    after a saved row, at idle priority); the second finds it at work on any machine."""
    rng = random.Random(seed + 1)
    return [("start", s) if k % 2 == 0 else ("row", round(rng.uniform(0.0, 0.3), 3)) for k, s in enumerate(moments(seed, lo, hi))]


# Long enough that 20 kills mostly hit the command at work, and that the rows the ten kills after
# a row leave (one or two each) and the others' do not finish it early (a failure names the
# moment): 36 runs of ~0.5 s of CPU each two at a time, 64 draws of ~0.4 s (2 s of world time:
# what a draw's length changes is only the CPU the test costs; 4 s draws cost 0.74 s each,
# measured 2026-12-07, and kept the first layer's longest test at 213 s beside stress-ng).
SWEEP = [sys.executable, "-m", "zswarm", "sweep", str(T32), "--vary", "links.drop=0,0.1,0.2,0.3,0.4,0.5", "--repeats", "6", "--duration", "2", "--jobs", "2", "--engine", "sim", "--no-plots"]
BASIN = [sys.executable, "-m", "zswarm", "basin", str(T56), "--draws", "64", "--duration", "2", "--engine", "sim", "--jobs", "2", "--no-plots"]
WALL = {"wall_s"}  # the only cells that differ between two runs of the same command
# A command's next row (a sim run or a draw of 2 s: ~0.5 s of CPU each) or a recorder's first
# message comes within seconds; 120 s is a hang's deadline on a loaded machine, not a measure.
AFTER_DEADLINE_S = 120.0


def _descendants(pid: int) -> set[int]:
    out: set[int] = set()
    todo = [pid]
    while todo:
        kids = _children(todo.pop())
        out.update(kids)
        todo.extend(kids)
    return out


def _kill_at(cmd: list[str], delay: float, log: Path, after: Callable[[], bool] | None = None) -> int | None:
    """Start ``cmd``, SIGKILL it (the command alone, not its group: its children must see it
    die) ``delay`` s later (``after``: ``delay`` s after ``after()`` first holds, polled every
    20 ms; not within AFTER_DEADLINE_S: a hang, killed and failed), reap it; its exit code when it
    ended by itself first.  The processes it had started must end by themselves within 60 s (else
    killed, and a failure)."""
    with open(log, "ab") as f:
        p = subprocess.Popen(cmd, cwd=ROOT, stdin=subprocess.DEVNULL, stdout=f, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + AFTER_DEADLINE_S
        while after is not None and not after():
            assert time.monotonic() < deadline, f"{cmd[3]}: no new row (or message) in {AFTER_DEADLINE_S:g} s; see {log}"
            try:
                return p.wait(0.02)
            except subprocess.TimeoutExpired:
                pass
        try:
            return p.wait(delay)
        except subprocess.TimeoutExpired:
            kids = _descendants(p.pid)
            os.kill(p.pid, signal.SIGKILL)
            p.wait()
            deadline = time.monotonic() + 60
            while (left := [k for k in kids if pid_alive(k)]) and time.monotonic() < deadline:
                time.sleep(0.1)
            for k in left:
                os.kill(k, signal.SIGKILL)
            assert not left, f"{cmd[3]} killed at {delay} s: its processes {left} outlived it"
            return None
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


def _by(table: rows.Table, key: str) -> dict[str, dict[str, str]]:
    got: dict[str, dict[str, str]] = {}
    for r in table.rows:
        assert r[key] not in got, f"{r[key]} is in the file twice"
        got[r[key]] = {k: v for k, v in r.items() if k not in WALL}
    return got


def _nemesis(cmd: list[str], out: Path, ref: Path, csv_name: str, key: str, seed: int, tmp_path: Path) -> None:
    p = subprocess.run([*cmd, "--out", str(ref)], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    want = _by(rows.read(ref / csv_name), key)
    assert len(want) > 1
    log = tmp_path / "nemesis.log"
    finished_early = restarts = 0
    saved, advanced = 0, 0  # rows whole in the file; kills after which it held more than before

    def ok_rows() -> int:
        return sum(1 for r in rows.read(out / csv_name).rows if r.get("status") == "ok") if (out / csv_name).exists() else 0

    for k, (kind, delay) in enumerate(plan(seed, 0.3, 4.0)):
        before = saved
        rc = _kill_at([*cmd, "--out", str(out)], delay, log, (lambda b=before: ok_rows() > b) if kind == "row" else None)
        at = f"kill {k} ({delay} s after {'its start' if kind == 'start' else 'a row'})"
        finished_early += rc is not None
        assert rc in (None, 0), f"{at}: the command failed by itself (exit {rc}); see {log}"
        if k % 5 == 4 and (out / csv_name).exists():  # a power cut as well: the file's last bytes lost
            data = (out / csv_name).read_bytes()
            (out / csv_name).write_bytes(data[: len(data) - random.Random(seed + k).randint(1, 40)])
        t = rows.read(out / csv_name)
        assert t.header is None or t.torn in ([], [len(t.rows) + 2]), f"{at}: torn lines {t.torn} beyond the last"
        now = 0
        for rid, r in _by(t, key).items():  # what is in the file is whole and right at every moment
            if r.get("status") == "ok":
                assert r == want[rid], f"{at}: {rid}"
                now += 1
        advanced += now > saved
        saved = now
        if now == len(want):  # done: the next kills start over in an empty folder, at work again on a fast machine
            shutil.rmtree(out)
            saved, restarts = 0, restarts + 1
    p = subprocess.run([*cmd, "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    final = rows.read(out / csv_name)
    assert final.torn == []
    assert _by(final, key) == want  # every run once, whole, as uninterrupted
    # The moments must have hit the commands at work, not only after they had finished: most
    # of them (a command that ends before its kill tests nothing of a kill).
    assert finished_early < N_KILLS // 2, f"{finished_early} of {N_KILLS} commands ended before their kill"
    # And a quarter of them after the command had saved rows (a kill during the start-up tests the
    # start-up only): the ten kills after a row do, on any machine, but where a power cut took
    # the row again (every fifth kill) or the command ended before its kill.
    print(f"{advanced} of {N_KILLS} kills came after their command had saved a row; {finished_early} commands ended before their kill; {restarts} folders done and started over")
    assert advanced >= N_KILLS // 4, f"only {advanced} of {N_KILLS} kills came after their command had saved a row"


def test_a_sweep_killed_at_20_moments_resumes_to_the_uninterrupted_rows(tmp_path):
    _nemesis(SWEEP, tmp_path / "sweep", tmp_path / "ref", "sweep.csv", "run_id", 5001, tmp_path)


def test_a_basin_killed_at_20_moments_resumes_to_the_uninterrupted_rows(tmp_path):
    _nemesis(BASIN, tmp_path / "basin", tmp_path / "ref", "basin.csv", "draw", 5002, tmp_path)


def test_a_recorder_killed_at_20_moments_leaves_readable_recordings(procs, tmp_path):
    """A live world (§3.2; this test holds the agents' tokens); `zswarm record` joins it and
    is killed at plan(5003, 0.5, 4.0): ten times 0.5-4 s after its start, ten times 0-0.3 s after
    its recording first held a message.  Each recording it leaves is read up to the kill."""
    ep = f"tcp/127.0.0.1:{free_port()}"
    procs.start(zswarm("router", "--listen", ep), log=tmp_path / "router.log")
    run = "kill9"
    alive: set = set()
    with ZenohBus(zenoh_config("client", connect=[ep])) as bus:
        bus.watch_alive(keys.alive_all(run), lambda k, up: (alive.add if up else alive.discard)(keys.parse_alive(k)))
        for i in range(1, 9):
            bus.declare_token(keys.alive(run, "agent", i))
        first = tmp_path / "rec-first"
        procs.start(zswarm("record", str(T32), "--out", str(first), "--run-id", run, "--connect", ep, "--no-report"), log=tmp_path / "rec-first.log")
        wait_for(lambda: ("recorder", 0) in alive, 60, "the first recorder alive")
        procs.start([sys.executable, "-m", "world", "--topology", str(T32), "--duration", "600", "--wait-for-recorder", "--run-id", run, "--connect", ep], log=tmp_path / "world.log")
        wait_for(lambda: "start:" in (tmp_path / "world.log").read_text(), 60, "the world started")
        read_any = 0
        for k, (kind, delay) in enumerate(plan(5003, 0.5, 4.0)):
            out = tmp_path / f"rec-{k}"
            raw = out / ("recording" + mcap_io.RAW_SUFFIX)

            def holds_a_message(raw: Path = raw) -> bool:  # the odd kills: after its first message is on disk
                return raw.exists() and next(iter(mcap_io.read(raw, [])), None) is not None  # an empty or begun file: no message

            rc = _kill_at(zswarm("record", str(T32), "--out", str(out), "--run-id", run, "--connect", ep, "--no-report"), delay, tmp_path / f"rec-{k}.log", holds_a_message if kind == "row" else None)
            assert rc is None, f"recorder {k} ended by itself (exit {rc})"
            if not raw.exists():
                continue  # killed before it opened its file
            lost: list = []
            got = list(mcap_io.read(raw, lost))  # never raises on a file a kill cut
            assert all(x.offset >= 0 and "cut short" in x.text() for x in lost), [x.text() for x in lost]
            if got:
                read_any += 1
                p = subprocess.run(zswarm("report", str(out)), cwd=ROOT, capture_output=True, text=True, timeout=300)
                assert p.returncode == 1 and "Traceback" not in p.stderr + p.stdout, (k, delay, p.stderr)
                assert "NOT COMPLETED" in p.stdout
        # The ten kills after a message was on disk left one to read (and those of the others that
        # came after the recorder's start-up, ~1 s of the 0.5-4 s moments): at least half, else the
        # test would check little.
        assert read_any >= N_KILLS // 2, f"only {read_any} of {N_KILLS} recordings held messages"
