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

The fine runs are the expensive part of the suite (1–2 min each); they run
two at a time in spawned processes.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest

from tests.conftest import TOPO
from zswarm.scenario import load
from zswarm.studies import step_size as study

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


def _one(args: tuple[str, bool, str]) -> study.Series:
    name, fine, out = args
    sc = load(TOPO / f"{name}.toml")
    if name in FIRST_ORDER:
        sc = dataclasses.replace(sc, duration=FIRST_ORDER[name])
    if name in HORIZON:
        sc = dataclasses.replace(sc, duration=HORIZON[name])
    if fine and name in FIRST_ORDER:
        sc = study.refine(sc)  # De Carli: its parts (200/100/50 Hz) at 5× with the agent's clock (1 kHz)
    elif fine:
        sc = study.refine(sc, agent_rate=5 * max(a.clock.rate for a in sc.agents), sensor_rate=5 * sc.sensor_rate)
    return study.run(sc, Path(out))


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("study")
    names = [*FIRST_ORDER, *SCENARIOS]  # the longest fine run first
    jobs = [(n, True, str(tmp / f"{n}-fine")) for n in names] + [(n, False, str(tmp / f"{n}-default")) for n in names]
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        got = list(pool.map(_one, jobs))
    return {(n, f): s for (n, f, _), s in zip(jobs, got, strict=True)}


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


@pytest.mark.parametrize("name", SCENARIOS)
def test_default_rates_match_the_fine_step(results, name):
    rows = study.compare(results[(name, False)], results[(name, True)], name in FROM_ESCAPE)
    times = [r for r in rows if r["what"].endswith("(s)")]
    assert len(times) >= 2, rows  # the study compares something
    for r in times:
        assert r["default"] is not None, (name, r)
        assert abs(r["default"] - r["fine"]) <= 0.10 * r["fine"] + 0.1, (name, r)
    for r in rows:
        if r["what"].startswith("final"):
            d, f = r["default"], r["fine"]
            assert (d < 1e-5 and f < 1e-5) or f / 2 <= d <= 2 * f, (name, r)


def test_moving5_final_position_is_the_equations(results):
    """READING-NOTES: the equations give 0.022–0.023 at 30 s; the default step must
    land within ×2 of the 500 Hz value (it used to give 0.0085)."""
    d, f = results[("thesis-3.3-moving5", False)].final_pos, results[("thesis-3.3-moving5", True)].final_pos
    # The reference itself: the equations' 0.022–0.023, with room for the 500 Hz run's own
    # step error (400 Hz gave 0.019 before the step fix); it rejects the 0.0085 artefact.
    assert 0.015 < f < 0.03, f
    assert f / 2 <= d <= 2 * f, (d, f)


def test_decarli_is_first_order_in_the_step(results):
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
    rows = study.compare(results[(name, False)], results[(name, True)])
    finals = {r["what"].split()[1][:3]: r["default"] for r in rows if r["what"].startswith("final")}
    times = [r for r in rows if r["what"].endswith("(s)") and float(r["what"].split("<")[1].split("(")[0]) >= 3 * finals[r["what"][:3]]]
    assert len(times) >= 4, rows  # yaw < 0.1, 0.01; position < 1, 0.1 m
    for r in times:
        assert r["default"] is not None and abs(r["default"] - r["fine"]) <= 0.10 * r["fine"] + 0.1, (name, r)
    for r in rows:
        if r["what"].startswith("final"):
            d, f = r["default"], r["fine"]
            assert (d < 1e-5 and f < 1e-5) or 5 / 2 <= d / f <= 5 * 2, (name, r)
