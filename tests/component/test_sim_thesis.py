"""``zswarm sim`` reproduces the thesis §3.3.4 and §4.5 runs (READING-NOTES numbers).

Tolerances as in test_sim.py: READING-NOTES integrates the continuous-time
observers with Lie–Euler at 1 ms, we step at 100 Hz with 200 Hz sensors, so
curves agree to ~10–30 %; ±30 % bands (or the issue's thresholds) still fail
on a wrong sign, gain or convention, which changes them by orders of
magnitude.
"""

import math

import numpy as np
import pytest

from tests.conftest import TOPO
from tests.notes import agrees, interval
from zswarm.engines.sim import simulate
from zswarm.families.tree import tree_metrics
from zswarm.report import load_recording
from zswarm.results import make_report
from zswarm.scenario import load

STEP_45 = {10.0: 0.1, 20.0: 0.2}  # 2 x 4.6 % and 2 x 9.4 %, rounded up (module docstring)
# §4.5 hybrid5's relative attitude error |R̄_k|_I at 20 s per edge, the scenario at 10x the rates
# (zswarm.studies.step_size.refine: 1 kHz ticks, 2 kHz sensors; 2026-12-07): the dt -> 0 reference
# the 100 Hz run is held to.  100 Hz gave 1.290e-3, 2.096e-3, 2.098e-3, 1.296e-3: 8.9-9.5 % above.
FINE_45_REL_ATT_20S = {1: 1.185e-3, 2: 1.916e-3, 3: 1.915e-3, 4: 1.183e-3}
# §3.3.4's mean position error at 100 Hz against 10x the rates: 1.0 % above at 10 s, 2.6 % at 20 s,
# 4.2 % at 30 s (0.0223 against 0.0214; READING-NOTES' dt -> 0: 0.022–0.023); twice that, rounded up.
STEP_33 = {2.0: 0.02, 10.0: 0.02, 20.0: 0.06, 30.0: 0.09}


def sim(tmp, name, duration=None):
    sc = load(TOPO / f"{name}.toml")
    d = sc.duration if duration is None else duration
    simulate(sc, tmp, d, sc.seed)
    summary = make_report(tmp, sc, "sim", d, 0.0, sc.seed, plots=False)
    return sc, summary, load_recording(tmp / "recording.mcap")


def at(tm_t, series, t):
    return series[int(np.searchsorted(tm_t, t - 1e-9))]


@pytest.fixture(scope="module")
def moving5(tmp_path_factory):
    sc, summary, rec = sim(tmp_path_factory.mktemp("m5"), "thesis-3.3-moving5")
    return summary, _follower_means(tmp_path_factory, summary, rec)


def _follower_means(_f, summary, rec):
    from zswarm.report import errors

    errs = errors(rec)
    out = {}
    for T in (0.0, 2.0, 5.0, 10.0, 20.0, 30.0):
        rows = [e[np.argmin(np.abs(e[:, 0] - T))] for i, e in errs.items() if i > 2]
        out[T] = (np.mean([r[1] for r in rows]), np.mean([r[2] for r in rows]))
    return out


def test_moving5_matches_reading_notes(moving5):
    summary, m = moving5
    assert agrees(m[0.0][0], "0.31", 0.0), m[0.0]  # t = 0: the scenario's values
    # READING-NOTES' 5.5 at t = 0 is the direct ‖p − p̂‖; the thesis' ‖p̃‖, p̃ = p − R R̂^T p̂
    # (3.26), computed here from the scenario's initial values, is what errors.csv reports.
    sc = load(TOPO / "thesis-3.3-moving5.toml")
    fol = [a for a in sc.agents if a.role == "follower"]
    direct = np.mean([np.linalg.norm(np.array(a.p) - np.array(a.estimate["p"])) for a in fol])
    tilde = np.mean([np.linalg.norm(np.array(a.p) - a.R_matrix @ np.array(a.estimate["R"]).reshape(3, 3).T @ np.array(a.estimate["p"])) for a in fol])
    assert direct == pytest.approx(5.5, rel=0.01)  # READING-NOTES prints two figures: ±0.05 = 0.9 %
    # The first row is the initial estimate against the truth at t = 0: the same formula,
    # so only round-off (1e-15) separates them.
    assert m[0.0][1] == pytest.approx(tilde, rel=1e-12)
    # notes: ≈1e-4 within 2 s, so below what prints as 1e-4 by then (ours 3.7e-6, the 10x run's
    # 1.6e-6: the attitude's floor, no longer its transient)
    assert m[2.0][0] < interval("1e-4", STEP_33[2.0])[1]
    assert m[5.0][0] < 1e-2  # the threshold
    assert agrees(m[10.0][1], "0.4", STEP_33[10.0]), m[10.0]
    assert agrees(m[20.0][1], "0.09", STEP_33[20.0]), m[20.0]
    assert m[30.0][1] < 0.1 and agrees(m[30.0][1], "0.02", STEP_33[30.0]), m[30.0]  # the issue's threshold; the notes' ≈ 0.02
    assert summary["mean_position_error_final"] < 0.05


@pytest.fixture(scope="module")
def hybrid5(tmp_path_factory):
    sc, summary, rec = sim(tmp_path_factory.mktemp("h5"), "thesis-4.5-hybrid5")
    return sc, summary, rec, tree_metrics(sc, rec)


def test_hybrid5_jumps_once_at_start_to_0_08pi(hybrid5):
    sc, summary, rec, _ = hybrid5
    assert summary["jumps_total"] == 4
    for k, e in summary["edges"].items():
        assert e["jumps"] == 1 == e["jumps_reported_by_head"], k
        (j,) = e["jump_log"]
        assert j["t"] <= 0.02 and j["xi_before"] == 0.0 and j["xi_after"] == pytest.approx(0.08 * math.pi)


def test_hybrid5_matches_reading_notes(hybrid5):
    sc, summary, rec, tm = hybrid5
    for k in tm.rel_att:
        assert at(tm.t, tm.rel_att[k], 0.0) == pytest.approx(1.0, abs=1e-6)
        # notes: 0.04–0.06 at 10 s (what prints as 0.04 to what prints as 0.06), widened by STEP_45[10]
        assert interval("0.04", STEP_45[10.0])[0] <= at(tm.t, tm.rel_att[k], 10.0) < interval("0.06", STEP_45[10.0])[1], k
        # notes: "≈ 1e-3 at 20 s" for every edge, one figure read off a log-scale plot: what rounds
        # to 1e-3 there is [10^-3.5, 10^-2.5).  The equations themselves (the same scenario at 10x
        # the rates) put edges 1, 4 at 1.18e-3 and edges 2, 3 at 1.92e-3; 100 Hz is within
        # STEP_45[20] (twice the measured step error) of them.
        x = at(tm.t, tm.rel_att[k], 20.0)
        assert 10**-3.5 <= x < 10**-2.5, (k, x)
        assert x == pytest.approx(FINE_45_REL_ATT_20S[k], rel=STEP_45[20.0]), k
        assert np.max(tm.rel_att[k][tm.t >= 25.0]) < 1e-2  # the threshold
    assert abs(summary["edges"]["1"]["xi_final"]) < 1e-2


def test_continuous5_leaves_the_undesired_equilibrium(tmp_path):
    """Theorem 4.1 gives no escape guarantee; asynchronous steps perturb it off the unstable set."""
    sc, summary, rec = sim(tmp_path, "thesis-4.5-continuous5", duration=10.0)
    tm = tree_metrics(sc, rec)
    for k in tm.rel_att:
        assert at(tm.t, tm.rel_att[k], 0.0) == pytest.approx(1.0, abs=1e-6)
    assert summary["max_relative_attitude_error_final"] < 1e-2


def test_hybrid_pose5_recovers_the_formation(tmp_path):
    sc, summary, rec = sim(tmp_path, "thesis-4.5-hybrid-pose5")
    assert summary["jumps_total"] == 4
    assert summary["max_relative_attitude_error_final"] < 1e-2
    assert summary["max_relative_position_error_final"] < 0.1  # the threshold
    assert "common frame" in summary["errors_up_to"]


@pytest.mark.parametrize("name", ["thesis-4.5-hybrid5-noisy", "thesis-3.3-moving5-noisy"])
def test_noisy_runs_stay_bounded(tmp_path, name):
    sc, summary, rec = sim(tmp_path, name, duration=20.0)
    if summary["report_family"] == "tree":
        assert summary["max_relative_attitude_error_final"] < 0.2
        assert summary["mean_relative_attitude_error_final"] > 1e-3  # the noise really is on
    else:
        assert summary["mean_attitude_error_final"] < 0.2
        assert summary["mean_position_error_final"] < 1.5
