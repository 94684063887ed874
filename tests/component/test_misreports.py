"""Summaries and files that say what they cannot know (issue 61, item 7), on ``zswarm sim``
folders: a summary remade without summary.json gives the engine and duration the folder ran
with (or "unknown"), a full disk leaves no truncated recording.mcap, and a run far beyond
reason is refused with one line naming its cost."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

from tests.conftest import ROOT, TOPO

T33 = TOPO / "thesis-3.3-moving5.toml"  # five agents, scenario.duration = 30 s


def _cli(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "zswarm", *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def sim_dir(tmp_path_factory) -> Path:
    """A sim of 6 s (not the scenario's 30) with seed 7 (not its 1): its recording is three
    chunks long (measured: 1.08 MB, 1.07 MB, 42 kB), so that the first one can be lost."""
    out = tmp_path_factory.mktemp("sim") / "run"
    p = _cli("sim", str(T33), "--duration", "6", "--seed", "7", "--no-plots", "--quiet", "--out", str(out))
    assert p.returncode == 0, p.stderr
    return out


def _remade(dst: Path) -> tuple[subprocess.CompletedProcess[str], dict]:
    """``zswarm report`` on a copy of a folder whose summary.json was lost."""
    (dst / "summary.json").unlink()
    p = _cli("report", str(dst))
    return p, json.loads((dst / "summary.json").read_text())


def _lose_first_chunk(path: Path) -> None:
    """Damage the end of the recording's first chunk (as a bad sector would): its messages,
    ctl/start among them, are lost; the rest is read on past it."""
    with open(path, "rb") as f:
        start, length = min((c.chunk_start_offset, c.chunk_length) for c in make_reader(f).get_summary().chunk_indexes)
    with open(path, "r+b") as f:
        f.seek(start + length - 300)
        f.write(b"\xde\xad" * 100)


def test_a_remade_summary_of_a_sim_folder_says_sim_and_its_duration(sim_dir, tmp_path):
    d = shutil.copytree(sim_dir, tmp_path / "d")
    p, s = _remade(d)
    assert p.returncode == 0, p.stderr
    assert (s["engine"], s["duration_s"], s["seed"], s["time_scale"]) == ("sim", 6.0, 7, 0.0), s
    assert p.stdout.splitlines()[0].startswith("thesis-3.3-moving5 (bearing_pose_moving, engine=sim, 6 s, seed 7)"), p.stdout


def test_a_remade_summary_of_a_damaged_sim_recording_keeps_the_runs_duration(sim_dir, tmp_path):
    """The start message lost with the first chunk: the duration used to be the scenario's 30 s
    (and every estimate after 6 s "missing"); the recording's metadata, written before any
    chunk, still says what the run was."""
    d = shutil.copytree(sim_dir, tmp_path / "d")
    _lose_first_chunk(d / "recording.mcap")
    p, s = _remade(d)
    assert p.returncode == 1, p.stderr  # a damaged recording: not completed
    assert (s["engine"], s["duration_s"], s["seed"]) == ("sim", 6.0, 7), s
    assert not s["recording"]["cut_short"], s["recording"]  # it ends at 6 s, the run's end


def test_a_remade_summary_says_unknown_where_the_folder_does_not_tell(sim_dir, tmp_path):
    """Neither the start message (its chunk lost), nor zswarm's metadata (a foreign name on it),
    nor a launcher's processes.json or world log: the engine and duration are unknown, and the
    summary says so instead of "run" and the scenario's 30 s."""
    d = shutil.copytree(sim_dir, tmp_path / "d")
    _lose_first_chunk(d / "recording.mcap")
    data = bytearray((d / "recording.mcap").read_bytes())
    at = data.index(b"zswarm", 0, 4096)  # the metadata record's name, before the first chunk
    data[at : at + 6] = b"xswarm"
    (d / "recording.mcap").write_bytes(bytes(data))
    p, s = _remade(d)
    assert p.returncode == 1, p.stderr
    assert s["engine"] == "unknown" and s["duration_s"] is None and s["seed"] is None, {k: s[k] for k in ("engine", "duration_s", "seed")}
    assert s["remade"]["duration_s"].startswith("unknown"), s["remade"]
    assert "engine=unknown, duration unknown, seed unknown" in p.stdout.splitlines()[0], p.stdout


@pytest.fixture
def full_disk(tmp_path):
    """A 1 MiB tmpfs (as tests/integration/test_processes.py's small_disk): room for the
    scenario, not for the 6 s sim's 2.2 MB recording; unmounted at the end whatever happens."""
    d = tmp_path / "full"
    d.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(d)], check=True)
    try:
        yield d
    finally:
        subprocess.run(["umount", "-l", str(d)], check=False)


def test_a_sim_on_a_full_disk_leaves_no_truncated_recording(full_disk):
    """It left recording.mcap cut at the disk's end (1 044 480 bytes, not one message readable)
    under its final name, where a report or a viewer takes it for the run's recording."""
    out = full_disk / "s"
    p = _cli("sim", str(T33), "--duration", "6", "--no-plots", "--quiet", "--out", str(out))
    assert p.returncode == 1, p.stderr
    said = [x for x in p.stderr.splitlines() if x.startswith("zswarm sim: ")]
    assert len(said) == 1 and f"{out / 'recording.mcap'}: cannot write the recording: No space left on device" in said[0] and "Traceback" not in p.stderr, p.stderr
    left = {f.name: f.stat().st_size for f in out.iterdir()}
    assert "recording.mcap" not in left and not any(n.endswith(".part") for n in left), left  # the partial file removed: the disk has its room back


T32 = TOPO / "thesis-3.2-fixed8.toml"  # eight agents, no loader note on stderr
LONG = ("--set", "world.step=1e-6", "--duration", "1e5")  # 1e11 world steps (issue 61)


def _refused(*args: str) -> tuple[int, str]:
    """Exit code and stderr of a command that must end at once; one that runs on is killed after
    60 s (loading the scenario takes 1-2 s here; 60 leaves a loaded machine 30 times that)."""
    p = subprocess.Popen([sys.executable, "-m", "zswarm", *args], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        _out, err = p.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        p.kill()
        _out, err = p.communicate()
        return -1, f"still running after 60 s (killed); stderr: {err[-2000:]}"
    return p.returncode, err


@pytest.mark.parametrize("cmd", ["sim", "run"])
def test_a_run_far_beyond_reason_is_refused_with_its_cost(tmp_path, cmd):
    """It started silently and ran until killed.  Now one line naming the estimate, exit 2, and
    nothing started or made (no results folder)."""
    out = tmp_path / "out"
    code, err = _refused(cmd, str(T32), *LONG, "--quiet", "--out", str(out))
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, (code, err)
    # 1e5 s / 1e-6 s steps for 8 agents at 0.2 µs an agent-step (zswarm/engines/cost.py) is 44.4 h,
    # and 8e7 ticks at 0.15 ms 3.3 h more: 47.8 h.
    want = f"error: {T32}: --duration 100000 at world.step = 1e-06 s is 1e+11 world steps for 8 agents and 8e+07 agent ticks: at least 47.8 h of CPU"
    assert lines[0].startswith(want) and "--allow-long" in lines[0], lines[0]
    assert not out.exists()


def test_allow_long_runs_it_anyway(tmp_path):
    """With --allow-long the same sim starts (its results folder made), and stops on SIGTERM."""
    import signal
    import time

    out = tmp_path / "out"
    p = subprocess.Popen([sys.executable, "-m", "zswarm", "sim", str(T32), *LONG, "--allow-long", "--quiet", "--no-plots", "--out", str(out)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 60  # as _refused: 30 times the start here
        while not (out / "scenario.toml").exists() and p.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        running = p.poll() is None and (out / "scenario.toml").exists()
        p.send_signal(signal.SIGTERM)
        _o, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert running and p.returncode == 143, (p.returncode, err[-2000:])
