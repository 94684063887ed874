"""``zswarm basin``: the draws, the Monte-Carlo loop end to end, resume, bad input."""

import csv
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from tests.conftest import ROOT, TOPO
from zswarm import basin
from zswarm.scenario import load


def test_uniform_rotations_are_haar():
    rng = np.random.default_rng(5)
    Rs = np.array([basin.uniform_rotation(rng) for _ in range(20000)])
    assert np.allclose(np.einsum("nji,njk->nik", Rs, Rs), np.eye(3), atol=1e-12) and np.all(np.linalg.det(Rs) > 0)
    # Haar measure: E[R] = 0 (each entry's std is 1/√3, so the mean of 20000 is within
    # 5σ = 5/√(3·20000) = 0.02), and the angle θ has density (1 − cos θ)/π: E[cos θ] = −1/2,
    # i.e. E[tr R] = 0 (std of tr R is 1: 5σ = 0.035).
    assert np.max(np.abs(Rs.mean(axis=0))) < 0.02
    assert abs(np.trace(Rs, axis1=1, axis2=2).mean()) < 0.035


def test_draws_are_reproducible_and_cover_the_right_attitudes():
    law = load(TOPO / "thesis-5.6-velocity-free7.toml")
    a = basin.draw_overrides(law, 1, 3)
    assert [o.field for o in a] == [f for n in range(7) for f in (f"agents[{n}].R", f"agents[{n}].estimate.Q")]
    assert [o.value for o in a] == [o.value for o in basin.draw_overrides(law, 1, 3)]
    assert [o.value for o in a] != [o.value for o in basin.draw_overrides(law, 1, 4)]
    assert basin.draw_overrides(law, 1, 0) == []  # draw 0: the scenario's own start
    obs = load(TOPO / "thesis-4.5-hybrid5.toml")
    assert [o.field for o in basin.draw_overrides(obs, 1, 1)] == [f"agents[{n}].estimate.R" for n in range(5)]
    # Every drawn attitude loads as a rotation (full precision survives the TOML round trip).
    sc = load(TOPO / "thesis-5.6-velocity-free7.toml", a)
    R = np.array(sc.agent(2).R).reshape(3, 3)
    assert np.allclose(R, np.array(a[2].value)) and abs(np.linalg.det(R) - 1) < 1e-12


def test_summary_counts_and_wilson_interval():
    rows = [{"draw": "0", "kind": "scenario", "status": "ok", "synchronized": "True", "settle_01_s": "50", "settle_s": "90", "final_max": "1e-3", "jumps": "8"}]
    rows += [
        {"draw": str(d), "kind": "uniform", "status": "ok", "synchronized": str(d % 5 != 0), "settle_01_s": str(10 + d), "settle_s": "" if d % 5 == 0 else str(20 + d), "final_max": "1e-3", "jumps": "1"}
        for d in range(1, 101)
    ]
    s = basin.summarize(rows, 0.01, 150.0)
    assert s["uniform_draws"] == 100 and s["synchronized"] == 80 and s["fraction"] == 0.8
    lo, hi = s["fraction_95ci"]
    assert lo == pytest.approx(0.7112, abs=1e-3) and hi == pytest.approx(0.8666, abs=1e-3)  # Wilson, z = 1.96
    assert s["settle_s"]["min"] == 21 and s["settle_s"]["max"] == 119
    assert s["scenario_start"]["settle_s"] == "90"


def test_basin_end_to_end_resume_and_bad_input(tmp_path):
    out = tmp_path / "b"
    cmd = [sys.executable, "-m", "zswarm", "basin", str(TOPO / "thesis-4.5-hybrid5.toml"), "--draws", "3", "--duration", "20", "--jobs", "2", "--out", str(out)]
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    rows = list(csv.DictReader(open(out / "basin.csv")))
    assert sorted(int(r["draw"]) for r in rows) == [0, 1, 2] and all(r["status"] == "ok" for r in rows)
    own = next(r for r in rows if r["draw"] == "0")
    # Draw 0 is §4.5's own start: every ξ_k jumps once (4 edges), then it settles (≈15 s, READING-NOTES).
    assert own["jumps"] == "4" and own["synchronized"] == "True" and 10 < float(own["settle_s"]) < 20
    # The hybrid observer is global: random R̂_i(0) synchronize too (Theorem 4.2).
    assert all(r["synchronized"] == "True" for r in rows)
    s = json.loads((out / "basin.json").read_text())
    assert s["uniform_draws"] == 2 and s["synchronized"] == 2 and (out / "basin.png").exists()
    assert "2 of 2 uniform draws synchronized" in p.stdout
    # The same command resumes: nothing left to run.
    p2 = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p2.returncode == 0 and "draw " not in p2.stderr.replace("draws", "")
    assert len(list(csv.DictReader(open(out / "basin.csv")))) == 3
    # Another horizon in the same folder is refused; a non-tree scheme is not covered.
    p3 = subprocess.run([*cmd[:5], "--duration", "10", "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert p3.returncode == 2 and "holds a different basin check (differs in: duration_s)" in p3.stderr
    p4 = subprocess.run([sys.executable, "-m", "zswarm", "basin", str(TOPO / "thesis-3.2-fixed8.toml"), "--out", str(tmp_path / "c")], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert p4.returncode == 2 and "covers the tree schemes" in p4.stderr
    assert math.isfinite(float(own["final_max"]))
