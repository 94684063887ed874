"""A ``zswarm sim`` gives the same bits with the compiled loops (zswarm/math/_kernels.c) and without
them (``ZSWARM_KERNELS=0``: every function in Python and numpy): the one-draw paths an agent's tick
takes (the gyro's pre-integration, so3's products, the §3 observers' sums) as well as the world's
and the filters'.  tests/unit/test_kernels.py holds each function to its Python on chosen inputs;
this holds whole runs of the schemes that call them most, over 3 s (300 ticks of every agent)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tests.conftest import ROOT

SCENARIOS = ("thesis-3.2-fixed8", "thesis-3.2-fixed8-filtered", "thesis-3.3-moving5", "thesis-4.5-hybrid-pose5")


@pytest.mark.parametrize("name", SCENARIOS)
def test_a_run_is_the_same_with_and_without_the_compiled_loops(name, tmp_path):
    outs = {}
    for k in ("1", "0"):
        out = tmp_path / f"kernels-{k}"
        cmd = [sys.executable, "-m", "zswarm", "sim", str(ROOT / "topologies" / f"{name}.toml"), "--duration", "3", "--out", str(out), "--no-plots", "--quiet", "--no-recording"]
        subprocess.run(cmd, env={**os.environ, "ZSWARM_KERNELS": k}, cwd=ROOT, check=True, timeout=300, capture_output=True)
        outs[k] = out
    for f in ("errors.csv", "edges.csv"):
        a, b = outs["1"] / f, outs["0"] / f
        assert a.exists() == b.exists(), f
        if a.exists():
            assert a.read_bytes() == b.read_bytes(), f"{name}: {f} differs with and without the compiled loops"
    assert (outs["1"] / "errors.csv").stat().st_size > 1000  # the run wrote its rows
