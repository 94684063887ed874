"""Scenario loading for §3.3 and §4: the shipped set-ups and every bad-input path."""

import math
import subprocess
import sys

import numpy as np
import pytest

from tests.conftest import ROOT, TOPO
from zswarm.math import so3
from zswarm.scenario import ScenarioError, load, loads

NEW = [
    "thesis-3.3-moving5",
    "thesis-3.3-moving5-noisy",
    "thesis-4.5-continuous5",
    "thesis-4.5-continuous5-noisy",
    "thesis-4.5-hybrid5",
    "thesis-4.5-hybrid5-noisy",
    "thesis-4.5-hybrid-pose5",
]


@pytest.mark.parametrize("name", NEW)
def test_shipped_scenarios_load(name):
    sc = load(TOPO / f"{name}.toml")
    assert sc.name == name and len(sc.agents) == 5 and sc.formation is not None


def test_moving5_reproduces_thesis_3_3_4():
    sc = load(TOPO / "thesis-3.3-moving5.toml")
    assert sc.formation.axis == (1.0, 0.0, 0.0) and sc.formation.rate == pytest.approx(math.pi / 6)
    assert [sc.agent(i).gains["k_R"] for i in (3, 4, 5)] == [10.0, 5.0, 3.0]
    assert sc.agent(5).neighbors == (3, 4) and sc.agent(4).p == (2.0, 1.0, -2.0)
    # Agent 4 and its neighbours 2, 3 lie on one line: accepted on persistent excitation, with a note.
    assert any("agent 4" in w and "persistent excitation" in w for w in sc.warnings)
    noisy = load(TOPO / "thesis-3.3-moving5-noisy.toml")
    assert (noisy.gyro_var, noisy.velocity_var, noisy.bearing_var) == (0.1, 0.1, 0.01)
    assert noisy.agent(4).gyro_bias == (0.1, 0.02, 0.01)


def test_hybrid5_reproduces_thesis_4_5():
    sc = load(TOPO / "thesis-4.5-hybrid5.toml")
    assert sc.oriented == ((1, 2), (2, 3), (3, 4), (4, 5)) and sc.oriented_from == "graph.edges"
    assert sc.params.Xi == pytest.approx((0.08 * math.pi,)) and sc.params.delta == 0.003 and sc.params.gamma == 1.9251
    assert dict(sc.gains) == {"k_R": 1.1, "k_xi": 3.5}
    assert sc.agent(5).omega[2](3.0) == 5.0 and sc.agent(2).neighbors == (1, 3)
    R2 = np.array(sc.agent(2).estimate["R"]).reshape(3, 3)
    assert np.allclose(R2, so3.Ra(math.pi / 2, np.array([0.0, 0, 1])))
    assert dict(sc.agent(1).estimate["xi"]) == {1: 0.0}
    pose = load(TOPO / "thesis-4.5-hybrid-pose5.toml")
    assert pose.agent(3).estimate["p"] == (-2.0, 0.0, -1.0) and pose.gains["k_p"] == 1.0
    noisy = load(TOPO / "thesis-4.5-hybrid5-noisy.toml")
    assert (noisy.gyro_var, noisy.rel_att_var) == (0.01, 0.01)


@pytest.fixture
def hybrid_text() -> str:
    return (TOPO / "thesis-4.5-hybrid5.toml").read_text()


BAD_TREE = [
    # (replace this, with that, error must match)
    ("edges = [[1, 2], [2, 3], [3, 4], [4, 5]]", "edges = [[1, 2], [2, 3], [3, 1], [4, 5]]", r"x\.toml: graph\.edges\[2\]: edge 3-1 closes the cycle .*Assumption 4\.2"),
    ("edges = [[1, 2], [2, 3], [3, 4], [4, 5]]", "edges = [[1, 2], [2, 3], [4, 5]]", r"x\.toml: graph\.edges: the graph is not connected"),
    ("edges = [[1, 2], [2, 3], [3, 4], [4, 5]]", "edges = [[1, 2], [2, 1], [3, 4], [4, 5]]", r"graph\.edges\[1\]: edge 2-1 listed twice"),
    ("edges = [[1, 2], [2, 3], [3, 4], [4, 5]]", "edges = [[1, 9], [2, 3], [3, 4], [4, 5]]", r"graph\.edges\[0\]: unknown agent 9"),
    ("gamma = 1.9251", "gamma = 2.1", r"x\.toml: algorithm\.params\.gamma: Prop\. 4\.2 needs 0 < γ < 4Δ\*/π² = 2\.02642 \(got 2\.1\)"),
    ("delta = 0.0030", "delta = 0.01", r"x\.toml: algorithm\.params\.delta: Prop\. 4\.2 needs 0 < δ < .* = 0\.0032"),
    ("u = [0, 0.6455, 0.7638]", "u = [1, 0, 0]", r"x\.toml: algorithm\.params\.u: is not Prop\. 4\.2's u"),
    ("A = [5, 8.57, 12]", "A = [5, 5, 12]", r"x\.toml: algorithm\.params\.A: needs three distinct eigenvalues \(Assumption 4\.4\)"),
    ('Xi = ["0.08*pi"]', 'Xi = ["1.2*pi"]', r"x\.toml: algorithm\.params\.Xi: every \|ξ\| must lie in \(0, π\]"),
    ("xi = { 2 = 0.0 }", "xi = { 1 = 0.0 }", r"x\.toml: agents\[1\]\.estimate\.xi\.1: ξ_1 lives at the head of edge 1 \(1 -> 2\), agent 1 \(Remark 4\.4\), not agent 2"),
    ("xi = { 2 = 0.0 }", "xi = { 7 = 0.0 }", r"agents\[1\]\.estimate\.xi\.7: no edge 7"),
    ("id = 5\n", 'id = 5\nrole = "leader"\n', r"agents\[4\]\.role: the §4 observers have no leaders"),
    ("k_xi = 3.5", "k_xi = 0", r"algorithm\.gains\.k_xi: must be > 0"),
]


@pytest.mark.parametrize("old, new, match", BAD_TREE)
def test_bad_tree_input_names_file_field_problem(hybrid_text, old, new, match):
    assert old in hybrid_text
    with pytest.raises(ScenarioError, match=match):
        loads(hybrid_text.replace(old, new, 1), "x.toml")


def test_tree_orientation_is_derived_when_not_given(hybrid_text):
    text = hybrid_text.replace("[graph]\nedges = [[1, 2], [2, 3], [3, 4], [4, 5]]   # [head, tail]; edge k is the k-th\n", "")
    # Each undirected edge listed by one end or both; the derived head is the smaller id.
    text = text.replace("id = 2\n", "id = 2\nneighbors = [1, 3]\n").replace("id = 4\n", "id = 4\nneighbors = [3, 5]\n")
    text = text.replace("id = 5\n", "id = 5\nneighbors = [4]\n")
    sc = loads(text, "x.toml")
    assert sc.oriented == ((1, 2), (2, 3), (3, 4), (4, 5)) and sc.oriented_from.startswith("derived")


def test_moving_follower_with_collinear_unexcited_bearings_is_rejected():
    text = (TOPO / "thesis-3.3-moving5.toml").read_text()
    # Agent 3 on the rotation axis' line through 1 and 2 would still be excited;
    # a fixed formation (no [world.formation]) keeps agent 4's line still.
    fixed = text.replace('formation = { axis = [1, 0, 0], rate = "pi/6" }\n', "")
    with pytest.raises(ScenarioError, match=r"x\.toml: agents\[3\]\.neighbors: bearings to in-neighbours are collinear at t = 0 and the motion does not excite them"):
        loads(fixed, "x.toml")
    # Rotating about the line itself (its direction is e3 through [2 1 z]) does not excite it either.
    along = text.replace('axis = [1, 0, 0], rate = "pi/6"', 'axis = [0, 0, 1], rate = "pi/6"').replace("p = [2, 1, 2]", "p = [0, 0, 2]").replace(
        "p = [2, 1, 0]", "p = [0, 0, 0.5]"
    ).replace("p = [2, 1, -2]", "p = [0, 0, -2]")
    with pytest.raises(ScenarioError, match=r"agents\[3\]\.neighbors: bearings to in-neighbours are collinear"):
        loads(along, "x.toml")


def test_bad_scenario_from_the_cli_exits_2(tmp_path, hybrid_text):
    bad = tmp_path / "bad.toml"
    bad.write_text(hybrid_text.replace("edges = [[1, 2], [2, 3], [3, 4], [4, 5]]", "edges = [[1, 2], [2, 3], [3, 1], [4, 5]]"))
    r = subprocess.run([sys.executable, "-m", "zswarm", "sim", str(bad)], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert f"{bad}: graph.edges[2]: edge 3-1 closes the cycle" in r.stderr


@pytest.mark.parametrize(
    "argv, code, needle",
    [
        (["--A", "5,8.57,12", "--xi", "0.08pi"], 0, "u       = [0.0000, 0.6455, 0.7638]"),
        (["--A", "5,8.57,12", "--xi", "0.9pi", "--gamma", "1.9251", "--delta", "0.3848"], 0, "δ       = 0.3848"),
        (["--A", "5,8.57,12", "--xi", "0.08pi", "--gamma", "2.1"], 2, "--gamma: Prop. 4.2 needs 0 < γ < 4Δ*/π² = 2.02642"),
        (["--A", "5,8.57", "--xi", "0.08pi"], 2, "--A: give 3 eigenvalues or 9 entries"),
        (["--A", "5,8.57,12", "--xi", "two"], 2, "--xi:"),
    ],
)
def test_design_hybrid_cli(argv, code, needle):
    r = subprocess.run([sys.executable, "-m", "zswarm", "design-hybrid", *argv], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == code, r.stderr
    assert needle in (r.stdout + r.stderr)
