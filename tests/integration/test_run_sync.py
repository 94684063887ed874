"""``zswarm run`` closes the loop: §5.6's hybrid law over Zenoh, torques to the world's plant.

The run is judged against ``sim`` on the same scenario and against
READING-NOTES: settle times of max_k |R̄_k|_I within 25 % (the issue's
criterion; both engines step the same objects on the same samples, but over
Zenoh the agents tick asynchronously and a torque reaches the world 0.3–5 ms
after it was computed instead of at once, which moves the lightly damped
transient by seconds, not tens of seconds).  While it runs, hostile and
malformed commands are published on the command keys: each must be counted
by the world and none applied (one NaN torque would make the plant NaN and
the run never settle).
"""

from __future__ import annotations

import json
import math
import time

import msgpack
import numpy as np
import pytest

from tests.conftest import TOPO
from tests.integration.conftest import assert_run_exit_ok, fail_if_overloaded, not_alive, require_kept_up, stop_tail, wait_for, zswarm
from zswarm.transport import keys, wire
from zswarm.transport.bus import ZenohBus, zenoh_config

pytestmark = pytest.mark.integration
NAME = "thesis-5.6-hybrid7"
# The run's horizon: the first 75 of the scenario's 150 s.  What is checked over Zenoh is the
# transient, where asynchrony and command latency act: the jumps (all by 9.8 s in sim) and the
# settle below 0.1 (58.5 s in READING-NOTES; a run may be 25 % later than sim, 73 s, so 75 s
# decides it).  The settle below 0.01 (102 s) is the same decay continued at the equations'
# rate (k_ω = 0.1: 0.053 /s from 0.1 to 0.01), which sim holds against READING-NOTES at 100 Hz
# and 1 kHz (test_sim_sync); over Zenoh it cost 75 s of the integration layer's wall time.
DURATION = 75.0


def _bad_commands(run: str) -> list[tuple[str, bytes]]:
    """Five commands the world must drop: garbage, a NaN torque, a wrong shape, another
    agent's src on agent 3's key, an agent the scenario does not have."""
    nan = msgpack.packb({"v": wire.VERSION, "type": "cmd", "src": 3, "seq": 10**6, "inc": 0, "t": 1.0, "t_local": 1.0, "tau": [[3], np.array([np.nan, 0.0, 0.0]).tobytes()]})
    return [
        (keys.cmd(run, 2), b"\x93garbage"),
        (keys.cmd(run, 3), nan),
        (keys.cmd(run, 4), wire.encode("cmd", 4, 10**6, 1.0, t_local=1.0, tau=np.zeros(2))),
        (keys.cmd(run, 5), wire.encode("cmd", 6, 10**6, 1.0, t_local=1.0, tau=np.zeros(3))),
        (keys.cmd(run, 99), wire.encode("cmd", 99, 0, 1.0, t_local=1.0, tau=np.zeros(3))),
    ]


def test_hybrid_law_over_zenoh_matches_sim_and_drops_bad_commands(procs, sim_reference, tmp_path):
    out = tmp_path / "run"
    ref = sim_reference(TOPO / f"{NAME}.toml", tmp_path / "sim", DURATION, lean=True)  # computed while the run runs
    # At time scale 1 (DURATION world s in as many s of wall time): seven agents at 100 Hz and the
    # rigid-body world at 1 kHz use 0.8-1.0 of this machine's two cores (2026-12-03, summary
    # "cpu": agents 6-8 % of a core each, world 16 %, router 10 %, recorder 8 %).  Beside
    # `stress-ng --cpu 1` the agents missed ≤ 0.04 % of their ticks and the world skipped
    # 0.3-0.7 % of its samples in three runs: not overloaded, so the equations' checks below
    # ran (8 jumps, settled below 0.1 at 58.5 s and 0.01 at 98.9 s in the first).  Before
    # issue 28 the same needed 1.7-1.9 cores, and at time scale 0.5 with a core busy the
    # agents stepped at 55-60 Hz; an overloaded run fails the test (its settle times and
    # jumps would not be the equations').
    p = procs.start(zswarm("run", str(TOPO / f"{NAME}.toml"), "--out", str(out), "--duration", f"{DURATION:g}", "--time-scale", "1", "--quiet", "--no-plots"), log=tmp_path / "launcher.log")
    meta = wait_for(lambda: (out / "processes.json").exists() and json.loads((out / "processes.json").read_text()), 60, "processes.json")
    run_id, ep = meta["run_id"], meta["router"]["endpoint"]
    procs.adopt(out)
    alive: set = set()
    with ZenohBus(zenoh_config("client", connect=[ep])) as bus:
        bus.watch_alive(keys.alive_all(run_id), lambda k, up: (alive.add if up else alive.discard)(keys.parse_alive(k)))
        wait_for(lambda: ("world", 0) in alive, 90, "world alive")
        time.sleep(3.0)  # into the run: the world is sampling and applying commands
        pubs = {}
        for key, payload in _bad_commands(run_id):
            pubs.setdefault(key, bus.publisher(key)).put(payload)
        time.sleep(0.5)
    code = p.wait(DURATION * 2 + 120)  # DURATION s of wall time, ×2 for a loaded machine, + start-up
    procs.adopt(out)
    s = assert_run_exit_ok(code, out, tmp_path / "launcher.log")
    assert s["completed"]
    assert not (why := not_alive(out, s)), why

    # Every bad command counted, none applied (a NaN torque would never let the run settle).
    assert s["commands"]["malformed"] == 5, s["commands"]
    log = (out / "logs" / "world.log").read_text()
    assert log.count("dropped malformed command") == 5  # once per key, five keys
    # Command links: every agent's torques reached the world; latency measured.
    cmd = {k: v for k, v in s["links"].items() if k.endswith("->world")}
    assert len(cmd) == 7
    for link, v in cmd.items():
        _assert_commands_delivered(s, link, v)
        assert v["latency_p50_ms"] < 20, v
    ov = s["overload"]

    ss = ref.summary()
    sy, sy_sim = s["synchronization"], ss["synchronization"]
    # Every ξ_k jumps 0 -> 0.9π at the start (the first steps after the epoch), finitely often after.
    for e in s["edges"].values():
        j = e["jump_log"][0]
        assert j["t"] < 0.1 and j["xi_before"] == pytest.approx(0.0, abs=1e-6) and j["xi_after"] == pytest.approx(0.9 * math.pi)
    # A run that did not keep up stepped on older data than configured: a delay τ takes
    # about k_R·λ(A)·τ ≈ 12τ off the damping k_ω = 0.1 (attitude_sync_terms, "Sampled
    # data"), so at 55-60 Hz with 20-30 ms old measurements the loop does not settle and
    # keeps jumping (measured: 22, 52 and 91 jumps in 150 s).  Neither the settle times
    # nor the jump count are then the equations': such a run fails here, saying why.
    assert not ov["overloaded"] or "OVERLOADED" in (tmp_path / "launcher.log").read_text()
    fail_if_overloaded(s, "the jumps and settle times")
    # sim (and READING-NOTES, and sim at 10x the rates) has 8: six at the start, two at 7.6 and
    # 9.8 s (test_sim_sync).  Over Zenoh each agent steps on data 0-15 ms old, which takes
    # ≈ 12τ off the damping k_ω = 0.1 (≈ 0.06 at the mean τ ≈ 5 ms): ‖ω‖ swings longer, and an
    # R̄_k that swings back through its δ band jumps again, at most once a swing.  The settle
    # times below hold the swings to sim's within 25 %; the bound here allows each of the six
    # edges one swing more than sim's (8 + 6), where chattering, the failure it exists for,
    # shows as hundreds (the noisy §4.5 observer: 1000-1400 jumps per edge in 30 s).
    assert 6 <= s["jumps_total"] <= ss["jumps_total"] + len(s["edges"]), (s["jumps_total"], ss["jumps_total"])
    key, notes = "settles_below_0.1_at", 58.5
    got, ref = sy[key], sy_sim[key]
    assert got is not None and ref is not None, (sy, sy_sim)
    assert abs(got - ref) <= 0.25 * ref, (key, got, ref)  # run vs sim (the criterion)
    assert abs(got - notes) <= 0.25 * notes, (key, got, notes)  # run vs READING-NOTES
    assert sy["settles_below_0.01_at"] is None and sy_sim["settles_below_0.01_at"] is None, (sy, sy_sim)  # not by 75 s: the horizon is the transient's
    # The machine's capacity, last (an overloaded run reruns; the checks above were made on it).
    require_kept_up(s, "the command rates and ages")
    for link, v in cmd.items():
        _assert_command_rate(link, v, DURATION, 0.95)
    assert all(v["expired"] == 0 for v in s["commands"]["per_agent"].values()), s["commands"]  # none outlived its max_age at the world


def _assert_commands_delivered(s: dict, link: str, v: dict) -> None:
    """Agent i -> world: a command per step that computed one (all but the steps before the first
    measurements), none lost in between, only the stop's tail undelivered (on any run)."""
    a = s["agents"][link.split("->")[0]]
    assert 0.9 * a["steps"] <= v["sent"] <= a["steps"], (link, v, a["steps"])
    assert v["dropped"] == 0 and v["delivered"] >= v["sent"] - stop_tail(100.0), (link, v)


def _assert_command_rate(link: str, v: dict, duration: float, share: float) -> None:
    """At the configured 100 Hz on a run that kept up: more than ``share`` of duration × 100
    commands (the steps before the first measurements and the start-up are the rest)."""
    assert v["sent"] > share * duration * 100, (link, v)


def test_velocity_free_law_over_zenoh_starts_like_the_thesis(procs, tmp_path):
    """The velocity-free law (no gyro) over real processes, first 15 s: every ξ_k and every ζ_i
    jumps 0 -> 0.9π at the start (§5.6: Q̃_i(0) = Ra(π, e3) too), the filter (Q_i, ζ_i) then
    tracks R_i (|Q̃_i|_I < 0.1 after 5 s; READING-NOTES: ≈ 0.05), and torques reach the world.

    At time scale 1: beside `stress-ng --cpu 1` (2026-12-03) the agents keep up; the world
    skipped 0.2-2.0 % of its samples over three runs while it skipped every sample it woke a
    period late (now two: test_run.py).  An overloaded run fails: its jumps would not be the
    law's."""
    name = "thesis-5.6-velocity-free7"
    out = tmp_path / "run"
    args = ("--out", str(out), "--duration", "15", "--time-scale", "1", "--quiet", "--no-plots")
    p = procs.start(zswarm("run", str(TOPO / f"{name}.toml"), *args), log=tmp_path / "launcher.log")
    code = p.wait(15 * 3 + 120)  # 15 world s at time scale 1: 15 s of wall time, ×3 for a loaded machine, + start-up
    procs.adopt(out)
    s = assert_run_exit_ok(code, out, tmp_path / "launcher.log")
    assert s["completed"]
    assert not (why := not_alive(out, s)), why
    for e in s["edges"].values():
        j = e["jump_log"][0]
        assert j["t"] < 0.1 and j["xi_after"] == pytest.approx(0.9 * math.pi)
    for a in s["agents"].values():
        j = a["zeta_jump_log"][0]
        assert j["t"] < 0.1 and j["zeta_before"] == pytest.approx(0.0, abs=1e-9) and j["zeta_after"] == pytest.approx(0.9 * math.pi)
        assert a["Q_tilde_max_after_5s"] < 0.1, a
    fail_if_overloaded(s, "the jump counts")  # stale data move the jumps
    # sim has 8 ξ-jumps (six at the start) and 7 ζ-jumps (one per agent at the start) over the
    # whole 150 s, so at most that in these 15 s (docs/studies/chapter5.md, test_sim_sync).  As in the hybrid
    # test above, data 0-15 ms old over Zenoh take damping off, so an R̄_k (or a Q̃_i) that swings
    # back through its δ band may jump once more a swing: one more per edge (6) and per agent (7)
    # than sim's.  Chattering, the failure this exists for, shows as hundreds.
    n_edges, n_agents = len(s["edges"]), len(s["agents"])
    assert s["jumps_total"] <= 8 + n_edges and s["zeta_jumps_total"] <= 7 + n_agents, (s["jumps_total"], s["zeta_jumps_total"])
    cmd = {k: v for k, v in s["links"].items() if k.endswith("->world")}
    assert len(cmd) == 7
    for link, v in cmd.items():
        _assert_commands_delivered(s, link, v)
    assert s["commands"]["malformed"] == 0
    require_kept_up(s, "the command rates")
    for link, v in cmd.items():
        _assert_command_rate(link, v, 15.0, 0.9)  # 15 s: the start-up is a larger share
