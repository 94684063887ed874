"""Convergence study: each shipped noise-free scenario on ``sim`` at its default
rates (agents 100 Hz, sensors 200 Hz) against the same scenario at 5× those
rates (agents 500 Hz, sensors 1 kHz; zswarm/studies/step_size.py).  5× and not 10×: the
reference's own step error is then a fifth of the default's (O(a·dt) ≤ 1 % on
a time), which is all the criteria below need, at half the cost of the
suite's most expensive fixture; `zswarm.studies.step_size.refine`'s 10× gave the same
verdicts and the numbers in the README.

What the study may accept, and why:

* Times to thresholds within 10 % (the issue's criterion) plus one grid step
  of 0.1 s, the resolution at which convergence times are measured
  (report.GRID_S): a first-order step of 10 ms moves a convergence time by
  O(a·dt) relative (a ≤ 5 /s for these observers: ≤ 5 %), a 2 ms step five
  times less; anything beyond 10 % is not discretisation.
* Final errors within ×2, or both below 1e-5 (the issue's criterion): below
  1e-5 the floors are set by the truth integration and the float arithmetic
  of 30–60 s of steps, not by the observer.
* ``thesis-4.5-continuous5`` starts exactly on an unstable equilibrium: when
  it leaves is set by round-off and asynchrony (Theorem 4.1 promises nothing
  there), so its times are measured from the escape (mean |R̄_k|_I < 0.9).

**The fine runs are kept in a file.**  They cost 7–65 s of CPU each (235 s in all, 4/5 of this
module's 267 s when it made them all, the suite's largest item; 2026-12 on the writing machine) and their numbers depend only on the code and the
scenario files.  ``make fine-references`` (``python -m tests.component.test_convergence_study
--write``) runs them and keeps in tests/data/convergence_fine.json what
:func:`zswarm.studies.step_size.compare` reads of each (``study.reference``: its times to
thresholds and final errors), with each run as it was made (its TOML's digest, horizon, rates,
step, seed), its CPU seconds and the rounding of the machine that wrote it (tests/golden.py's
fingerprint).  The tests compare each default-rate run, made here (a fifth of a fine run's
cost), with its kept fine numbers, and check that the file is what that command writes now:

* it names the command, and its runs, horizons, rates and TOML digests are the ones this module
  makes (a changed scenario file or horizon fails there: write the file again);
* ONE fine run is made again here (:func:`_rerun`: the cheapest kept run whose times are the
  equations', not round-off's) and must give its kept numbers, exactly on the machine that wrote
  the file and elsewhere within what another rounding moves them (test_a_fine_run_again_gives_its_file).

A code change that moves the fine runs is seen there if it moves the re-run one.  One that moves
another fine run and not its default run is not the default step's error (what this study is
about: tests/component/test_golden_sim.py watches every run's numbers); one that moves a default
run is judged against the kept fine numbers as before.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import multiprocessing
import shutil
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import ROOT, TOPO
from tests.golden import fingerprint
from tests.reproduce import near, write_main
from zswarm.scenario import Scenario, load
from zswarm.studies import step_size as study

FINE = ROOT / "tests" / "data" / "convergence_fine.json"
WRITER = "make fine-references (python -m tests.component.test_convergence_study --write)"

SCENARIOS = ["thesis-3.2-fixed8", "thesis-3.2-fixed8-filtered", "thesis-3.3-moving5", "thesis-4.5-continuous5", "thesis-4.5-hybrid5", "thesis-4.5-hybrid-pose5"]
FROM_ESCAPE = {"thesis-4.5-continuous5"}


# Horizons shorter than the scenario's, both runs alike, where the criteria are decided earlier:
# - thesis-4.5-continuous5: its times are 0.2-0.6 s after the escape and |R̄|_I is at its
#   round-off floor from 5 s on (5.0e-7 to 8.4e-7 at 5, 10, ..., 30 s on the default run):
#   10 s compares the same floor, 1/3 of the cost.
# - thesis-4.5-hybrid-pose5: its last threshold (position < 0.1) falls at 33 s; at 45 s the
#   attitude is at its floor (1.6e-6, both below 1e-5) and the position error decays at
#   ≈ 0.1 /s (3.0e-2 at 45 s, 1.9e-2 at 50 s), so a time shift of the default run's O(a·dt)
#   ≤ 1 % moves it by a few %, far inside ×2.  3/4 of the cost of the suite's largest run.
HORIZON = {"thesis-4.5-continuous5": 10.0, "thesis-4.5-hybrid-pose5": 45.0}


def _scenario(name: str, fine: bool) -> Scenario:
    sc = load(TOPO / f"{name}.toml")
    if name in FIRST_ORDER:
        sc = dataclasses.replace(sc, duration=FIRST_ORDER[name])
    if name in HORIZON:
        sc = dataclasses.replace(sc, duration=HORIZON[name])
    if fine and name in FIRST_ORDER:
        sc = study.refine(sc)  # De Carli: its parts (200/100/50 Hz) at 5× with the agent's clock (1 kHz)
    elif fine:
        sc = study.refine(sc, agent_rate=5 * max(a.clock.rate for a in sc.agents), sensor_rate=5 * sc.sensor_rate)
    return sc


def _spec(name: str) -> dict[str, Any]:
    """The fine run of ``name`` as this module makes it: what its kept numbers are made of."""
    sc = _scenario(name, True)
    return {
        "toml_sha256": hashlib.sha256((TOPO / f"{name}.toml").read_bytes()).hexdigest(),
        "duration": sc.duration,
        "seed": sc.seed,
        "agent_rates": sorted({a.clock.rate for a in sc.agents}),
        "sensor_rate": sc.sensor_rate,
        "step": sc.step,
        "part_rate_scale": sc.part_rate_scale,
        "from_escape": name in FROM_ESCAPE,
    }


def _one(args: tuple[str, bool, str]) -> tuple[study.Series, float]:
    """The run, and the CPU seconds it took."""
    name, fine, out = args
    c0 = time.process_time()
    s = study.run(_scenario(name, fine), Path(out))
    return s, time.process_time() - c0


def _runs(jobs: list[tuple[str, bool, str]]) -> list[tuple[study.Series, float]]:
    """``jobs`` two at a time in spawned processes."""
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        return list(pool.map(_one, jobs))


def _rerun(kept: dict[str, Any]) -> str:
    """The fine run made again: the cheapest kept one (its cpu_s) with at least two times, whose
    times are the equations' (not FROM_ESCAPE: thesis-4.5-continuous5's escape is round-off's, and
    the run grows a perturbation x835, tests/golden.py)."""
    runs = kept["runs"]
    ok = [n for n in sorted(runs) if n not in FROM_ESCAPE and len(runs[n]["reference"]["times"]) >= 2]
    return min(ok, key=lambda n: runs[n]["cpu_s"])


def write(path: Path) -> None:
    """Make every fine run and keep what the study compares of each (``make fine-references``)."""
    names = [*FIRST_ORDER, *SCENARIOS]
    tmp = path.parent / f".{path.stem}-runs"
    try:
        got = _runs([(n, True, str(tmp / n)) for n in names])
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    runs = {
        n: {"scenario": _spec(n), "cpu_s": round(cpu, 1), "reference": study.reference(s, n in FROM_ESCAPE)} for n, (s, cpu) in zip(names, got, strict=True)
    }
    path.write_text(json.dumps({"written_by": WRITER, "fingerprint": fingerprint(), "runs": runs}, indent=1) + "\n")


@pytest.fixture(scope="module")
def kept() -> dict[str, Any]:
    return json.loads(FINE.read_text())


@pytest.fixture(scope="module")
def results(tmp_path_factory, kept):
    """Every default-rate run, and the one fine run :func:`_rerun` picks, made here."""
    tmp = tmp_path_factory.mktemp("study")
    again = _rerun(kept)
    names = [*FIRST_ORDER, *SCENARIOS]
    jobs = [(again, True, str(tmp / f"{again}-fine"))] + [(n, False, str(tmp / f"{n}-default")) for n in names]  # the longest first
    got = _runs(jobs)
    return {(n, f): s for (n, f, _), (s, _cpu) in zip(jobs, got, strict=True)}


# The Chapter 5 closed loops have their own step-size checks (tests/component/test_sim_sync.py:
# 100 Hz against 1 kHz agents over their transient, and READING-NOTES' settle times); a 150 s
# closed loop at 1 kHz costs 3 min here, more than this study's whole budget.
CLOSED_LOOP = {"thesis-5.6-continuous7", "thesis-5.6-hybrid7", "thesis-5.6-velocity-free7"}


# De Carli et al. (first order in the step, see test_decarli_is_first_order_in_the_step): the
# paper's 200/100/50 Hz against 1000/500/250 Hz (study.refine scales the part rates), over
# its first 8 s (the observers' transients end by 2.2 s): the fine run costs ~42 s, 40 s of it
# would cost 4 min.
FIRST_ORDER = {"decarli-8-formation": 8.0}


def test_the_shipped_scenarios_are_all_in_the_study():
    shipped = {p.stem for p in TOPO.glob("*.toml") if "noisy" not in p.stem}
    assert shipped == set(SCENARIOS) | CLOSED_LOOP | set(FIRST_ORDER)


def test_the_kept_fine_runs_are_the_commands_for_these_runs(kept):
    """tests/data/convergence_fine.json names the command that writes it, and holds one fine run of
    each scenario of the study, made as this module makes it now (scenario file, horizon, rates,
    step, seed): else its numbers are another run's, and ``make fine-references`` writes it anew."""
    assert kept["written_by"] == WRITER
    assert list(kept["runs"]) == [*FIRST_ORDER, *SCENARIOS]
    for name, run in kept["runs"].items():
        assert run["scenario"] == _spec(name), (name, "make fine-references")
        assert run["cpu_s"] > 0 and len(run["reference"]["times"]) >= 2, (name, run)  # the study compares something


def test_a_fine_run_again_gives_its_file(results, kept):
    """The fine run :func:`_rerun` picks, made here, gives its kept numbers: the same thresholds
    reached, and

    * on the machine that wrote the file (the same fingerprint), the same bits: the same code
      path on the same rounding (tests/reproduce.py);
    * elsewhere, each time within one step of its series' grid (0.1 s; De Carli's 10 ms): a
      rounding moves a crossing only where the series is within round-off of its threshold at
      a grid point, and then to the next point; each final error as tests/reproduce.near
      prints it (one unit of its third significant digit, or the attitude measure's round-off
      floor 1.7e-7): the project's bound for a long run on another rounding (tests/reproduce.py:
      1.1e-3 relative was measured over 150 s of §4.5's continuous observer, which grows a
      perturbation x835; the runs picked here contract).  Both are far inside what the study
      accepts (10 % + 0.1 s on a time, ×2 on a final error)."""
    name = _rerun(kept)
    want = kept["runs"][name]["reference"]
    s = results[(name, True)]
    got = study.reference(s, name in FROM_ESCAPE)
    assert [(r["key"], r["thr"]) for r in got["times"]] == [(r["key"], r["thr"]) for r in want["times"]], (name, got, want)
    if fingerprint() == kept["fingerprint"]:
        assert got == want, name
        return
    grid = float(s.t[1] - s.t[0])
    for g, w in zip(got["times"], want["times"], strict=True):
        assert abs(g["t"] - w["t"]) <= grid + 1e-9, (name, g, w)  # 1e-9: the grid's own rounding (t = k·grid)
    assert near(got["final_att"], want["final_att"]), (name, got, want)
    assert (got["final_pos"] is None) == (want["final_pos"] is None), (name, got, want)
    assert got["final_pos"] is None or near(got["final_pos"], want["final_pos"]), (name, got, want)


@pytest.mark.parametrize("name", SCENARIOS)
def test_default_rates_match_the_fine_step(results, kept, name):
    rows = study.compare(results[(name, False)], kept["runs"][name]["reference"], name in FROM_ESCAPE)
    times = [r for r in rows if r["what"].endswith("(s)")]
    assert len(times) >= 2, rows  # the study compares something
    for r in times:
        assert r["default"] is not None, (name, r)
        assert abs(r["default"] - r["fine"]) <= 0.10 * r["fine"] + 0.1, (name, r)
    for r in rows:
        if r["what"].startswith("final"):
            d, f = r["default"], r["fine"]
            assert (d < 1e-5 and f < 1e-5) or f / 2 <= d <= 2 * f, (name, r)


def test_moving5_final_position_is_the_equations(results, kept):
    """READING-NOTES: the equations give 0.022–0.023 at 30 s; the default step must
    land within ×2 of the 500 Hz value (it used to give 0.0085)."""
    d, f = results[("thesis-3.3-moving5", False)].final_pos, kept["runs"]["thesis-3.3-moving5"]["reference"]["final_pos"]
    # The reference itself: the equations' 0.022–0.023, with room for the 500 Hz run's own
    # step error (400 Hz gave 0.019 before the step fix); it rejects the 0.0085 artefact.
    assert 0.015 < f < 0.03, f
    assert f / 2 <= d <= 2 * f, (d, f)


def test_decarli_is_first_order_in_the_step(results, kept):
    """De Carli et al. at the paper's rates against 5× faster ones.  The robots keep turning
    (the yaw splines) and moving, so a finite step leaves a floor: (7) and (13) are at
    round-off there (their inputs are brought to each step's time), (21) at 50 Hz keeps a
    first-order one, ∝ dt.  What the study
    accepts, and why:

    * every threshold at least 3× above the default run's final error (its floor, which
      the error wanders around by ±50 % as the excitation varies): the times within 10 %
      + one 0.1 s grid step, as for the other scenarios (the transients are the
      equations', not the step's).  Thresholds nearer the floor are the floor's business:
    * the final errors shrink with the step: default/fine between 5/2 and 5·2 for a step
      ratio of 5 (first order, with the ×2 allowance the other scenarios get), or both
      below 1e-5 (as for the other scenarios).  A floor that is not discretisation (a
      bias, a timing bug) would not shrink: ratio ≈ 1.  Measured at 8 s: yaw 5.1e-6
      against 1.2e-6; position 4.1e-4 against 8.3e-5 m (5.0), from the 50 Hz part's step."""
    name = "decarli-8-formation"
    rows = study.compare(results[(name, False)], kept["runs"][name]["reference"])
    finals = {r["what"].split()[1][:3]: r["default"] for r in rows if r["what"].startswith("final")}
    times = [r for r in rows if r["what"].endswith("(s)") and float(r["what"].split("<")[1].split("(")[0]) >= 3 * finals[r["what"][:3]]]
    assert len(times) >= 4, rows  # yaw < 0.1, 0.01; position < 1, 0.1 m
    for r in times:
        assert r["default"] is not None and abs(r["default"] - r["fine"]) <= 0.10 * r["fine"] + 0.1, (name, r)
    for r in rows:
        if r["what"].startswith("final"):
            d, f = r["default"], r["fine"]
            assert (d < 1e-5 and f < 1e-5) or 5 / 2 <= d / f <= 5 * 2, (name, r)


if __name__ == "__main__":
    write_main("Make the study's fine runs and keep their numbers (tests/data/convergence_fine.json).", FINE, write)
