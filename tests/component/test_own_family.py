"""An experiment family of one's own, registered by entry point, used by every command with no
file of zswarm edited (issue 47): docs/examples/spin_family (the tutorial's "Your own family")
copied into tmp_path with the dist-info pip would write for it, put on PYTHONPATH, and then
``zswarm generate``, ``sim``, ``sweep`` (batched and sim), ``basin`` (batched and sim) and its
own command run on it.

The engines must agree on the family's own numbers: the batched engine and sim differ by
round-off (≈ 1e-12 relative here, tests/component/test_batched.py), which the CSV cells'
6 significant digits (%.6g) can turn into one unit of the 6th digit: rel 1e-5."""

import csv
import json
import os
import shutil
import subprocess
import sys
import tomllib

import pytest

from tests.conftest import ROOT

EXAMPLE = ROOT / "docs" / "examples" / "spin_family"
CELL_REL = 1e-5  # two engines' values printed with %.6g (see the module docstring)
# The numbers the tutorial quotes (section 9), printed with 3 significant digits: half a unit of
# the third digit is ≤ 1e-2 relative of the smallest (0.541).
QUOTED_REL = 1e-2


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The example package installed as pip installs it: the package and a dist-info whose
    entry_points.txt registers its family and its algorithm (from its pyproject.toml)."""
    d = tmp_path_factory.mktemp("site")
    shutil.copytree(EXAMPLE / "spin_family", d / "spin_family")
    project = tomllib.loads((EXAMPLE / "pyproject.toml").read_text())["project"]
    info = d / f"spin_family-{project['version']}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {project['name']}\nVersion: {project['version']}\n")
    eps = "".join(f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in entries.items()) + "\n" for group, entries in project["entry-points"].items())
    (info / "entry_points.txt").write_text(eps)
    return d


def zswarm(site, *args, timeout=300):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), str(ROOT)]))
    return subprocess.run([sys.executable, "-m", "zswarm", *map(str, args)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout)


def rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def close(a, b):
    return a == b or (a != "" and b != "" and float(a) == pytest.approx(float(b), rel=CELL_REL))


def test_a_family_of_ones_own_in_every_command(site, tmp_path):
    # generate: its recipe is listed and draws a scenario of its algorithm
    p = zswarm(site, "generate", "--list")
    assert p.returncode == 0 and "spin-hybrid" in p.stdout and "attitude-sync-hybrid" in p.stdout, p.stderr
    topo = tmp_path / "spin4.toml"
    p = zswarm(site, "generate", "spin-hybrid", "-n", 4, "--seed", 3, "--duration", 3, "-o", topo)
    assert p.returncode == 0, p.stderr
    assert 'name = "spin_sync"' in topo.read_text()

    # sim: its report section, its table line, its figure (besides the sync family's it builds on)
    run = tmp_path / "run"
    p = zswarm(site, "sim", topo, "--out", run)
    assert p.returncode == 0, p.stderr
    s = json.loads((run / "summary.json").read_text())
    assert s["report_family"] == "spin" and "synchronization" in s
    assert s["spin"]["initial"] == 0.0  # the bodies start at rest (the recipe's ω(0) = 0), then turn
    assert s["spin"]["final"] == pytest.approx(0.907, rel=QUOTED_REL)  # the tutorial's number
    assert "spin: mean_i ‖ω_i‖" in p.stdout
    assert (run / "plots" / "spin.png").stat().st_size > 5_000 and (run / "plots" / "relative_attitude_error.png").exists()

    # its own command
    p = zswarm(site, "spin-info", run)
    assert p.returncode == 0 and json.loads(p.stdout) == s["spin"], p.stderr
    assert "spin-info" in zswarm(site, "--help").stdout

    # sweep: its column, filled by the batched engine's measure and from sim's files alike, and its figure
    got = {}
    for engine in ("batched", "sim"):
        out = tmp_path / f"sweep-{engine}"
        p = zswarm(site, "sweep", topo, "--vary", "algorithm.gains.k_omega=0.1,0.5", "--engine", engine, "--jobs", 1, "--out", out)
        assert p.returncode == 0, p.stderr
        assert ("2 batched in" in p.stderr) == (engine == "batched"), p.stderr  # the family's batched measure ran
        got[engine] = rows(out / "sweep.csv")
        assert list(got[engine][0])[-2:] == ["spin_final", "wall_s"]
        assert (out / "sweep_algorithm.gains.k_omega.png").stat().st_size > 10_000
    for b, sm in zip(got["batched"], got["sim"], strict=True):
        assert b["run_id"] == sm["run_id"] and b["status"] == sm["status"] == "ok"
        for col in ("spin_final", "final_attitude_error", "jumps", "cmd_sent", "edge_sent"):
            assert close(b[col], sm[col]), (col, b[col], sm[col])
    assert [float(r["spin_final"]) for r in got["batched"]] == pytest.approx([0.907, 0.541], rel=QUOTED_REL)  # the tutorial's: the gain made a difference
    # sim's row is the summary's final: the family's from_run read it
    assert float(got["sim"][0]["spin_final"]) == pytest.approx(json.loads((tmp_path / "sweep-sim" / "runs" / "p000-r0" / "summary.json").read_text())["spin"]["final"], rel=CELL_REL)

    # basin: its verdict and measure, the same rows on the batched engine as on sim
    basins = {}
    for engine in ("batched", "sim"):
        out = tmp_path / f"basin-{engine}"
        p = zswarm(site, "basin", topo, "--draws", 3, "--duration", 3, "--threshold", 1.5, "--engine", engine, "--jobs", 1, "--out", out)
        assert p.returncode == 0, p.stderr
        assert ("on the batched engine" in p.stderr) == (engine == "batched"), p.stderr
        assert "1 of 2 uniform draws still (mean_i ‖ω_i‖ < 1.5 from some t ≤ 3 s on)" in p.stdout  # the tutorial's
        with open(out / "basin.csv", newline="") as f:
            assert next(csv.reader(f))[:3] == ["draw", "kind", "still"]
        basins[engine] = rows(out / "basin.csv")
        j = json.loads((out / "basin.json").read_text())
        assert j["verdict"] == "still" and j["measure"] == "mean_i ‖ω_i‖" and "still" in j
    for b, sm in zip(basins["batched"], basins["sim"], strict=True):
        for col in ("draw", "still", "settle_s", "left_s", "jumps"):
            assert b[col] == sm[col], (col, b, sm)
        for col in ("final_max", "initial_max"):
            assert close(b[col], sm[col]), (col, b[col], sm[col])
