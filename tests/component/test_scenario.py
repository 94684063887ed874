"""Scenario loading and every bad-input path: ``file: field: problem (got X)``."""

import math
import subprocess
import sys
import warnings

import numpy as np
import pytest

from tests.conftest import ROOT, TOPO
from zswarm.math import so3
from zswarm.scenario import ScenarioError, load, loads


@pytest.mark.parametrize("name", ["thesis-3.2-fixed8", "thesis-3.2-fixed8-filtered", "thesis-3.2-fixed8-noisy"])
def test_shipped_scenarios_load(name):
    sc = load(TOPO / f"{name}.toml")
    assert sc.name == name and len(sc.agents) == 8 and sc.duration == 40.0


def test_fixed8_reproduces_thesis_3_2_5():
    sc = load(TOPO / "thesis-3.2-fixed8.toml")
    assert sc.agent(7).p == (2.0, 2.0, 6.0)
    assert sc.agent(6).neighbors == (2, 4, 5)
    assert [a.role for a in sc.agents] == ["leader"] * 2 + ["follower"] * 6
    R6 = np.array(sc.agent(6).estimate["R"]).reshape(3, 3)
    assert np.allclose(R6, so3.Ra(0.9 * math.pi, np.array([1.0, 0, 0])), atol=1e-15)
    assert sc.agent(8).estimate["p"] == (-3.0, 0.5, 2.0)
    assert sc.agent(5).omega[2](0.1) == pytest.approx(math.sin(0.9))
    assert dict(sc.gains) == {"k_R": 1.0, "k_p": 1.0}
    noisy = load(TOPO / "thesis-3.2-fixed8-noisy.toml")
    assert noisy.agent(6).gyro_bias == (0.1, 0.04, 0.03) and noisy.gyro_var == 0.01 and noisy.bearing_var == 0.001
    filt = load(TOPO / "thesis-3.2-fixed8-filtered.toml")
    assert dict(filt.gains) == {"k_Omega": 1.0, "k_p": 1.0}


BAD = [
    # (replace this, with that, error must match)
    ("seed = 1", "seed = 1\ncolour = 3", r"x\.toml: scenario\.colour: unknown key"),
    ("duration = 40.0", 'duration = "long"', r"x\.toml: scenario\.duration: must be a number \(got 'long'\)"),
    ("k_R = 1.0", "k_R = -0.5", r"x\.toml: algorithm\.gains\.k_R: must be > 0 \(got -0\.5\)"),
    ("neighbors = [1, 7]", "neighbors = [7]", r"x\.toml: agents\[7\]\.neighbors: a follower needs at least 2 in-neighbours"),
    ("neighbors = [2, 3]", "neighbors = [2, 5]", r"x\.toml: agents\[3\]\.neighbors: in-neighbours must be numbered below the agent.*\(got 5\)"),
    ('omega = ["-cos(t)", "1", "sin(2*t)"]', 'omega = ["-cos(t)", "1", "sinh(2*t)"]', r"x\.toml: agents\[2\]\.omega\[2\]: unknown name 'sinh'"),
    ('name = "bearing_pose_fixed"', 'name = "magic"', r"x\.toml: algorithm\.name: unknown algorithm"),
    ("p = [0, 2, 7]", "p = [2, 2, 6]", r"x\.toml: agents\[7\]\.p: agent 8 is collocated with agent 7"),
    ('role = "leader"\np = [2, 0, 1]', 'role = "follower"\np = [2, 0, 1]', r"x\.toml: agents\[1\]\.role: agent 2 must be a leader"),
    ("id = 8", "id = 9", r"x\.toml: agents: ids must be 1\.\.n"),
    ("rate = 100.0", "rate = 0", r"x\.toml: clock\.rate: must be > 0 \(got 0\)"),
    ("step = 0.001", "step = 0.01", r"x\.toml: world\.step: must be <= 0\.001"),
    # Accepted before, and the world never finished:
    ("step = 0.001", "step = 1e-300", r"x\.toml: world\.step: must be >= 1e-06 \(got 1e-300\)"),
    ("duration = 40.0", "duration = 1e300", r"x\.toml: scenario\.duration: must be <= 1e\+06 \(got 1e\+300\)"),
]


@pytest.mark.parametrize("old, new, match", BAD)
def test_bad_input_names_file_field_problem(fixed8_text, old, new, match):
    assert old in fixed8_text
    with pytest.raises(ScenarioError, match=match):
        loads(fixed8_text.replace(old, new, 1), "x.toml")


@pytest.mark.parametrize("axis, unit", [("[1e300, 1e300, 0]", (0.5**0.5, 0.5**0.5, 0.0)), ("[1e-200, 0, 1e-200]", (0.5**0.5, 0.0, 0.5**0.5)), ("[0, 3, 4]", (0.0, 0.6, 0.8))])
def test_axes_far_from_unit_length(axis, unit):
    """Axes whose norm overflows or underflows in floats are still directions: the
    formation's axis was (0, 0, 0) for the first (norm inf) with a RuntimeWarning, and the
    rotation's was refused as zero for the second."""
    text = (TOPO / "thesis-3.3-moving5.toml").read_text()
    old = "formation = { axis = [1, 0, 0]"
    assert old in text
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow on the way
        sc = loads(text.replace(old, f"formation = {{ axis = {axis}", 1), "x.toml")
    assert sc.formation is not None
    assert sc.formation.axis == pytest.approx(unit, abs=1e-15)  # one division each: a few ulps
    fixed8 = (TOPO / "thesis-3.2-fixed8.toml").read_text()
    sc8 = loads(fixed8.replace('R = { angle = "0.1*pi", axis = [1, 0, 0] }', f'R = {{ angle = "0.1*pi", axis = {axis} }}', 1), "x.toml")
    R = np.array(sc8.agent(3).estimate["R"]).reshape(3, 3)
    # The same rotation of axes equal to a few ulps (above): entries within ~1e-16 each.
    assert np.allclose(R, so3.Ra(0.1 * math.pi, np.array(unit)), atol=1e-15)
    with pytest.raises(ScenarioError, match=r"x\.toml: world\.formation\.axis: must be non-zero"):
        loads(text.replace(old, "formation = { axis = [0, -0.0, 0]", 1), "x.toml")


def test_collinear_bearings_rejected(fixed8_text):
    # Agent 3 at (2, 2, 2) sees 1 at (0,0,0) and 2 moved to (1,1,1): collinear bearings.
    text = fixed8_text.replace("p = [2, 0, 1]", "p = [1, 1, 1]", 1)
    with pytest.raises(ScenarioError, match=r"x\.toml: agents\[2\]\.neighbors: bearings to in-neighbours are collinear"):
        loads(text, "x.toml")


def test_missing_file_and_bad_toml(tmp_path):
    with pytest.raises(ScenarioError, match="nope.toml: cannot read file"):
        load(tmp_path / "nope.toml")
    bad = tmp_path / "b.toml"
    bad.write_text("[scenario\n")
    with pytest.raises(ScenarioError, match="b.toml: TOML syntax"):
        load(bad)


def _zswarm(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "zswarm", *args], capture_output=True, text=True, cwd=cwd, timeout=60)


@pytest.mark.parametrize("old, new, match", BAD[:6])
def test_cli_exits_2_with_one_line(tmp_path, fixed8_text, old, new, match):
    f = tmp_path / "x.toml"
    f.write_text(fixed8_text.replace(old, new, 1))
    r = _zswarm("sim", str(f), "--out", str(tmp_path / "out"))
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and str(f) in lines[0]
    import re

    assert re.search(match.replace(r"x\.toml", ""), lines[0])


@pytest.mark.parametrize("argv", [[], ["run"], ["sim"], ["run", "t.toml", "--duration", "-3"], ["run", "t.toml", "--time-scale", "x"], ["frobnicate"]])
def test_cli_usage_errors(argv):
    r = _zswarm(*argv)
    assert r.returncode == 2 and "usage:" in r.stderr


def test_process_entry_points_usage_errors():
    for mod, argv in (("agent", ["--topology", "topologies/thesis-3.2-fixed8.toml"]), ("world", []), ("agent", ["--topology", "topologies/thesis-3.2-fixed8.toml", "--id", "99", "--connect", "tcp/127.0.0.1:1"])):
        r = subprocess.run([sys.executable, "-m", mod, *argv], capture_output=True, text=True, cwd=ROOT, timeout=60)
        assert r.returncode == 2, (mod, argv, r.stderr)


def test_a_motion_not_finite_later_in_the_run_is_named():
    # 1/(1-t) is finite at t = 0 (the expression's own check) and infinite at t = 1: the
    # truth turned NaN there and every sensor packet was dropped as malformed, silently.
    text = (TOPO / "thesis-3.3-moving5.toml").read_text()
    old = 'omega = ["-cos(3*t)", "1", "sin(2*t)"]'
    assert old in text
    bad = text.replace(old, 'omega = ["-cos(3*t)", "1/(1-t)", "sin(2*t)"]', 1)
    with pytest.raises(ScenarioError, match=r"x\.toml: agents\[1\]\.omega\[1\]: is not finite at t = 1 s .*'1/\(1-t\)'"):
        loads(bad, "x.toml")
    # A pole between two grid points is not found this way; one on a millisecond is.
    with pytest.raises(ScenarioError, match=r"omega\[1\]: is not finite at t = 12\.345 s"):
        loads(text.replace(old, 'omega = ["-cos(3*t)", "1/(t-12.345)", "sin(2*t)"]', 1), "x.toml")
    loads(text.replace(old, 'omega = ["-cos(3*t)", "1/(t-31)", "sin(2*t)"]', 1), "x.toml")  # after the run's 30 s: fine


def test_a_sensor_rate_under_1_hz_runs(tmp_path, fixed8_text):
    # 0.4 Hz was accepted by the loader and then divided by zero in the world and in sim
    # (stats every round(sensor_rate) samples).
    f = tmp_path / "slow.toml"
    f.write_text(fixed8_text.replace("sensor_rate = 200.0", "sensor_rate = 0.4", 1))
    r = _zswarm("sim", str(f), "--duration", "6", "--out", str(tmp_path / "out"))
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "out" / "summary.json").exists()


# Values the wire would reject later (issue 29): the loader says so first, file: field: problem.
WIRE_BOUNDS = [
    # An own clock past ±1e10 s: 2e12 put every message off the wire (all dropped, exit 0), 1e300 hung sim.
    ('rate = 100.0        # Hz, every agent\'s step rate on its own clock', "rate = 100.0\noffset = 2e12", r"x\.toml: clock\.offset: must be within ±1e\+10 s"),
    ('rate = 100.0        # Hz, every agent\'s step rate on its own clock', "rate = 100.0\noffset = 1e300", r"x\.toml: clock\.offset: must be within ±1e\+10 s"),
    # ω = 1e13 was a traceback; exp(3t) made the truth wire-invalid at 9.2 s (dropped, run "completed").
    ('omega = ["1", "-2", "1"]', 'omega = ["1e13", "-2", "1"]', r"x\.toml: agents\[0\]\.omega\[0\]: must be within ±1571 \(a quarter turn per world\.step of 0\.001 s\)"),
    # exp(3t) = π/2 / 1 ms at t = ln(1570.8)/3 = 2.4530 s: the first millisecond past it.
    ('omega = ["1", "-2", "1"]', 'omega = ["exp(3*t)", "-2", "1"]', r"x\.toml: agents\[0\]\.omega\[0\]: reaches 1575 at t = 2\.454 s, beyond ±1571"),
    # gyro_var = 1e30: every packet beyond the wire's bound, 0 steps, exit 0.
    ("seed = 1", "seed = 1\n[noise]\ngyro_var = 1e30\nbearing_var = 0.0", r"x\.toml: noise\.gyro_var: must be <= 1e\+22"),
    # The name is the results folder's: one outside runs/, a NUL a traceback.
    ('name = "thesis-3.2-fixed8"', 'name = "тест ☃/../../x"', r"x\.toml: scenario\.name: must be a file name"),
    ('name = "thesis-3.2-fixed8"', 'name = "a\\u0000b"', r"x\.toml: scenario\.name: must be a file name"),
    ('name = "thesis-3.2-fixed8"', 'name = ".."', r"x\.toml: scenario\.name: must be a file name"),
]


@pytest.mark.parametrize("old, new, match", WIRE_BOUNDS)
def test_the_loader_knows_the_wires_bounds(fixed8_text, old, new, match):
    assert old in fixed8_text
    with pytest.raises(ScenarioError, match=match):
        loads(fixed8_text.replace(old, new, 1), "x.toml")


def test_names_and_bounds_that_stay_allowed(fixed8_text):
    for name in ("тест-1", "run_2.b", "a" * 100):
        assert loads(fixed8_text.replace('name = "thesis-3.2-fixed8"', f'name = "{name}"', 1), "x.toml").name == name
    rate = 'rate = 100.0        # Hz, every agent\'s step rate on its own clock'
    assert loads(fixed8_text.replace(rate, "rate = 100.0\noffset = 1.8e9", 1), "x.toml").agents[0].clock.offset == 1.8e9  # a Unix time
