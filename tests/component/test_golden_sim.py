"""``zswarm sim`` on every shipped scenario gives the same numbers as the reference
(tests/data/golden_sim.json): a refactor of the algorithm interface, the scenario loader
or the report (issue 30) must not move one bit of ``errors.csv``, ``edges.csv`` or the
numbers of ``summary.json``.

Each scenario runs for DURATION s of world time: long enough for the hybrid schemes'
jumps at t = 0 and the first flow, the De Carli estimators' first updates and every
report section (the report's convergence entries are ``null`` this early, which is
compared too).  The reference is written by ``ZSWARM_GOLDEN_WRITE=1 pytest
tests/component/test_golden_sim.py`` on a commit whose numbers are known good.

Bit for bit holds for one numpy build: the reference records numpy's version; under
another numpy (another BLAS, another SIMD path) the CSV digests cannot be compared, and
the summary numbers are compared to RTOL instead: a different rounding of the same
operations moves a result by a few ulps per operation, ~1e-13 relative after the 200
steps here; a changed formula, gain or ordering moves it by far more than 1e-9.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import ROOT, TOPO
from zswarm.report import make_report
from zswarm.scenario import load
from zswarm.sim import simulate

GOLDEN = ROOT / "tests" / "data" / "golden_sim.json"
DURATION = 2.0
RTOL = 1e-9
SCENARIOS = sorted(p.stem for p in TOPO.glob("*.toml"))
# Measured wall times and the wall-time-derived figures are not results.
NOT_RESULTS = ("wall_time", "compute_mean_us", "compute_max_us", "compute_s")
# Keys summary.json gained after the reference was written (not numbers of the run): left out
# of the comparison of key sets; every number of the reference is still compared.
ADDED = ("report_family",)


def numbers(x, path=""):
    """The summary's result leaves: path -> number, string, bool or None (timings left out)."""
    if isinstance(x, dict):
        out = {}
        for k, v in x.items():
            if any(n in k for n in NOT_RESULTS):
                continue
            out.update(numbers(v, f"{path}.{k}" if path else str(k)))
        return out
    if isinstance(x, list):
        out = {}
        for n, v in enumerate(x):
            out.update(numbers(v, f"{path}[{n}]"))
        return out
    return {path: x}


def run(name: str, out: Path) -> dict:
    sc = load(TOPO / f"{name}.toml")
    simulate(sc, out, DURATION, sc.seed)
    summary = make_report(out, sc, "sim", DURATION, 0.0, sc.seed, plots=False)
    digests = {f: hashlib.sha256((out / f).read_bytes()).hexdigest() for f in ("errors.csv", "edges.csv") if (out / f).exists()}
    return {"csv_sha256": digests, "summary": numbers(json.loads(json.dumps(summary)))}


def _reference() -> dict:
    return json.loads(GOLDEN.read_text()) if GOLDEN.exists() else {}


@pytest.mark.parametrize("name", SCENARIOS)
def test_sim_numbers_are_the_references(name, tmp_path):
    got = run(name, tmp_path)
    if os.environ.get("ZSWARM_GOLDEN_WRITE") == "1":
        ref = _reference()
        ref["numpy"] = np.__version__
        ref.setdefault("scenarios", {})[name] = got
        GOLDEN.write_text(json.dumps(ref, indent=1, sort_keys=True) + "\n")
        return
    ref = _reference()
    assert name in ref.get("scenarios", {}), f"{name}: no reference in {GOLDEN} (a new scenario: write it, see the module docstring)"
    want = ref["scenarios"][name]
    assert set(got["summary"]) - set(ADDED) == set(want["summary"]) - set(ADDED), sorted((set(got["summary"]) ^ set(want["summary"])) - set(ADDED))
    same_numpy = ref["numpy"] == np.__version__
    for k, w in want["summary"].items():
        g = got["summary"][k]
        if same_numpy or not isinstance(w, float) or isinstance(w, bool):
            assert g == w or (isinstance(w, float) and math.isnan(w) and math.isnan(g)), (k, g, w)
        else:
            assert g == pytest.approx(w, rel=RTOL, nan_ok=True), (k, g, w)
    if same_numpy:
        assert got["csv_sha256"] == want["csv_sha256"]
