"""``zswarm run`` on De Carli et al. (decarli-8-formation): eight agent processes over Zenoh,
each with its four parts at their own rates, the world's kinematic plant driven by their
commands; judged against ``sim`` on the same scenario.

Eight agents stepping at 200 Hz are more than two cores keep up with in real time (measured
at time scale 1: 20 % missed ticks, the run flags itself OVERLOADED), so the run goes at
time scale 0.25: the world's clock at a quarter of the wall clock, so the agents' ticks,
part rates and deadlines are the scenario's in world time with room for one busy core.
The first 8 s cover the three observers' transients (the formation itself needs ≈ 18 s).

What is compared, and why these bounds:

* each part's achieved rate (summary.json) within 2 % of 200/100/50/200 Hz: over Zenoh a
  part steps when a step ends ≥ its period less half a clock period after its last one,
  and sensor samples that arrive late are stepped on at the next tick (catch-up), so the
  count over the run is the configured one to a few steps in 12 s × rate;
* the settle times of the relative yaw (max over edges, < 0.05), the common-frame yaw
  (max over robots up to α, < 0.05) and the position (< 0.1 m) within 25 % of sim's (the
  issue's criterion) plus 0.05 s: over Zenoh, messages are 1–10 ms old and the agents
  start within a few of their first samples, which moves a 0.4 s transient by a few tens
  of ms (measured: 0.52/0.43/2.22 s against 0.46/0.38/2.20 s at 40 s);
* the floors below the thresholds, and the common rotation α constant over the run's
  second half (Theorem 2: < 0.05 rad; measured over 20–40 s: 2.0e-3 on run, 3.8e-4 on
  sim, the message ages leaving a (ω_i − ω_j)·a residue).
"""

from __future__ import annotations

import pytest

from tests.conftest import TOPO
from tests.integration.conftest import assert_run_exit_ok, not_alive, zswarm

pytestmark = pytest.mark.integration
NAME = "decarli-8-formation"
DURATION, SCALE = 8.0, 0.25


def test_decarli_over_zenoh_matches_sim(procs, sim_reference, tmp_path):
    out = tmp_path / "run"
    ref = sim_reference(TOPO / f"{NAME}.toml", tmp_path / "sim", DURATION, lean=True)  # computed while the run runs
    p = procs.start(
        zswarm("run", str(TOPO / f"{NAME}.toml"), "--out", str(out), "--duration", str(DURATION), "--time-scale", str(SCALE), "--quiet", "--no-plots"),
        log=tmp_path / "launcher.log",
    )
    code = p.wait(DURATION / SCALE * 2 + 120)
    procs.adopt(out)
    s = assert_run_exit_ok(code, out, tmp_path / "launcher.log")
    assert s["completed"]
    assert not (why := not_alive(out, s)), why
    ss = ref.summary()

    for a in s["agents"].values():
        for name, want in (("relative", 200.0), ("yaw", 100.0), ("position", 50.0), ("control", 200.0)):
            assert a["parts"][name]["rate_hz"] == pytest.approx(want, rel=0.02), (name, a["parts"])

    fr, fs = s["formation"], ss["formation"]
    for key in ("relative_yaw_max", "yaw_max", "position_max"):
        t_run, t_sim = fr["settle_s"][key], fs["settle_s"][key]
        assert t_run is not None and t_sim is not None, (key, fr["settle_s"], fs["settle_s"])
        assert abs(t_run - t_sim) <= 0.25 * t_sim + 0.05, (key, t_run, t_sim)
    assert fr["relative_yaw_error_max_final"] < 0.05 and fr["yaw_error_max_final"] < 0.05 and fr["position_error_max_final_m"] < 0.1, fr
    assert fr["common_rotation_alpha_drift_rad"] < 0.05, fr
