"""``zswarm info`` and ``zswarm runs`` (zswarm/results/catalog.py) on what ``zswarm sim`` writes:
the counts and rates they print are the recording's, read here independently."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter

import pytest
from mcap.reader import make_reader

from tests.conftest import ROOT, TOPO
from zswarm.recording.mcap_io import read

FIXED8 = TOPO / "thesis-3.2-fixed8.toml"


def zswarm(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "zswarm", *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def sim_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("info") / "sim"
    p = zswarm("sim", str(FIXED8), "--duration", "2", "--out", str(out))
    assert p.returncode == 0, p.stderr
    return out


def test_info_of_a_sim_results_folder(sim_dir):
    p = zswarm("info", str(sim_dir), "--json")
    assert p.returncode == 0, p.stderr
    d = json.loads(p.stdout)
    summary = json.loads((sim_dir / "summary.json").read_text())
    assert d["kind"] == "results" and d["summary"] == summary
    rec = d["recording"]
    # Every run stream's count is what the recording holds (read by mcap_io, which skips the viewer channels).
    counts = Counter(stream for stream, _m, _t in read(sim_dir / "recording.mcap"))
    assert counts and all(rec["channels"][k]["count"] == n for k, n in counts.items()), (counts, rec["channels"])
    assert rec["messages"] >= sum(counts.values()) and rec["readable_to_end"]
    # sim's log times are world time in ns: the sensors' rate is the scenario's, exactly (to the ns
    # rounding of the stamps, ~1e-9 relative over 2 s); truth once per sensor sample too.
    assert rec["channels"]["sense/3"]["rate_hz"] == pytest.approx(200.0, rel=1e-6)
    assert rec["channels"]["est/3"]["rate_hz"] == pytest.approx(100.0, rel=1e-6)
    assert rec["start_utc"] is None  # world time, not a wall clock
    text = zswarm("info", str(sim_dir))
    assert text.returncode == 0
    lines = text.stdout.splitlines()
    assert lines[0] == f"results:    {sim_dir}"
    assert "scenario:   thesis-3.2-fixed8 (bearing_pose_fixed, family leader_follower)" in lines
    assert "status:     completed" in lines
    assert not any(line.startswith("timing:") for line in lines)  # sim keeps no real time: nothing to say
    row = next(line.split() for line in lines if line.strip().startswith("sense/3 "))
    assert row[1:3] == [str(counts["sense/3"]), "200.00"]
    assert any(line.split()[:1] == ["world->3"] for line in lines)  # the links' counters


def test_info_of_a_recording_alone_and_of_a_damaged_one(sim_dir, tmp_path):
    whole = json.loads(zswarm("info", str(sim_dir / "recording.mcap"), "--json").stdout)
    assert whole["kind"] == "recording" and whole["recording"]["metadata"]["scenario"] == "thesis-3.2-fixed8"
    data = (sim_dir / "recording.mcap").read_bytes()
    with open(sim_dir / "recording.mcap", "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    assert len(chunks) >= 2
    end_of_first = chunks[0].chunk_start_offset + chunks[0].chunk_length
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: end_of_first + 100])  # a recorder killed while writing its second chunk
    p = zswarm("info", str(cut), "--json")
    assert p.returncode == 0, p.stderr
    part = json.loads(p.stdout)["recording"]
    assert not part["readable_to_end"]
    assert 0 < part["messages"] < whole["recording"]["messages"]
    assert "DAMAGED or cut short" in zswarm("info", str(cut)).stdout


@pytest.mark.parametrize("what", ["README.md", "no-such-folder", "topologies"])
def test_info_of_something_else_is_one_line_and_exit_2(what):
    p = zswarm("info", str(ROOT / what))
    assert p.returncode == 2, p
    assert p.stderr.count("\n") == 1 and p.stderr.startswith("error: ") and "Traceback" not in p.stderr


def test_runs_lists_results_folders_with_their_status(sim_dir, tmp_path):
    root = sim_dir.parent
    (root / "empty").mkdir()
    half = root / "half"
    half.mkdir()
    (half / "scenario.toml").write_text(FIXED8.read_text())  # a run killed before its report
    broken = root / "broken"
    broken.mkdir()
    (broken / "summary.json").write_text("{")
    p = zswarm("runs", str(root), "--json")
    assert p.returncode == 0, p.stderr
    rows = {r["name"]: r for r in json.loads(p.stdout)}
    assert set(rows) == {"sim", "half", "broken"}
    assert rows["sim"]["status"] == "completed" and rows["sim"]["engine"] == "sim" and rows["sim"]["duration_s"] == 2.0
    assert rows["half"]["status"].startswith("no summary") and rows["half"]["scenario"] == "thesis-3.2-fixed8"
    assert rows["broken"]["status"] == "summary.json unreadable"
    text = zswarm("runs", str(root)).stdout.splitlines()
    assert len(text) == 4 and text[0].startswith("written (UTC)")
    assert zswarm("runs", str(tmp_path / "none")).returncode == 2
