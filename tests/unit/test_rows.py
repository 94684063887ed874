"""Results CSVs read as whole rows or torn ones (zswarm.util.rows): what a resume trusts.

Issue 50's finding: a sweep.csv whose last row lost its end (kill -9 or a power cut mid-write)
resumed as "all done", the torn row kept with ``edge_dropped`` 138 where the run had 1382.
"""

from __future__ import annotations

import csv
import io

import pytest

from zswarm.studies.sweep import read_done
from zswarm.util import rows

HEADER = ["run_id", "status", "edge_dropped", "error"]
ROWS = [
    {"run_id": "p000-r0", "status": "ok", "edge_dropped": 1382, "error": ""},
    {"run_id": "p000-r1", "status": "failed", "edge_dropped": None, "error": "exit code 1: a, \"quoted\"\nsecond line"},
    {"run_id": "p001-r0", "status": "ok", "edge_dropped": 1382, "error": ""},
]


def _written(tmp_path):
    p = tmp_path / "sweep.csv"
    f, w, t = rows.open_append(p, HEADER)
    with f:
        for r in ROWS:
            rows.append(f, w, r)
    return p, p.read_bytes()


def test_written_rows_read_back_whole_one_line_each(tmp_path):
    p, data = _written(tmp_path)
    t = rows.read(p)
    assert t.header == HEADER and t.torn == []
    assert [r["run_id"] for r in t.rows] == ["p000-r0", "p000-r1", "p001-r0"]
    assert t.rows[1]["error"] == 'exit code 1: a, "quoted" second line'  # a cell never holds a newline
    assert t.rows[0]["edge_dropped"] == "1382" and t.rows[1]["edge_dropped"] == ""
    assert data.count(b"\n") == 1 + len(ROWS)
    assert t.whole == data


def test_every_cut_of_the_last_row_is_torn_and_its_run_done_again(tmp_path):
    """A write cut after any byte of the last row: the row is never read, and opening the file
    to append drops it (the bytes before it stay as written), so its run runs again once."""
    p, data = _written(tmp_path)
    start = data.rstrip(b"\n").rfind(b"\n") + 1  # where the last row begins
    for cut in range(start + 1, len(data)):
        p.write_bytes(data[:cut])
        t = rows.read(p)
        assert [r["run_id"] for r in t.rows] == ["p000-r0", "p000-r1"], cut
        assert t.torn == [len(ROWS) + 1], cut  # the header is line 1
        assert set(read_done(p)) == {"p000-r0", "p000-r1"}
        f, w, t2 = rows.open_append(p, HEADER)
        f.close()
        assert p.read_bytes() == data[:start], cut
        assert t2.torn == t.torn


def test_a_row_with_its_cells_cut_but_a_newline_is_torn(tmp_path):
    """The issue's row: the first cells of a run (status "ok") and the rest missing."""
    p, data = _written(tmp_path)
    p.write_bytes(data + b"p002-r0,ok,138\r\n")
    t = rows.read(p)
    assert [r["run_id"] for r in t.rows] == ["p000-r0", "p000-r1", "p001-r0"]
    assert "p002-r0" not in read_done(p)


@pytest.mark.parametrize(
    "junk",
    [b"\x00" * 40 + b"\n", b"\xff\xfe garbage \x81\n", b'p009-r0,"ok,1\n', b"p009-r0,ok,1,,extra\n"],
    ids=["nuls", "not-utf8", "open-quote", "extra-cell"],
)
def test_damage_in_the_middle_is_dropped_and_the_rest_kept(tmp_path, junk):
    """A broken disk's block of NULs or garbage between rows: that line is torn, the rows
    around it whole; appending afterwards leaves a file whose every line is whole."""
    p, data = _written(tmp_path)
    lines = data.split(b"\n")
    p.write_bytes(b"\n".join(lines[:2]) + b"\n" + junk + b"\n".join(lines[2:]))
    t = rows.read(p)
    assert [r["run_id"] for r in t.rows] == ["p000-r0", "p000-r1", "p001-r0"]
    assert t.torn == [3]
    f, w, _ = rows.open_append(p, HEADER)
    with f:
        rows.append(f, w, {"run_id": "p002-r0", "status": "ok", "edge_dropped": 7, "error": ""})
    again = rows.read(p)
    assert again.torn == [] and [r["run_id"] for r in again.rows] == ["p000-r0", "p000-r1", "p001-r0", "p002-r0"]
    assert list(csv.reader(io.StringIO(p.read_text(), newline="")))[0] == HEADER


def test_a_torn_header_starts_the_file_again(tmp_path):
    p = tmp_path / "sweep.csv"
    p.write_bytes(b"run_id,sta")
    assert rows.read(p).header is None
    f, w, t = rows.open_append(p, HEADER)
    f.close()
    assert t.rows == [] and rows.read(p).header == HEADER


def test_an_older_header_is_kept_and_rows_checked_against_it(tmp_path):
    """A folder begun by an older zswarm keeps its columns; a row's cells are counted against them."""
    p = tmp_path / "sweep.csv"
    p.write_bytes(b"run_id,status\r\np000-r0,ok\r\np000-r1,ok,extra\r\n")
    f, w, t = rows.open_append(p, HEADER)
    with f:
        rows.append(f, w, {"run_id": "p001-r0", "status": "ok", "edge_dropped": 3})
    assert w.fieldnames == ["run_id", "status"]
    assert [r["run_id"] for r in rows.read(p).rows] == ["p000-r0", "p001-r0"]


def test_the_torn_text_names_the_file_the_lines_and_what_happens(tmp_path):
    p = tmp_path / "sweep.csv"
    assert rows.torn_text(p, [6]) == f"{p}: line 6: a torn row (a write cut short) dropped; its run is done again"
    assert rows.torn_text(p, [3, 9]) == f"{p}: lines 3, 9: 2 torn rows (writes cut short) dropped; their runs are done again"
