"""A damaged or cut recording (issue 50): read up to the damage and past it where MCAP allows,
every loss one line ``file: byte N: what``, ``zswarm report`` and ``zswarm view`` exit 1 (2 for a
file that is not MCAP) and never print a traceback.

The finding (audit against 8aadf64): a ``recording.mcap`` whose chunk end a bad sector changed
made ``zswarm report`` and ``zswarm view --save`` end in ``zstandard.backend_c.ZstdError:
decompression error: Data corruption detected`` and a traceback.
"""

from __future__ import annotations

import json
import random
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

from tests.conftest import ROOT, TOPO
from zswarm.recording import mcap_io
from zswarm.recording.mcap_read import NotMcap

FIXED8 = TOPO / "thesis-3.2-fixed8.toml"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """A real sim's results folder (its recording several 4 MiB chunks long)."""
    out = tmp_path_factory.mktemp("rec") / "run"
    p = subprocess.run([sys.executable, "-m", "zswarm", "sim", str(FIXED8), "--duration", "8", "--no-plots", "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    return out


def _chunks(path: Path) -> list[tuple[int, int]]:
    with open(path, "rb") as f:
        s = make_reader(f).get_summary()
    return sorted((c.chunk_start_offset, c.chunk_length) for c in s.chunk_indexes)


def _all(path: Path) -> tuple[list[tuple[str, int]], list]:
    lost: list = []
    got = [(stream, t) for stream, _m, t in mcap_io.read(path, lost)]
    return got, lost


def _copy(run_dir: Path, tmp_path: Path, name: str) -> Path:
    d = tmp_path / name
    shutil.copytree(run_dir, d)
    return d


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "zswarm", *args], cwd=ROOT, capture_output=True, text=True, timeout=300)


def test_a_damaged_chunk_costs_that_chunk_only(run_dir, tmp_path):
    full, lost0 = _all(run_dir / "recording.mcap")
    assert lost0 == []
    chunks = _chunks(run_dir / "recording.mcap")
    assert len(chunks) >= 3, chunks  # a middle chunk to damage
    d = _copy(run_dir, tmp_path, "bad")
    start, length = chunks[1]
    with open(d / "recording.mcap", "r+b") as f:  # the chunk's compressed end, as a bad sector would
        f.seek(start + length - 300)
        f.write(b"\xde\xad" * 100)
    got, lost = _all(d / "recording.mcap")
    texts = [x.text() for x in lost]
    assert texts[0].startswith(f"{d / 'recording.mcap'}: byte {start}: damaged chunk (") and "are lost; read on after it" in texts[0], texts
    # What was read is the whole file's messages less one contiguous run of them (that chunk's).
    assert 0 < len(got) < len(full)
    k = next(i for i, (a, b) in enumerate(zip(got, full, strict=False)) if a != b)
    assert got[:k] == full[:k] and got[k:] == full[len(full) - (len(got) - k) :]
    assert texts[-1].endswith("messages lost (the count in its statistics)")

    p = _cli("report", str(d))
    assert p.returncode == 1, p.stderr
    assert "Traceback" not in p.stderr + p.stdout
    assert texts[0] in p.stderr.splitlines()
    s = json.loads((d / "summary.json").read_text())
    assert not s["completed"] and s["recording"]["damaged"] == texts
    assert any(q.startswith("the recording is damaged: ") for q in s["problems"])
    assert any(q.startswith("the recording has 1 hole") for q in s["problems"]), s["problems"]  # the chunk's span of truth

    v = _cli("view", str(d), "--save", str(tmp_path / "bad.rrd"))
    assert v.returncode == 1, v.stderr
    assert "Traceback" not in v.stderr and texts[0] in v.stderr.splitlines()
    assert (tmp_path / "bad.rrd").stat().st_size > 0


def test_a_damaged_record_header_is_passed_by_the_chunk_index(run_dir, tmp_path):
    """The record's own framing damaged (its opcode and length): nothing says where the next
    record starts but the summary's chunk index, which the reader follows."""
    chunks = _chunks(run_dir / "recording.mcap")
    d = _copy(run_dir, tmp_path, "head")
    start = chunks[1][0]
    with open(d / "recording.mcap", "r+b") as f:
        f.seek(start)
        f.write(b"\xff" * 9)
    got, lost = _all(d / "recording.mcap")
    full, _ = _all(run_dir / "recording.mcap")
    assert lost[0].offset == start and f"read again from the next chunk at byte {chunks[2][0]}" in lost[0].text()
    assert 0 < len(got) < len(full)


def test_a_file_cut_anywhere_reads_a_prefix_and_says_where(run_dir, tmp_path):
    """Cut at 20 seeded offsets (a killed writer, a full disk): what is read is always the
    first messages of the whole file, in order, and a cut inside a record is named."""
    path = run_dir / "recording.mcap"
    data = path.read_bytes()
    full, _ = _all(path)
    rng = random.Random(50)
    cuts = sorted(rng.randrange(9, len(data)) for _ in range(20))
    for cut in cuts:
        p = tmp_path / "cut.mcap"
        p.write_bytes(data[:cut])
        got, lost = _all(p)
        assert got == full[: len(got)], cut
        assert all("Traceback" not in x.text() for x in lost)
        assert len(lost) <= 1 and all(x.offset < cut for x in lost), (cut, [x.text() for x in lost])


def test_a_file_cut_before_its_first_record_holds_nothing_and_says_so(run_dir, tmp_path):
    """A recorder killed before its first flush (every 0.5 s) leaves an empty file, or one cut
    inside MCAP's 8-byte magic: ours, with nothing in it (not "not an MCAP recording", exit 2).
    zswarm report says the run did not complete, in one line per problem (exit 1)."""
    data = (run_dir / "recording.mcap").read_bytes()
    for cut in range(8):
        p = tmp_path / "cut.mcap"
        p.write_bytes(data[:cut])
        got, lost = _all(p)
        assert got == [] and len(lost) == 1 and lost[0].offset == cut and "cut short" in lost[0].text(), (cut, [x.text() for x in lost])
    d = _copy(run_dir, tmp_path, "empty")
    (d / "recording.mcap").write_bytes(b"")
    p = _cli("report", str(d))
    assert p.returncode == 1 and "Traceback" not in p.stderr + p.stdout, p.stderr
    assert "NOT COMPLETED" in p.stdout, p.stdout


def test_a_cut_recording_reports_and_views_without_a_traceback(run_dir, tmp_path):
    d = _copy(run_dir, tmp_path, "cut")
    data = (d / "recording.mcap").read_bytes()
    (d / "recording.mcap").write_bytes(data[: len(data) // 2])
    p = _cli("report", str(d))
    assert p.returncode == 1 and "Traceback" not in p.stderr, p.stderr
    s = json.loads((d / "summary.json").read_text())
    assert not s["completed"] and any("ends at t =" in q for q in s["problems"])


def test_a_file_that_is_not_mcap_is_one_line_and_exit_2(run_dir, tmp_path):
    d = _copy(run_dir, tmp_path, "foreign")
    (d / "recording.mcap").write_bytes(b"PK\x03\x04 a zip file, not a recording" * 10)
    with pytest.raises(NotMcap):
        list(mcap_io.read(d / "recording.mcap", []))
    for args in (("report", str(d)), ("view", str(d), "--save", str(tmp_path / "x.rrd"))):
        p = _cli(*args)
        assert p.returncode == 2, (args, p.stderr)
        assert "Traceback" not in p.stderr and "not an MCAP recording" in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr


def test_a_damaged_raw_recording_keeps_its_losses_in_the_viewer_file(tmp_path):
    """The recorder's raw file (no chunk index) with a damaged chunk: the transcode reads the
    rest, writes each loss on events/lost, and the report made from the viewer file (the raw
    one deleted) still names it."""
    raw = tmp_path / ("recording" + mcap_io.RAW_SUFFIX)
    out = mcap_io.RawOut(raw)
    for k in range(300):
        out.alive({"key": f"zswarm/run/alive/agent/{k % 8}", "alive": True, "t_wall": float(k)}, k * 10**6)
        if k % 100 == 99:
            out.flush()  # a chunk a flush, as the recorder's every 0.5 s
    out.close()
    data = bytearray(raw.read_bytes())
    offs, pos = [], 8
    while pos + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, pos)
        if opcode == 0x06:  # Chunk
            offs.append(pos)
        pos += 9 + length
    assert len(offs) >= 2
    second = offs[1]
    data[second + 60 : second + 80] = b"\x00" * 20  # inside the second chunk's data: its CRC fails
    raw.write_bytes(bytes(data))
    vo = tmp_path / "recording.mcap"
    mcap_io.transcode(raw, vo, None)
    assert not raw.exists()
    texts = [m["text"] for s, m, _t in mcap_io.read(vo, []) if s == mcap_io.LOST_CHANNEL]
    assert texts[0].startswith(f"{raw}: byte {offs[1]}: damaged chunk") and texts[1:] == [f"{raw}: in all: 100 of its 300 messages lost (the count in its statistics)"], texts
    assert sum(1 for s, _m, _t in mcap_io.read(vo, []) if s == mcap_io.ALIVE_CHANNEL) == 200  # the other two chunks
