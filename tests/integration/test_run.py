"""``zswarm run`` over real processes: router, world, 8 agents, recorder."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time

import pytest

from tests.conftest import ROOT, TOPO
from tests.integration.conftest import (
    assert_run_exit_ok,
    assert_run_matches_sim,
    not_alive,
    pid_alive,
    require_kept_up,
    stop_tail,
    unconfirmed,
    wait_for,
    world_started,
    zswarm,
)
from zswarm.recording.mcap_io import read
from zswarm.report import load_recording
from zswarm.scenario import load as load_scenario
from zswarm.transport import keys

pytestmark = pytest.mark.integration

def run_and_load(procs, tmp_path, name, duration, extra=()):
    out = tmp_path / "out"
    p = procs.start(zswarm("run", str(TOPO / f"{name}.toml"), "--duration", str(duration), "--out", str(out), "--quiet", *extra), log=tmp_path / "launcher.log")
    code = p.wait(duration * 3 + 90)
    procs.adopt(out)
    return code, out


@pytest.mark.parametrize("name", ["thesis-3.2-fixed8", "thesis-3.2-fixed8-filtered"])
def test_run_converges_and_agrees_with_sim(procs, sim_reference, tmp_path, name):
    # Time scale 1.  Beside `stress-ng --cpu 1` (2026-12-03, after issue 28's cheaper ticks)
    # the agents keep up (≤ 0.1 % missed ticks).  The world, which skipped a sample whenever
    # it woke more than one 5 ms period late, dropped 0.4-3.9 % of them in four runs (3.9 %
    # is over the report's 2 %, and an overloaded run is not compared with sim below); since
    # it takes samples late (world/__main__.py: CATCH_UP_S), 0.05 %.
    # Before issue 28 the agents missed 26-33 % of their ticks at 1 with a core kept busy.
    ref = sim_reference(TOPO / f"{name}.toml", tmp_path / "sim", 40.0)  # computed while the run runs
    code, out = run_and_load(procs, tmp_path, name, 40.0, ("--time-scale", "1"))
    s = assert_run_exit_ok(code, out, tmp_path / "launcher.log")
    sc = load_scenario(TOPO / f"{name}.toml")
    assert s["engine"] == "run" and s["completed"]
    assert not (why := not_alive(out, s)), why
    assert not unconfirmed(out)  # every agent and the world had the recorder's word before closing
    # Neighbours leaving at the run's end is not a loss: no warning of one in a clean run (issue 50).
    assert not [p.name for p in (out / "logs").glob("agent-*.log") if "lost (liveliness)" in p.read_text(errors="replace")]
    for i, a in s["agents"].items():
        if a["role"] == "follower":
            assert a["attitude_error_final"] < 1e-2, (i, a)
            assert a["position_error_final"] < 0.1, (i, a)
    for link, c in s["links"].items():
        assert c["dropped"] == 0, (link, c)
        # Nothing lost in between (dropped == 0 counts gaps), only the tail at the stop.
        rate = sc.sensor_rate if link.startswith("world->") else sc.agent(int(link.split("->")[0])).clock.rate
        assert c["delivered"] >= c["sent"] - stop_tail(rate), (link, c)
    # Every child exited cleanly and none is left.
    assert all(v == 0 for v in s["exit_codes"].values()), s["exit_codes"]
    assert not [c for c in procs.adopt(out) if pid_alive(c["pid"])]
    # The CPU of the run (processes.json, issue 28): every process read, none more than the
    # machine has, and the readings over the run within the kernel's totals for the command.
    cpu = json.loads((out / "processes.json").read_text())["cpu"]
    assert set(cpu["run_cpu_s"]) == {c["name"] for c in procs.adopt(out)} | {"launcher+router"}
    assert all(v > 0 for v in cpu["run_cpu_s"].values()), cpu
    # A span's CPU is at most the machine's cores times the span.  The children's CPU over
    # the run is part of their CPU over the whole command (the kernel's total); each figure
    # is rounded to 0.01 s, so their sums may differ by half of that per figure summed.
    assert 0 < cpu["run_share_of_cores"] <= 1.0, cpu
    children = [v for k, v in cpu["run_cpu_s"].items() if k != "launcher+router"]
    assert sum(children) <= cpu["command_children_cpu_s"] + 0.005 * (len(children) + 1), cpu
    # Results folder.
    for f in ("scenario.toml", "summary.json", "errors.csv", "recording.mcap", "plots/attitude_error.png", "plots/position_error.png", "logs/world.log", "logs/agent-8.log", "logs/recorder.log"):
        assert (out / f).exists(), f
    topics = {t for t, _, _ in read(out / "recording.mcap")}
    assert {"truth", "est/3", "sense/3", "edge/1/3", "stats/agent/3", "ctl/start", "ctl/stop", "events/alive"} <= topics

    # sim on the same scenario and seed: final errors within SIM_RUN_TOL (an overloaded run fails here, saying so).
    ss = ref.summary()
    assert_run_matches_sim(s, ss, ("mean_attitude_error_final", "mean_position_error_final"), tmp_path / "launcher.log")
    # The machine's capacity, last: a run that kept up (≤ 2 % missed ticks and skipped samples)
    # and whose sensor packets came in time (≤ 2 % idle ticks) publishes at the configured rate
    # less its missed and idle ticks: at least 100 - 2 - 2 = 96 % of it; 5 % leaves 1 % for the
    # ticks before the first sensor packet (97-99.9 Hz measured).  Otherwise the run reruns.
    require_kept_up(s, "the agents' step rates")
    for i, a in s["agents"].items():
        assert a["step_rate_hz"] == pytest.approx(a["configured_rate_hz"], rel=0.05), i


def test_killed_agent_others_continue(procs, tmp_path):
    out = tmp_path / "out"
    p = procs.start(zswarm("run", str(TOPO / "thesis-3.2-fixed8.toml"), "--duration", "8", "--out", str(out), "--quiet", "--no-plots"), log=tmp_path / "launcher.log")
    kids = wait_for(lambda: procs.adopt(out), 60, "processes.json")
    wait_for(lambda: (out / "logs" / "agent-8.log").exists() and "started" in (out / "logs" / "agent-8.log").read_text(), 60, "agent 8 started")
    time.sleep(3.0)  # let it run a few seconds of world time before the kill
    pid8 = next(c["pid"] for c in kids if c["name"] == "agent-8")
    t_kill = time.time()
    os.kill(pid8, signal.SIGKILL)
    s = assert_run_exit_ok(p.wait(120), out, tmp_path / "launcher.log")
    assert (out / "errors.csv").exists() and not (out / "plots").exists()  # --no-plots: the report but its PNGs
    assert not s["agents"]["8"]["alive_at_end"]
    for i in range(1, 8):
        assert s["agents"][str(i)]["alive_at_end"], i
        assert s["agents"][str(i)]["last_estimate_t"] > 7.9
    # The recording holds agent 8 up to its death, and its death.
    rec = load_recording(out / "recording.mcap")
    last8 = rec.est[8][-1][0]
    start_epoch = rec.start["epoch"]
    # Its last estimate's world time, on the wall clock (epoch + t at time scale 1), is when that
    # step's measurement was due: before the kill (t_kill is read before os.kill; 5 ms for the
    # wall clock's reading and the epoch's rounding), and at most a tick (10 ms) plus the age of
    # its newest sensor packet before it: that age's p99 reached 112 ms on a loaded machine
    # (overload.late_evidence, 2026-12-07), and 0.5 s is four times that.
    assert -0.5 < (start_epoch + last8) - t_kill < 0.005, (start_epoch + last8) - t_kill
    assert any(keys.parse_alive(e["key"]) == ("agent", 8) and not e["alive"] for e in rec.alive_events)  # its token, tagged
    # zswarm info on the run's recording: each agent's estimates as the recording holds them, agent 8's
    # ending at its death, and log times on the recorder's wall clock.
    p = subprocess.run(zswarm("info", str(out), "--json"), capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    d = json.loads(p.stdout)
    ch = d["recording"]["channels"]
    assert ch["est/1"]["count"] == len(rec.est[1]) and ch["est/8"]["count"] == len(rec.est[8])
    assert ch["est/8"]["last_s"] < ch["est/1"]["last_s"] - 3.0  # killed ~3 s into an 8 s run
    assert d["recording"]["start_utc"] is not None and d["summary"]["engine"] == "run"


@pytest.mark.parametrize(("sig", "want"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)], ids=["SIGINT", "SIGTERM"])
def test_ctrl_c_stops_everything_and_writes_results(procs, tmp_path, sig, want):
    """Ctrl-C (SIGINT) or a kill (SIGTERM): everything stopped and reaped, the results written,
    the shell's exit code (128 + the signal); `zswarm report` on the folder then agrees that
    the run did not complete (exit 1), keeping the launcher's exit codes."""
    out = tmp_path / "out"
    p = procs.start(zswarm("run", str(TOPO / "thesis-3.2-fixed8.toml"), "--duration", "30", "--out", str(out), "--quiet"), log=tmp_path / "launcher.log")
    kids = wait_for(lambda: procs.adopt(out), 60, "processes.json")
    world_started(out)
    time.sleep(2.0)
    t0 = time.monotonic()
    p.send_signal(sig)
    code = p.wait(30)
    assert time.monotonic() - t0 < 15  # stopping + report (plots) of a short run
    assert code == want
    assert not [c for c in kids if pid_alive(c["pid"])]
    s = json.loads((out / "summary.json").read_text())
    assert s["interrupted"] and all(v == 0 for v in s["exit_codes"].values()), s["exit_codes"]
    assert 1.0 < max(a["last_estimate_t"] for a in s["agents"].values()) < 30
    assert (out / "errors.csv").stat().st_size > 1000
    r = subprocess.run(zswarm("report", str(out)), cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    again = json.loads((out / "summary.json").read_text())
    assert again["exit_codes"] == s["exit_codes"] and again["interrupted"] and not again["completed"]


def test_a_run_that_cannot_keep_up_says_so(procs, tmp_path):
    """Eight agents at 1 kHz and the world at 1 kHz on two cores: each agent tick costs
    0.2–0.5 ms of Python, so the agents alone want 1.6–4 cores (measured: 11–90 % of
    the ticks missed; the world skipped 0–30 % of its samples, by machine).  The run must
    finish and flag itself in its table and in summary.json, with the reasons it measured."""
    code, out = run_and_load(procs, tmp_path, "thesis-3.2-fixed8", 3.0, ("--set", "clock.rate=1000", "--set", "world.sensor_rate=1000"))
    log = (tmp_path / "launcher.log").read_text()
    s = json.loads((out / "summary.json").read_text())
    # Every process ran to the end.  So overloaded a run may also leave the recorder behind: the
    # router drops what its queue to the recorder cannot hold (congestion control DROP) and the
    # recording ends short of the run (CI, 2026-12-06: at 2.52 s of 3) or has holes in it (with a
    # core kept busy: 1-10 holes of 0.1 s, with the recorder's FIFO at 16 samples as at 1024; or a
    # world descheduled that long), which the run reports as NOT COMPLETED with exit 1.  That is a
    # true report of this machine, not a failure of the run: accepted when it is the only problem.
    assert all(v == 0 for v in s["exit_codes"].values()), (s["exit_codes"], log)
    assert code == 0 or (code == 1 and s["problems"] and all("recording ends at" in p or "the recording has" in p and "hole" in p for p in s["problems"])), log
    ov = s["overload"]
    assert ov["overloaded"] and ov["reasons"], ov
    # Which process fell behind is the machine's (here the agents missed 11-90 % of their ticks
    # and the world 0-30 % of its samples, by CPU and load); what the code must do is say so,
    # naming exactly the figures over the threshold.
    over = [i for i, pct in ov["agents_missed_pct"].items() if pct > ov["threshold_pct"]]
    assert any(r.startswith(f"{len(over)} of {len(s['agents'])} agents missed") for r in ov["reasons"]) == bool(over), ov
    starved = [i for i, pct in ov["agents_idle_pct"].items() if pct > ov["threshold_pct"]]
    assert any(r.startswith(f"{len(starved)} of {len(s['agents'])} agents found no new sensor packet") for r in ov["late"]) == bool(starved), ov
    assert any(r.startswith("the world skipped") for r in ov["reasons"]) == (ov["world_skipped_pct"] > ov["threshold_pct"]), ov
    assert "OVERLOADED: " in log and all(r in log for r in ov["reasons"])


@pytest.mark.parametrize("when", ["running", "starting"])
def test_a_killed_launcher_takes_its_children_with_it(procs, tmp_path, when):
    """SIGKILL of ``zswarm run`` (no handler runs, nothing is reaped by it): each child gets
    SIGTERM from the kernel (PR_SET_PDEATHSIG) and stops by itself.  Before, they ran on in
    their own sessions: the world to the end of its duration, processes still starting for
    up to 120 s.  The recorder's SIGTERM is its clean stop: the recording stays readable."""
    out = tmp_path / "out"
    p = procs.start(zswarm("run", str(TOPO / "thesis-3.2-fixed8.toml"), "--duration", "60", "--out", str(out), "--quiet"), log=tmp_path / "launcher.log")
    kids = wait_for(lambda: procs.adopt(out), 60, "processes.json")
    if when == "running":
        world_started(out)
        time.sleep(1.0)
    os.kill(p.pid, signal.SIGKILL)
    p.wait(10)
    # 20 s: a stop takes the world and agents ≤ 3 s and the recorder ≤ 5 s when the launcher
    # stops them (launch.stop_all's own deadlines); here each also finds its router gone.
    wait_for(lambda: not [c for c in kids if pid_alive(c["pid"])], 20, "every child gone after the launcher's SIGKILL")
    if when == "running":
        from zswarm.recording.mcap_io import ensure_recording

        rec = load_recording(ensure_recording(out, None))  # what `zswarm report DIR` reads
        assert rec.counts.get("truth", 0) > 0 and rec.counts.get("est", 0) > 0  # what was recorded up to the kill
