"""Faults on real processes (issue 14): an agent SIGKILLed and restarted mid-run, and the
router restarted, in the §3.2 scenario on ``zswarm run``.  Time scale 0.5, as the other
long real-time runs of the suite (a busy machine left agents missing ticks at 1)."""

from __future__ import annotations

import math

import pytest

from tests.conftest import TOPO
from tests.integration.conftest import SIM_RUN_TOL, assert_run_exit_ok, fail_if_overloaded, judged_if_kept_up, not_alive, wait_for, zswarm
from zswarm.transport.bus import LEASE_MS

pytestmark = pytest.mark.integration
T32 = str(TOPO / "thesis-3.2-fixed8.toml")

# A SIGKILLed process's TCP connection closes at once, the router drops its session and its
# liveliness token with it: measured 0.05–0.45 s from the kill to the neighbour's mark
# (the launcher's SIGKILL lands within its 0.1 s poll).  A hung process would take up to
# the 1 s lease (zswarm.transport.bus.zenoh_config) plus the lease's keep-alive period.
DETECT_BOUND_S = 1.0


# A hung (SIGSTOPped) process keeps its connection: the router drops it when its lease
# runs out, 1 s of wall time after its last keep-alive (sent every quarter lease): at most
# 1.25 s, measured 0.93 s.  In world time at time scale 0.5: half that, with 0.25 s margin.
HUNG_BOUND_S = 0.5 * (1.25 * LEASE_MS / 1000 + 0.25)


# sim of the killed-agent case (above): reconvergence 4.6 s after the restart, peak / level 10.0.
SIM_RECONVERGENCE_S = 4.6
SIM_PEAK_OVER_LEVEL = 10.0


def _run(procs, tmp_path, duration, *faults):
    out = tmp_path / "out"
    extra = [a for f in faults for a in ("--fault", f)]
    p = procs.start(zswarm("run", T32, "--duration", str(duration), "--time-scale", "0.5", "--out", str(out), "--quiet", *extra), log=tmp_path / "launcher.log")
    wait_for(lambda: procs.adopt(out), 60, "processes.json")
    code = p.wait(duration / 0.5 + 120)
    procs.adopt(out)  # a restarted agent is in processes.json too
    log = (tmp_path / "launcher.log").read_text()
    return assert_run_exit_ok(code, out, tmp_path / "launcher.log"), out, log


def test_a_killed_agent_is_flagged_rejoins_and_the_team_reconverges(procs, tmp_path):
    s, out, log = _run(procs, tmp_path, 28, "kill,agent=5,at=10,restart_at=15")
    (f,) = s["faults"]
    acts = {a["action"]: a["taken_at"] for a in s["fault_actions"]}
    assert abs(acts["kill"] - 10.0) < 0.2 and abs(acts["restart"] - 15.0) < 0.2, s["fault_actions"]  # the launcher polls every 0.1 s
    # The recorder and agent 6 (5's out-neighbour) saw the token go within the bound.
    assert 0 <= f["token"]["lost_after_s"] < DETECT_BOUND_S, f["token"]
    d6 = f["detected_by"]["6"]
    assert d6["lost_after_s"] is not None and 0 <= d6["lost_after_s"] < DETECT_BOUND_S, d6
    # It re-joined: its token came back (a new process: imports, session, warm-up) and
    # agent 6 marked it back; link 5->6 followed the new incarnation.
    assert d6["back_after_end_s"] is not None and f["token"]["back_at"] is not None
    assert s["links"]["5->6"]["restarts"] == 1
    assert s["exit_codes"]["agent-5~killed1"] == -9 and s["exit_codes"]["agent-5"] == 0
    # 13 s at 100 Hz after the restart (1300 steps), less its start-up (2–4 s of wall time):
    # more than 500 even when half of them went.
    assert s["agents"]["5"]["alive_at_end"] and s["agents"]["5"]["steps"] > 500
    assert f["steps_missed"] >= 450  # 5 s at 100 Hz, less the last period's rounding
    r = f["reconvergence"]
    assert not s["overload"]["overloaded"] or "OVERLOADED" in log
    fail_if_overloaded(s, "the team's reconvergence")  # then its errors are not the algorithm's alone
    # sim, same scenario and fault (zswarm sim --fault kill,agent=5,at=10,restart_at=15,
    # 2026-12-07): the mean error peaks at 0.158 after the restart and is back below its level
    # before the kill, 0.0158, 4.6 s after it: a decay of ln(10) in 4.6 s.  Over Zenoh the team
    # ends within SIM_RUN_TOL (3x) of sim's errors when it keeps up; at sim's decay rate a factor 3
    # is 4.6·ln(3)/ln(10) = 2.2 s.  And the new process first has to start and join: agent 6
    # marked it back d6["back_after_end_s"] after the restart (imports, session, warm-up).
    bound = d6["back_after_end_s"] + SIM_RECONVERGENCE_S * (1 + math.log(SIM_RUN_TOL) / math.log(SIM_PEAK_OVER_LEVEL))
    with judged_if_kept_up(s, "the team's reconvergence"):  # late sensor data slow it (seen at a load average of 10)
        assert r["reconvergence_s"] is not None and r["reconvergence_s"] < bound, (r, bound)
    # The axes alone make a 15.6 kB PNG; with the curves and the shading 73-76 kB.
    assert (out / "plots" / "attitude_error.png").stat().st_size > 30_000


def test_a_router_restart_and_a_hung_agent(procs, tmp_path):
    s, out, _log = _run(procs, tmp_path, 14, "router,at=5,duration=1", "stop,agent=5,at=9,duration=2")
    f, hung = s["faults"]
    acts = {a["action"]: a["taken_at"] for a in s["fault_actions"]}
    down = acts["router_up"] - acts["router_down"]
    # 1 s of world time, taken within a launcher poll (0.1 s of wall time, 0.05 of world
    # time at 0.5) of each end, and "up" logged once the router session is open again
    # (measured 0.5 s of wall time: 0.25 of world time); 1.5 leaves 0.2 s for a busy machine.
    assert 0.9 < down < 1.5, s["fault_actions"]
    # Every process came back: exit 0, every agent's final stats recorded.
    assert all(c == 0 for c in s["exit_codes"].values()), s["exit_codes"]
    assert not (why := not_alive(out, s)), why
    # Loss counted from sequence numbers: each sensor stream lost the world's samples of the
    # outage (200 Hz of world time), plus those sent while the clients reconnected (≤ 0.5 s
    # of wall time measured, 0.25 s of world time at 0.5; 1 s allowed).
    for i in range(1, 9):
        n = f["lost"].get(f"sense/{i}", 0)
        assert 200 * down - 2 <= n <= 200 * (down + 1.0), (i, n, down)
        # The agent counted the same gap on its own sensor link, from the same numbers.
        assert s["links"][f"world->{i}"]["dropped"] >= 200 * down - 2
    # The hung agent: flagged by its neighbour within the lease, back at once at its SIGCONT.
    d6 = hung["detected_by"]["6"]
    assert d6["lost_after_s"] is not None and 0 <= d6["lost_after_s"] < HUNG_BOUND_S, d6
    # At the SIGCONT its session, dropped by the router at the lease's end, reconnects and
    # declares its token again: measured 0.11 s at time scale 1 (the client's retry starts at
    # 0.1 s); 1.0 s of world time leaves a busy machine 2 s of wall time.
    assert d6["back_after_end_s"] is not None and d6["back_after_end_s"] < 1.0, d6
    assert hung["steps_missed"] >= 190  # 2 s at 100 Hz
