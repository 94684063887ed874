"""``zswarm view RUN_DIR --save FILE.rrd`` (issue 32): every shipped scenario's results become a
Rerun recording whose entities are what the run has, read back with the SDK's own ``rerun rrd
print`` (the file as the viewer loads it).

Each scenario runs 1.5 s on ``sim``: past the first estimates, commands, link statistics (1 Hz)
and the hybrid laws' first jumps at t = 0.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests import browser
from tests.conftest import ROOT, TOPO
from zswarm.engines.sim import simulate
from zswarm.families import contract as family
from zswarm.recording import rerun_view
from zswarm.scenario import load

DURATION = 1.5
SCENARIOS = sorted(p.stem for p in TOPO.glob("*.toml"))
ENV = os.environ | {"TELEMETRY_ENABLED": "false"}


def entities(rrd: Path) -> set[str]:
    """The entity paths of an .rrd file, as the SDK's ``rerun rrd print`` lists its chunks."""
    r = subprocess.run([sys.executable, "-m", "rerun", "rrd", "print", str(rrd)], capture_output=True, text=True, env=ENV, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    return set(re.findall(r"\) - (/\S+) - data columns", r.stdout))


@pytest.mark.parametrize("name", SCENARIOS)
def test_every_shipped_scenario_views(name, tmp_path):
    sc = load(TOPO / f"{name}.toml")
    run = tmp_path / "run"
    run.mkdir()
    simulate(sc, run, DURATION, sc.seed)
    shutil.copy(TOPO / f"{name}.toml", run / "scenario.toml")  # as zswarm sim leaves it: the view reads the graph there
    v = rerun_view.view(run, tmp_path / "x.rrd")
    assert v.count > 0 and v.malformed == 0
    got = entities(tmp_path / "x.rrd")
    want = {f"/world/agent_{i}" for i in sc.ids} | {f"/world/agent_{i}/body" for i in sc.ids} | {"/world/edges"}
    if sc.plant != "prescribed":  # every agent's command, each component (τ_i: x, y, z and the norm)
        assert {g.rsplit("/", 1)[1] for g in got if g.startswith("/commands/")} == {str(i) for i in sc.ids}, sorted(got)
    fam = family.of(sc).name
    if fam == "sync":
        want |= {f"/sync/edge/attitude/{h}_{t}" for h, t in sc.oriented} | {f"/sync/omega/{i}" for i in sc.ids}
    else:
        estimating = [i for i in sc.ids if sc.agent(i).role != "leader"]
        want |= {f"/world/agent_{i}_est" for i in estimating} | {f"/errors/attitude/{i}" for i in estimating}
        want |= {f"/errors/edge/attitude/{h}_{t}" for h, t in sc.oriented}
    if getattr(sc.params, "Xi", ()):
        want |= {"/hybrid/jumps"} | {f"/hybrid/xi/{k}" for k in range(1, len(sc.oriented) + 1)}
    assert not want - got, sorted(want - got)
    assert any(g.startswith("/links/delivered/") for g in got)


def test_fault_windows_and_the_cli(tmp_path):
    """A cut link's window (start, end, 0/1 series) and the command line: --save writes the file
    and exits 0; a folder without a recording exits 2 with the reason and writes nothing."""
    run = tmp_path / "run"
    r = subprocess.run(
        [sys.executable, "-m", "zswarm", "sim", str(TOPO / "thesis-3.2-fixed8.toml"), "--duration", "2", "--out", str(run), "--fault", "cut,link=1->3,at=0.5,duration=1", "--no-plots", "--quiet"],
        capture_output=True, text=True, cwd=ROOT, timeout=300,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    r = subprocess.run(
        [sys.executable, "-m", "zswarm", "view", str(run), "--save", str(tmp_path / "f.rrd")], capture_output=True, text=True, env=ENV, timeout=300
    )
    assert r.returncode == 0, r.stderr
    assert "messages" in r.stdout and "malformed" not in r.stdout
    got = entities(tmp_path / "f.rrd")
    assert {"/faults", "/faults/0/active", "/links/dropped/1_to_3"} <= got, sorted(got)
    empty = tmp_path / "empty"
    empty.mkdir()
    r = subprocess.run(
        [sys.executable, "-m", "zswarm", "view", str(empty), "--save", str(tmp_path / "g.rrd")], capture_output=True, text=True, env=ENV, timeout=120
    )
    assert r.returncode == 2 and "no recording there" in r.stderr, (r.stdout, r.stderr)
    assert not (tmp_path / "g.rrd").exists() and not list(empty.iterdir())
    headless = {k: v for k, v in ENV.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run([sys.executable, "-m", "zswarm", "view", str(run)], capture_output=True, text=True, env=headless, timeout=120)
    assert r.returncode == 2 and "no display" in r.stderr and "--web" in r.stderr, (r.stdout, r.stderr)


def test_sim_streams_live_to_a_rerun_viewer(tmp_path):
    """``zswarm sim --rerun URL``: the run reaches a listening Rerun program as it is simulated
    (here ``rerun --save``, which writes what it receives), with the entities of the view."""
    sc = load(TOPO / "thesis-5.6-hybrid7.toml")
    with browser.rerun_receiver(tmp_path / "live.rrd") as url:
        r = subprocess.run(
            [
                sys.executable,
                "-m",
                "zswarm",
                "sim",
                str(TOPO / "thesis-5.6-hybrid7.toml"),
                "--duration",
                "2",
                "--out",
                str(tmp_path / "run"),
                "--no-plots",
                "--quiet",
                "--rerun",
                url,
            ],
            capture_output=True,
            text=True,
            cwd=ROOT,
            env=ENV,
            timeout=300,
        )
        assert r.returncode == 0, r.stderr
    got = entities(tmp_path / "live.rrd")
    want = {f"/world/agent_{i}" for i in sc.ids} | {f"/sync/edge/attitude/{h}_{t}" for h, t in sc.oriented} | {"/hybrid/jumps", "/world/edges"}
    assert not want - got, sorted(want - got)
