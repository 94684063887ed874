"""``zswarm run`` on the §3.3 and §4 scenarios, against the issue's thresholds and ``sim``.

Agreement is judged on convergence times (the first time after which an
error stays below a threshold): the engines run the same objects on the same
sensor samples, but over Zenoh agents tick asynchronously and messages are
0.1–10 ms old, which shifts transients by a fraction of a second.  Measured
(2 cores): §4.5 hybrid per-edge settle times 14.4–16.1 s on run vs 13.9–15.4 s on sim;
±25 % fails for a broken engine (a missed jump or stale ξ changes them by
tens of seconds or prevents convergence).  Final floors are only required
to be below the thresholds on both, and the final errors within a factor 3
(conftest.SIM_RUN_TOL) unless the run flags itself as overloaded.
"""

from __future__ import annotations

import csv
import math
from collections import defaultdict

import numpy as np
import pytest

from tests.conftest import TOPO
from tests.integration.conftest import assert_run_exit_ok, assert_run_matches_sim, not_alive, zswarm
from zswarm.scenario import load

pytestmark = pytest.mark.integration

# Horizons shorter than the scenario's, the run's and sim's alike, where every check below is
# decided earlier.  thesis-4.5-hybrid-pose5 (60 s, run at time scale 0.5: 120 s of wall time):
# its checks are the attitude below 1e-2 by 25 s, the worst relative position's settle below
# 0.3 and the final relative position error below 0.1, which the equations pass at 33 s (the
# convergence study's fine run: position < 0.1 at 33 s, 3.0e-2 at 45 s, decaying at ≈ 0.1 /s;
# a run 25 % later than sim still passes 0.1 by 41 s).  45 s saves 30 s of wall time.
HORIZON = {"thesis-4.5-hybrid-pose5": 45.0}


def run(procs, sim_reference, tmp_path, name, time_scale=1.0):
    sc = load(TOPO / f"{name}.toml")
    duration = HORIZON.get(name, sc.duration)
    out = tmp_path / "run"
    sim_out = tmp_path / "sim"
    ref = sim_reference(TOPO / f"{name}.toml", sim_out, duration, record=True)  # computed while the run runs; its files are read below
    p = procs.start(zswarm("run", str(TOPO / f"{name}.toml"), "--out", str(out), "--duration", f"{duration:g}", "--time-scale", f"{time_scale:g}", "--quiet"), log=tmp_path / "launcher.log")
    code = p.wait(duration / time_scale * 3 + 90)
    procs.adopt(out)
    s = assert_run_exit_ok(code, out, tmp_path / "launcher.log")
    assert s["completed"]
    assert not (why := not_alive(out, s)), why
    assert all(c["dropped"] == 0 for c in s["links"].values()), s["links"]
    ss = ref.summary()
    return sc, out, s, sim_out, ss


def follower_means(path):
    """Mean over followers of (attitude, position) error in 0.1 s bins: (t, att, pos) arrays."""
    bins = defaultdict(list)
    for r in csv.DictReader(open(path / "errors.csv")):
        if int(r["agent"]) > 2:
            bins[round(float(r["t"]), 1)].append((float(r["attitude_error"]), float(r["position_error"])))
    t = np.array(sorted(bins))
    return t, np.array([np.mean([a for a, _ in bins[x]]) for x in t]), np.array([np.mean([p for _, p in bins[x]]) for x in t])


def settles(t, v, thr):
    above = np.nonzero(v >= thr)[0]
    return t[0] if len(above) == 0 else (t[above[-1] + 1] if above[-1] + 1 < len(t) else math.inf)


def edge_series(path, col):
    out = defaultdict(list)
    for r in csv.DictReader(open(path / "edges.csv")):
        out[int(r["edge"])].append((float(r["t"]), float(r[col])))
    return {k: np.array(v) for k, v in out.items()}


def test_moving5_run(procs, sim_reference, tmp_path):
    sc, out, s, sim_out, ss = run(procs, sim_reference, tmp_path, "thesis-3.3-moving5")
    t, att, pos = follower_means(out)
    assert np.max(att[t >= 5.0]) < 1e-2  # attitude < 1e-2 by 5 s
    assert pos[t >= 29.9][0] < 0.1 and s["mean_position_error_final"] < 0.1  # position < 0.1 by 30 s
    ts, atts, poss = follower_means(sim_out)
    assert np.max(atts[ts >= 5.0]) < 1e-2
    t_run, t_sim = settles(t, pos, 0.2), settles(ts, poss, 0.2)
    assert t_run == pytest.approx(t_sim, rel=0.25), (t_run, t_sim)
    assert_run_matches_sim(s, ss, ("mean_attitude_error_final", "mean_position_error_final"), tmp_path / "launcher.log")


@pytest.mark.parametrize(("name", "time_scale"), [("thesis-4.5-hybrid5", 1.0), ("thesis-4.5-hybrid-pose5", 0.5)])
def test_hybrid_run(procs, sim_reference, tmp_path, name, time_scale):
    # Time scale 1 for §4.5 hybrid.  Beside `stress-ng --cpu 1` (2026-12-03, after issue 28's
    # cheaper ticks) the agents keep up (≤ 0.13 % missed ticks); the world skipped 0.5-1.9 % of
    # its samples over three runs of each while it skipped every sample it woke a period late,
    # near the 2 % where a run is overloaded; it now takes them late, up to 0.1 s (test_run.py).
    # Before issue 28 the agents missed 15-22 % at 1 and the settle times moved by +45 %.
    # The hybrid pose observer at 0.5: its ticks are the dearest of the shipped schemes (5 agents
    # and the world took 76 % of the two cores at 1 on a quiet machine, 2026-12-06), and in CI,
    # beside the background layer, 4 of its 5 agents missed over 2 % of their ticks, the worst
    # 5.8 % (overloaded, so the test failed: fail_if_overloaded).  At 0.5 the same processes
    # and links run at half the load; what the test checks (jumps, settle times, final errors
    # against sim) is in world time, which the time scale does not change.
    sc, out, s, sim_out, ss = run(procs, sim_reference, tmp_path, name, time_scale=time_scale)
    for k, e in s["edges"].items():
        first = e["jump_log"][0]
        assert first["t"] < 0.1 and first["xi_before"] == 0.0 and first["xi_after"] == pytest.approx(0.08 * math.pi), (k, e["jump_log"])
        # sim: exactly 1 per edge, the start's (test_sim_thesis).  Over Zenoh a neighbour's data are
        # up to 15 ms old, which can carry U(R̄_k, ξ_k) − min U back over δ = 0.003 while the
        # transient is fast: two more re-entries per edge are allowed; chattering, the failure
        # this guards against, shows as hundreds (the noisy case: 1000-1400 per edge in 30 s).
        assert e["jumps"] == e["jumps_reported_by_head"] <= ss["edges"][k]["jumps"] + 2, (k, e["jump_log"])
    ra, ras = edge_series(out, "relative_attitude_error"), edge_series(sim_out, "relative_attitude_error")
    for k in ra:
        assert np.max(ra[k][ra[k][:, 0] >= 25.0, 1]) < 1e-2, k  # every |R̄_k|_I < 1e-2 by 25 s
        t_run = settles(ra[k][:, 0], ra[k][:, 1], 1e-2)
        t_sim = settles(ras[k][:, 0], ras[k][:, 1], 1e-2)
        assert t_run == pytest.approx(t_sim, rel=0.25), (k, t_run, t_sim)
    if "pose" in name:
        assert s["max_relative_position_error_final"] < 0.1 and ss["max_relative_position_error_final"] < 0.1
        rp, rps = edge_series(out, "relative_position_error"), edge_series(sim_out, "relative_position_error")
        worst = np.max([rp[k][:, 1] for k in rp], axis=0)
        worst_s = np.max([rps[k][:, 1] for k in rps], axis=0)
        t_run, t_sim = settles(rp[1][:, 0], worst, 0.3), settles(rps[1][:, 0], worst_s, 0.3)
        assert t_run == pytest.approx(t_sim, rel=0.25), (t_run, t_sim)
    finals = ("mean_relative_attitude_error_final", "mean_attitude_error_final") + (("mean_relative_position_error_final",) if "pose" in name else ())
    assert_run_matches_sim(s, ss, finals, tmp_path / "launcher.log")
    for f in ("edges.csv", "plots/relative_attitude_error.png", "plots/xi.png"):
        assert (out / f).exists(), f
