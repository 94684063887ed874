"""``zswarm sweep`` end to end on the sim engine (real CLI, real child processes)."""

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.conftest import ROOT, TOPO, interrupt_when
from tests.integration.conftest import _children

FIXED8 = str(TOPO / "thesis-3.2-fixed8.toml")


def sweep(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "zswarm", "sweep", FIXED8, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def rows(out):
    with open(out / "sweep.csv", newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--vary", "links.dealy_ms=0,50"], "--vary links.dealy_ms=0: links.dealy_ms: unknown key"),
        (["--vary", "links.drop=0,1.5"], "--vary links.drop=1.5: links.drop: must be a probability in [0, 1]"),
        (["--vary", "links.delay_ms=-10,0"], "--vary links.delay_ms=-10: links.delay_ms: must be >= 0"),
        (["--vary", "links.drop=0", "--vary", "links.drop=0.1"], "--vary links.drop: field: given twice"),
        (["--vary", "links.drop=0", "--set", "links.delay_ms=-1"], "--set links.delay_ms=-1: links.delay_ms: must be >= 0"),
        (["--vary", "links.drop=0", "--thresholds", "0.1"], "--thresholds: give ATT,POS"),
    ],
)
def test_bad_sweeps_exit_2_naming_flag_and_field(tmp_path, args, message):
    p = sweep(*args, "--out", str(tmp_path / "s"))
    assert p.returncode == 2, p.stderr
    assert message in p.stderr
    assert not (tmp_path / "s" / "sweep.csv").exists()


def test_sweep_writes_rows_plots_and_resumes(tmp_path):
    out = tmp_path / "s"
    args = ["--vary", "links.delay_ms=0,100", "--vary", "links.drop=0,0.3", "--repeats", "2", "--duration", "1.5", "--out", str(out)]
    p = sweep(*args)
    assert p.returncode == 0, p.stderr
    rs = rows(out)
    assert len(rs) == 8 and all(r["status"] == "ok" for r in rs)
    assert sorted(r["run_id"] for r in rs) == sorted(f"p{k:03d}-r{r}" for k in range(4) for r in range(2))
    for r in rs:
        assert int(r["seed"]) == 1 + int(r["repeat"])  # seeds differ per repeat
        drop, sent = float(r["links.drop"]), int(r["edge_sent"])
        if drop == 0:
            assert int(r["edge_dropped"]) == 0
        else:
            assert abs(float(r["edge_drop_ratio"]) - drop) < 0.1
        if float(r["links.delay_ms"]) == 100:
            assert float(r["edge_latency_p50_ms"]) == pytest.approx(100.0, abs=1e-6)
        assert sent > 0 and float(r["final_attitude_error"]) > 0
    # With lossy links the two seeds lose different messages.
    lossy = [r for r in rs if r["links.drop"] == "0.3" and r["links.delay_ms"] == "0"]
    assert lossy[0]["edge_dropped"] != lossy[1]["edge_dropped"]
    for name in ("sweep_links.delay_ms.png", "sweep_links.drop.png", "sweep_heatmap.png"):
        assert (out / name).stat().st_size > 10_000
    assert not list(out.glob("runs/*/recording.mcap"))  # deleted unless --keep-recordings

    again = sweep(*args, "--no-plots")  # everything is done: nothing runs again
    assert again.returncode == 0, again.stderr
    assert "(0 run now" in again.stdout and "plots: none" in again.stdout
    assert len(rows(out)) == 8
    assert not list(out.glob("*.png"))  # --no-plots: the earlier figures removed, none written

    other = sweep("--vary", "links.drop=0,0.2", "--duration", "1.5", "--out", str(out))
    assert other.returncode == 2 and "holds a different sweep (differs in: repeats, vary)" in other.stderr


def _at_first_row(cmd, out, act):
    """Start the sweep ``cmd`` (a session of its own), call ``act(process)`` once its first row
    is in ``out``'s sweep.csv, and let it end; the process and its stderr.  Killed (its group)
    if anything fails on the way."""
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 300  # a hang's deadline: a row comes in seconds
        while not (out / "sweep.csv").exists() or len(rows(out)) < 1:
            assert p.poll() is None and time.monotonic() < deadline, p.communicate()
            time.sleep(0.05)
        act(p)
        _, err = p.communicate(timeout=300)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    return p, err


def test_interrupted_sweep_resumes_where_it_stopped(tmp_path):
    out = tmp_path / "s"
    # On sim, a run at a time: the batched engine would step the five together, done before the signal.
    args = [sys.executable, "-m", "zswarm", "sweep", FIXED8, "--vary", "links.drop=0,0.1,0.2,0.3,0.4", "--duration", "2", "--jobs", "1", "--engine", "sim", "--out", str(out)]
    proc, err = _at_first_row(args, out, lambda p: p.send_signal(signal.SIGINT))
    assert proc.returncode == 130, err
    assert "the same command resumes" in err
    first = rows(out)
    assert 1 <= len(first) < 5
    p = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    final = rows(out)
    assert sorted(r["run_id"] for r in final) == [f"p{k:03d}-r0" for k in range(5)]  # each run once
    assert final[: len(first)] == first  # what was done is kept as it was


def test_failed_runs_are_recorded_and_the_sweep_goes_on(tmp_path):
    out = tmp_path / "s"
    # 0.05 s is too short for any run's process: each one is killed and recorded as failed (on
    # sim: the batched engine would take the lossless run, and it runs no process per run).
    p = sweep("--vary", "links.drop=0,0.1,0.2", "--duration", "1", "--timeout", "0.05", "--engine", "sim", "--out", str(out))
    assert p.returncode == 1, p.stderr
    rs = rows(out)
    assert len(rs) == 3
    assert all(r["status"] == "failed" and "timed out after 0.05 s" in r["error"] for r in rs)
    assert "3 failed in all" in p.stdout


def _sweep_of(topology, *args, timeout=600):
    return subprocess.run([sys.executable, "-m", "zswarm", "sweep", str(TOPO / topology), *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout, check=False)


def test_a_run_past_its_timeout_kills_the_workers_and_their_other_runs_start_again(tmp_path, monkeypatch):
    """On sim a sweep's runs share worker processes (sweep.run_sweep_workers): a run past its
    timeout cannot be stopped alone, so the workers are stopped, it is a failed row, and the
    run another worker held starts again in the next ones.  Here the workers are threads and
    the runs stand-ins (their timing decides the case, not the scenario): A never ends, B ends
    at 2 s, C begins then and never ends on its first try.  A is late at its 4 s timeout, when C
    has run 2-2.5 s: C goes back to the queue and ends on its second try.  (The real processes
    are killed and started again in test_failed_runs_are_recorded_and_the_sweep_goes_on and
    test_a_killed_worker_s_runs_start_again_in_a_new_pool.)"""
    import threading
    from concurrent.futures import ThreadPoolExecutor
    from concurrent.futures.process import BrokenProcessPool
    from contextlib import contextmanager

    from zswarm.engines import cluster
    from zswarm.scenario import load
    from zswarm.studies import sweep as sw

    pools: list[threading.Event] = []
    tries: dict[str, int] = {}

    @contextmanager
    def threads(n_jobs, where=None):
        stopped = threading.Event()
        pools.append(stopped)
        with ThreadPoolExecutor(n_jobs) as pool:
            yield cluster.Runner(pool, n_jobs, stopped.set, f"{n_jobs} threads")
            stopped.set()

    def stand_in(text, path, job, duration, thresholds, scratch=None):
        tries[job.run_id] = tries.get(job.run_id, 0) + 1
        stopped = pools[-1]
        if job.run_id == "p000-r0" or (job.run_id == "p002-r0" and tries[job.run_id] == 1):
            stopped.wait(60)  # "never ends": until its workers are stopped
            raise BrokenProcessPool("its worker was killed")  # what a process pool's future of a killed worker gives
        if job.run_id == "p001-r0":
            time.sleep(2.0)
        return {"final_attitude_error": 0.5}, None, {"summary.json": b"{}"}

    monkeypatch.setattr(cluster, "executor", threads)
    monkeypatch.setattr(sw, "run_job", stand_in)
    sc = load(FIXED8)
    varies = [sw.parse_vary("links.drop=0,0.1,0.2")]
    jobs = sw.plan(FIXED8, sc, [], varies, 1, 1)
    out = tmp_path / "s"
    (out / "runs").mkdir(parents=True)
    # 4 s: C begins when B ends at 2 s and the loop looks every 0.5 s, so at A's timeout C has run
    # 2-2.5 s; only a loop stalled 1.5 s would find C late too (a stall, not the machine's speed).
    ok, failed, interrupted = sw.run_sweep_workers(FIXED8, jobs, varies, out, 1.0, (0.01, 0.1), 2, None, lambda: False, timeout=4.0)
    got = {r["run_id"]: r for r in rows(out)}
    assert (ok, failed, interrupted) == (2, 1, False)
    assert got["p000-r0"]["status"] == "failed" and got["p000-r0"]["error"] == "timed out after 4 s"
    assert got["p001-r0"]["status"] == "ok" and got["p002-r0"]["status"] == "ok", got
    assert tries == {"p000-r0": 1, "p001-r0": 1, "p002-r0": 2} and len(pools) == 2
    assert (out / "runs" / "p002-r0" / "summary.json").read_bytes() == b"{}"


def test_a_killed_worker_s_runs_start_again_in_a_new_pool(tmp_path):
    """SIGKILL of one of a sweep's worker processes (what the kernel's OOM killer does) while it
    holds a run: the pool is gone, its runs in flight start again in new workers, the sweep
    says so in a line and ends with every run ok, its scratch folder removed."""
    out = tmp_path / "s"
    cmd = [sys.executable, "-m", "zswarm", "sweep", FIXED8, "--vary", "links.drop=0,0.1,0.2,0.3", "--duration", "4", "--jobs", "2", "--engine", "sim", "--no-plots", "--out", str(out)]

    def kill_a_worker(p):
        workers = [k for k in _children(p.pid) if b"spawn_main" in Path(f"/proc/{k}/cmdline").read_bytes()]  # not its resource tracker
        assert len(workers) == 2, workers
        os.kill(workers[0], signal.SIGKILL)  # the row's worker went on to the next run: in flight

    p, err = _at_first_row(cmd, out, kill_a_worker)
    assert p.returncode == 0, err
    assert "a worker process died" in err and "start again in new ones" in err, err
    got = rows(out)
    assert sorted(r["run_id"] for r in got) == [f"p{k:03d}-r0" for k in range(4)] and all(r["status"] == "ok" for r in got), got
    assert not (out / ".work").exists()


def test_a_run_beyond_reason_is_a_failed_row_naming_its_cost(tmp_path):
    """A run zswarm sim would refuse without --allow-long (10^11 world steps) is not started by a
    sweep's worker either: a failed row naming the steps and the estimate."""
    out = tmp_path / "s"
    p = sweep("--vary", "links.drop=0", "--set", "world.step=1e-6", "--duration", "100000", "--engine", "sim", "--out", str(out))
    assert p.returncode == 1, p.stderr
    (r,) = rows(out)
    assert r["status"] == "failed" and "1e+11 world steps" in r["error"] and "without --allow-long" in r["error"], r


def test_auto_runs_on_sim_what_the_batched_engine_cannot(tmp_path):
    """auto: the grid point with agents on a perfect clock is batched, the one with clock jitter
    runs on sim and says why; --engine batched refuses that sweep before it starts (exit 2); a
    resumed sweep runs only what its sweep.csv lacks, whichever engine wrote the rest."""
    args = ["--vary", "clock.jitter=0,0.0005", "--set", "links.reorder=true", "--set", "links.jitter_ms=2", "--duration", "1", "--jobs", "2"]
    out = tmp_path / "auto"
    p = _sweep_of("thesis-5.6-hybrid7.toml", *args, "--out", str(out))
    assert p.returncode == 0, p.stderr
    assert "1 of 2 runs on sim: clock jitter" in p.stderr and "1 batched in 1 batches, 1 on sim" in p.stderr
    rs = rows(out)
    assert len(rs) == 2 and all(r["status"] == "ok" for r in rs)
    assert (out / "runs" / "p001-r0").is_dir() and not (out / "runs" / "p000-r0").exists()
    p = _sweep_of("thesis-5.6-hybrid7.toml", *args, "--engine", "batched", "--out", str(tmp_path / "b"))
    assert p.returncode == 2 and "--engine batched: run p001-r0: clock jitter" in p.stderr, p.stderr
    assert not (tmp_path / "b" / "sweep.csv").exists()
    lines = (out / "sweep.csv").read_text().splitlines()
    (out / "sweep.csv").write_text("\n".join(line for line in lines if not line.startswith("p000-r0")) + "\n")
    p = _sweep_of("thesis-5.6-hybrid7.toml", *args, "--engine", "sim", "--out", str(out))  # sim may resume what auto began
    assert p.returncode == 0, p.stderr
    assert "1 on sim" in p.stderr and "2 runs (1 run now" in p.stdout
    assert sorted(r["run_id"] for r in rows(out)) == ["p000-r0", "p001-r0"]


def test_ctrl_c_on_the_batched_engine_keeps_the_rows_and_resumes(tmp_path):
    """Ctrl-C reaches the whole process group: the rows of the batches that ended are kept, the
    workers are killed (their batches rerun on resume) and the command exits 130; the same
    command then runs only the runs that sweep.csv lacks.  Six batches of 3 s (sixteen of 6 s
    before, most of them run again on resume): the signal comes within a poll (0.2 s) of the
    first row, while each of the two workers has a batch of ~1 s of CPU under way, so a row or
    two are kept and four or five rerun."""
    out = tmp_path / "s"
    cmd = [sys.executable, "-m", "zswarm", "sweep", str(TOPO / "thesis-5.6-hybrid7.toml"), "--vary", "algorithm.gains.k_R=0.5:3:0.5"]
    cmd += ["--engine", "batched", "--chunk", "1", "--duration", "3", "--jobs", "2", "--out", str(out)]
    code, err = interrupt_when(cmd, lambda: (out / "sweep.csv").exists() and len(rows(out)) >= 1)  # nothing of the group left after it
    assert code == 130 and "interrupted:" in err and "Traceback" not in err, err
    kept = rows(out)
    assert 1 <= len(kept) < 6 and all(r["status"] == "ok" for r in kept)  # interrupted after the first row, before the 6th
    again = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600, check=False)
    assert again.returncode == 0, again.stderr
    assert f"{6 - len(kept)} batched" in again.stderr and len(rows(out)) == 6
