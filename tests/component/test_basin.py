"""``zswarm basin``: the draws, the Monte-Carlo loop end to end, resume, bad input."""

import csv
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from tests.conftest import ROOT, TOPO, interrupt_when
from zswarm.scenario import ScenarioError, load, parse_override, with_rotations
from zswarm.studies import basin, basin_compare


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


def test_near_draws_turn_the_scenarios_own_start_by_eps():
    def angle(A, B):
        return math.acos(np.clip((np.trace(A.T @ B) - 1) / 2, -1, 1))

    law = load(TOPO / "thesis-5.6-velocity-free7.toml")
    for eps in (1e-2, 1e-6):
        ov = basin.draw_overrides(law, 1, 5, near=eps)
        assert [o.field for o in ov] == [f for n in range(7) for f in (f"agents[{n}].R", f"agents[{n}].estimate.Q")]
        for o in ov:
            n = int(o.field[7])
            own = law.agents[n].R_matrix if o.field.endswith("].R") else np.array(law.agents[n].estimate["Q"]).reshape(3, 3)
            R = np.array(o.value)
            # R = own·exp(ε[n]×): a rotation at geodesic distance ε from own (acos loses
            # half the digits near 0: |Δθ| ≲ √(2·1e-16) ≈ 1.5e-8).
            assert np.allclose(R.T @ R, np.eye(3), atol=1e-14)
            assert angle(own, R) == pytest.approx(eps, abs=2e-8)
    obs = load(TOPO / "thesis-4.5-hybrid5.toml")
    for o in basin.draw_overrides(obs, 1, 2, near=0.1):
        n = int(o.field[7])
        assert angle(np.array(obs.agents[n].estimate["R"]).reshape(3, 3), np.array(o.value)) == pytest.approx(0.1, abs=1e-12)
    # The axes differ from draw to draw and from agent to agent.
    a, b = basin.draw_overrides(law, 1, 5, near=0.1), basin.draw_overrides(law, 1, 6, near=0.1)
    assert a[0].value != b[0].value and a[0].value != a[2].value


def test_summary_counts_and_wilson_interval():
    rows = [{"draw": "0", "kind": "scenario", "status": "ok", "synchronized": "True", "settle_01_s": "50", "settle_s": "90", "final_max": "1e-3", "jumps": "8"}]
    rows += [
        {"draw": str(d), "kind": "uniform", "status": "ok", "synchronized": str(d % 5 != 0), "settle_01_s": str(10 + d), "settle_s": "" if d % 5 == 0 else str(20 + d), "final_max": "1e-3", "jumps": "1"}
        for d in range(1, 101)
    ]
    s = basin.summarize(rows, 0.01, 150.0, verdict="synchronized")
    assert s["drawn"] == 100 and s["start"] == "uniform" and s["synchronized"] == 80 and s["fraction"] == 0.8
    lo, hi = s["fraction_95ci"]
    assert lo == pytest.approx(0.7112, abs=1e-3) and hi == pytest.approx(0.8666, abs=1e-3)  # Wilson, z = 1.96
    assert s["settle_s"]["min"] == 21 and s["settle_s"]["max"] == 119
    assert s["scenario_start"]["settle_s"] == "90"


def test_the_interval_of_all_synchronized_is_printed_below_100():
    """10,000 of 10,000: the Wilson interval is 99.9616-100 %, which one decimal would print
    as "100.0-100.0 %"; the lower bound is rounded down, with the decimals it needs."""
    rows = [{"draw": str(d), "kind": "uniform", "status": "ok", "synchronized": "True", "settle_01_s": "1", "settle_s": "2", "final_max": "1e-3", "jumps": "0"} for d in range(1, 10001)]
    s = basin.summarize(rows, 0.01, 30.0, verdict="synchronized")
    assert s["fraction_95ci"][0] == pytest.approx(0.999616, abs=1e-6)
    assert "95 % CI 99.96-100.00 %" in basin.table("x", s)
    assert basin.ci_text([0.7112, 0.8666]) == "71.1-86.7 %"  # one decimal where it shows the interval


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
    assert s["drawn"] == 2 and s["scenario"] == "thesis-4.5-hybrid5" and s["synchronized"] == 2 and (out / "basin.png").exists()
    assert "2 of 2 uniform draws synchronized" in p.stdout
    # The same command resumes: nothing left to run; --no-plots removes the earlier figure.
    p2 = subprocess.run([*cmd, "--no-plots"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p2.returncode == 0 and "draw " not in p2.stderr.replace("draws", "")
    assert not (out / "basin.png").exists() and "basin.png" not in p2.stdout
    assert len(list(csv.DictReader(open(out / "basin.csv")))) == 3
    # Another horizon in the same folder is refused; a non-tree scheme is not covered.
    p3 = subprocess.run([*cmd[:5], "--duration", "10", "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert p3.returncode == 2 and "holds a different basin check (differs in: duration_s)" in p3.stderr
    p4 = subprocess.run([sys.executable, "-m", "zswarm", "basin", str(TOPO / "thesis-3.2-fixed8.toml"), "--out", str(tmp_path / "c")], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert p4.returncode == 2 and "declares no basin check" in p4.stderr
    assert math.isfinite(float(own["final_max"]))
    # Starts 0.2 rad from the scenario's own, then both folders side by side.
    near = tmp_path / "n"
    p5 = subprocess.run([*cmd[:5], "--draws", "2", "--duration", "20", "--near", "0.2", "--jobs", "1", "--out", str(near)], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p5.returncode == 0, p5.stderr
    assert "1 of 1 starts 0.2 rad from the scenario's synchronized" in p5.stdout
    assert [r["kind"] for r in sorted(csv.DictReader(open(near / "basin.csv")), key=lambda r: r["draw"])] == ["scenario", "near"]
    fig = tmp_path / "cmp" / "c.png"
    p6 = subprocess.run([sys.executable, "-m", "zswarm", "basin-compare", str(out), str(near), "--out", str(fig)], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p6.returncode == 0, p6.stderr
    rows = [ln for ln in p6.stdout.splitlines() if ln.startswith("| thesis-4.5-hybrid5 |")]
    assert len(rows) == 2 and "| uniform | 2 of 2 " in rows[0] and "| 0.2 rad from its own | 1 of 1 " in rows[1]
    assert fig.stat().st_size > 10_000
    p7 = subprocess.run([sys.executable, "-m", "zswarm", "basin-compare", str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert p7.returncode == 2 and "no basin_def.json (not a zswarm basin folder)" in p7.stderr


def test_paired_differences_only_between_folders_that_drew_the_same_starts():
    def entry(name, settle, draws=(1, "law")):
        rows = [{"draw": str(d), "kind": "uniform", "status": "ok", "synchronized": "True", "settle_s": str(x), "settle_01_s": "", "jumps": "0"} for d, x in settle.items()]
        return {"scenario": name, "_rows": rows, "_draws": (draws[0], None, draws[1])}

    a = entry("hybrid", {1: 90.0, 2: 95.0, 3: 100.0})
    b = entry("continuous", {1: 91.0, 2: 99.0, 3: 97.0, 4: 80.0})  # draw 4 has no partner
    (line,) = basin_compare.paired([a, b])
    # differences −1, −4, +3: median −1, mean −2/3, hybrid earlier in 2 of 3
    assert "paired on 3 identical starts: hybrid − continuous settle time: median -1.00 s, mean -0.67 s, from -4.00 to +3.00 s; hybrid earlier in 2 of 3" == line
    assert basin_compare.paired([a, entry("other seed", {1: 1.0}, draws=(2, "law"))]) == []
    assert basin_compare.paired([a, entry("vf", {1: 1.0}, draws=(1, "law+Q"))]) == []  # Q_i(0) drawn too: other starts
    assert basin_compare.paired([a, entry("hybrid", {1: 1.0})]) == []  # the same scheme twice: nothing to pair


def test_folders_pair_only_when_their_own_starts_match(tmp_path):
    """Draw 0 and every --near draw start from the scenario's own attitudes, so two scenarios
    pair only when those match: the §5.6 continuous and hybrid laws do, a moved start does not."""
    c7, h7 = TOPO / "thesis-5.6-continuous7.toml", TOPO / "thesis-5.6-hybrid7.toml"
    kc, kh = basin_compare.sc_kind({"topology": str(c7)}), basin_compare.sc_kind({"topology": str(h7)})
    assert kc == kh and kc.startswith("agents[].R@")  # what the draws randomise (the family's basin_start)
    moved = tmp_path / "moved.toml"
    text = c7.read_text()
    assert text.count('R = { angle = "-pi/2", axis = [0, 0, 1] }') >= 1
    moved.write_text(text.replace('R = { angle = "-pi/2", axis = [0, 0, 1] }', 'R = { angle = "-pi/3", axis = [0, 0, 1] }', 1))
    assert basin_compare.sc_kind({"topology": str(moved)}) not in (kc, "?")
    assert basin_compare.sc_kind({"topology": str(tmp_path / "gone.toml")}) == "?"


@pytest.mark.parametrize("engine", ["sim", "batched"])
def test_ctrl_c_keeps_the_rows_and_reaps_the_workers(tmp_path, engine):
    """Ctrl-C reaches the whole process group: the parent keeps every finished row, kills its
    workers (the draws under way rerun on resume) and exits 130, without a traceback.  On
    the batched engine a task is a chunk of draws (4 here, ~1 s each of CPU; 400 draws)."""
    out = tmp_path / "b"
    size = ["--draws", "40"] if engine == "sim" else ["--draws", "400", "--chunk", "4"]
    cmd = [sys.executable, "-m", "zswarm", "basin", str(TOPO / "thesis-4.5-hybrid5.toml"), *size, "--engine", engine, "--duration", "20", "--jobs", "2", "--out", str(out)]
    code, err = interrupt_when(cmd, lambda: len(basin.read_rows(out / "basin.csv")) >= 1)  # nothing of the group left after it
    assert code == 130 and "interrupted:" in err and "Traceback" not in err, err
    rows = basin.read_rows(out / "basin.csv")
    # Interrupted after the first rows and before the last: fewer rows than draws asked (not a tolerance).
    assert 1 <= len(rows) < (40 if engine == "sim" else 400) and all(r["status"] == "ok" for r in rows)  # no draw recorded as failed


@pytest.mark.parametrize("stem", ["thesis-5.6-velocity-free7", "thesis-5.6-hybrid7-noisy", "thesis-4.5-hybrid5"])
def test_a_draw_is_the_scenario_its_overrides_load(stem):
    """scenario.with_rotations (a draw's starts set on the loaded scenario, as the basin does) is
    the Scenario that loading the file with the draw's overrides gives: every field, its TOML,
    and the error of a matrix that is not a rotation."""
    path = str(TOPO / f"{stem}.toml")
    base = load(path)
    for d, near in ((1, None), (2, None), (3, 0.3)):
        ovs = basin.draw_overrides(base, 5, d, near)
        assert with_rotations(base, ovs) == load(path, ovs)
        assert with_rotations(base, ovs).text == load(path, ovs).text
    bad = [parse_override("agents[1].R=[[1,0,0],[0,1,0],[0,0,2]]")]
    errors = []
    for f in (lambda: with_rotations(base, bad), lambda: load(path, bad)):
        with pytest.raises(ScenarioError) as exc:
            f()
        errors.append(str(exc.value))
    assert errors[0] == errors[1] and "agents[1].R: is not a rotation matrix" in errors[0]
    other = [parse_override("algorithm.gains.k_R=2")]  # not a start: loaded in full
    assert with_rotations(base, other) == load(path, other)


def test_a_basin_under_command_delay_and_loss_is_sims_draw_by_draw(tmp_path):
    """``--set`` reaches every draw; with random links draw d runs with seed + d (its own losses:
    draws that lose the same commands would not be a Monte-Carlo over the network), and the
    batched engine's rows are sim's, column by column (every number as written), with a sensor
    delay as well (5 ms: idle ticks and catch-up steps, agent/batched.py _SensorLinks)."""
    got = {}
    for engine in ("batched", "sim"):
        out = tmp_path / engine
        # 14 s (30 s before): the rows of 30 s had their last jump before 14 s (draw 0's 8th;
        # draws 1 and 2 theirs by 8 s: jumps 8, 3, 3 at 14 s and at 30 s) and no draw settled
        # to 0.1 in either, so the 16 s after only moved final_max; the command links cross
        # their 512-number block (5.12 s at 100 Hz) and the 5 ms sensor delay idles and catches
        # up every few seconds well before 14 s.
        cmd = [sys.executable, "-m", "zswarm", "basin", str(TOPO / "thesis-5.6-hybrid7.toml"), "--draws", "3", "--duration", "14", "--threshold", "0.1", "--jobs", "2"]
        cmd += ["--set", "links.commands.delay_ms=2", "--set", "links.commands.drop=0.1", "--set", "links.sensors.delay_ms=5", "--engine", engine, "--out", str(out)]
        p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600, check=False)
        assert p.returncode == 0, p.stderr
        with open(out / "basin.csv", newline="") as f:
            got[engine] = {r["draw"]: {k: v for k, v in r.items() if k != "wall_s"} for r in csv.DictReader(f)}
        assert json.loads((out / "basin_def.json").read_text())["set"] == ["links.commands.delay_ms=2", "links.commands.drop=0.1", "links.sensors.delay_ms=5"]
    assert got["batched"] == got["sim"] and len(got["sim"]) == 3
    assert all(int(r["jumps"]) > 0 for r in got["sim"].values())  # the hybrid law's jumps fired in every draw (8, 3, 3)
    sc = load(TOPO / "thesis-5.6-hybrid7.toml", [parse_override("links.commands.drop=0.1")])
    assert [basin.run_seed(sc, d) for d in range(3)] == [sc.seed, sc.seed + 1, sc.seed + 2]
    assert basin.run_seed(load(TOPO / "thesis-5.6-hybrid7.toml", [parse_override("links.commands.delay_ms=2")]), 2) == sc.seed  # no random links: one seed
    # A resume with another --set is another basin check: refused, nothing run.
    again = [*cmd[: cmd.index("--set")], "--set", "links.commands.delay_ms=5", "--out", str(tmp_path / "sim")]
    p = subprocess.run(again, cwd=ROOT, capture_output=True, text=True, timeout=60, check=False)
    assert p.returncode == 2 and "differs in: set" in p.stderr, p.stderr


def test_a_tree_basin_under_sensor_loss_is_sims_draw_by_draw(tmp_path):
    """The §4.5 hybrid observers under lossy, jittery sensor links: each draw's estimates held
    on its own 100 Hz grid from its agents' latest first estimate (tree_metrics per draw:
    agent/batched_stamps.py TreeErrors), so the batched engine's basin rows are sim's, column
    by column; ``auto`` runs it on sim (the batched engine is no faster there) and says so.
    6 s: draw 2 settles at 5.33 s (measured), so a synchronized verdict and its settle times
    are compared too.  ``auto`` runs the first two draws only: it is sim's code, and its rows
    are sim's for those (a third draw on sim again checked nothing more)."""
    got = {}
    for engine in ("batched", "sim", "auto"):
        out = tmp_path / engine
        draws = "2" if engine == "auto" else "3"
        cmd = [sys.executable, "-m", "zswarm", "basin", str(TOPO / "thesis-4.5-hybrid5.toml"), "--draws", draws, "--duration", "6", "--threshold", "0.01", "--jobs", "2"]
        cmd += ["--set", "links.sensors.drop=0.2", "--set", "links.sensors.jitter_ms=3", "--engine", engine, "--out", str(out)]
        p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600, check=False)
        assert p.returncode == 0, p.stderr
        with open(out / "basin.csv", newline="") as f:
            got[engine] = {r["draw"]: {k: v for k, v in r.items() if k != "wall_s"} for r in csv.DictReader(f)}
        if engine == "auto":
            assert "on sim (not batched: sensor links with jitter, loss or cuts on a prescribed truth" in p.stderr, p.stderr
    assert got["batched"] == got["sim"] and len(got["sim"]) == 3
    assert got["auto"] == {d: got["sim"][d] for d in ("0", "1")}
    assert all(r["status"] == "ok" for r in got["sim"].values())
    assert any(r["synchronized"] == "True" and r["settle_s"] for r in got["sim"].values())  # a settled draw compared
