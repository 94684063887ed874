"""Issue 47, typed wire messages (version 5): the recordings of version 4 still read.

``tests/data/v4`` holds one run of the §4.5 hybrid observer made by version 4 (its README says
how): the viewer recording (JSON) with what that version's report wrote, and the same run's raw
recording (msgpack).  Read by this version (zswarm.transport.wire_v4 turns each message into its
Struct), the report is the one version 4 wrote: errors.csv and edges.csv bit for bit (the messages
carry the same float64 values whichever version reads them, and the report computes the same things
from them), the summary's means within the rounding of numpy's summation order, which follows the
CPU (see the test)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

from tests.conftest import ROOT

DATA = ROOT / "tests" / "data" / "v4"
WALL = ("wall_time_s", "wall_time_run_s", "wall_time_recording_s", "wall_time_report_s")  # how long it took: not a result


def _report(folder):
    r = subprocess.run([sys.executable, "-m", "zswarm", "report", str(folder)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return r


def _flat(x, p=""):
    """A summary as {"a.b.c": value} (lists as they are)."""
    if isinstance(x, dict):
        out = {}
        for k, v in x.items():
            out.update(_flat(v, f"{p}.{k}" if p else str(k)))
        return out
    return {p: x}


def _summary(path):
    return {k: v for k, v in json.loads(path.read_text()).items() if k not in WALL}


def test_a_version_4_viewer_recording_reports_as_version_4_did(tmp_path):
    run = tmp_path / "run"
    shutil.copytree(DATA / "json", run)
    for f in ("errors.csv", "edges.csv"):  # (the summary stays: the report takes the run's engine and options from it)
        (run / f).unlink()
    _report(run)
    for f in ("errors.csv", "edges.csv"):
        assert (run / f).read_bytes() == (DATA / "json" / f).read_bytes(), f
    new, old = _flat(_summary(run / "summary.json")), _flat(_summary(DATA / "json" / "summary.json"))
    # What later versions of the summary added (late sensor data, 2026-12-06), and nothing else.
    assert set(old) <= set(new) and all((k.startswith(("overload.agents_idle_pct", "overload.late", "recording.damaged")) or k.endswith(".fate")) for k in set(new) - set(old)), sorted(set(new) ^ set(old))
    for k, w in old.items():
        g = new[k]
        if isinstance(w, float) and isinstance(g, float):
            # errors.csv is the same bytes; the final means over its last second are numpy means,
            # whose summation order follows the CPU's SIMD width (AVX-512 where the data was
            # written, AVX2 elsewhere: 2 of their 5 agents moved by 4e-16).  A sum of n terms in
            # another order moves by at most (n - 1) u sum|x| (u = 2^-53): with at most 1000 rows
            # of non-negative errors, 1000 u of the mean, and the mean over agents likewise.
            assert abs(g - w) <= 1000 * 2.0**-53 * abs(w), (k, g, w)
        else:
            assert g == w, (k, g, w)
    assert old["jumps_total"] == 4  # ξ's jumps, one per edge: the est messages' "jumps" of version 4


def test_a_version_4_raw_recording_reports_the_same_run(tmp_path):
    """The raw recording (msgpack payloads of version 4) of the same run: transcoded into a viewer
    recording of this version, then reported as above."""
    run = tmp_path / "raw"
    shutil.copytree(DATA / "raw", run)
    _report(run)
    assert (run / "recording.mcap").exists()
    assert (run / "errors.csv").read_bytes() == (DATA / "json" / "errors.csv").read_bytes()
    assert (run / "edges.csv").read_bytes() == (DATA / "json" / "edges.csv").read_bytes()
    assert _summary(run / "summary.json")["jumps_total"] == 4
