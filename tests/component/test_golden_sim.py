"""``zswarm sim`` on every shipped scenario gives the reference's numbers
(tests/data/golden_sim.json): a refactor of the algorithm interface, the scenario loader or the
report must not move one bit of ``errors.csv``, ``edges.csv`` or the numbers of
``summary.json`` on the machine the reference was written on, nor any number by more than its
round-off bound on another (tests/golden.py says which bits hold where, and derives the bound
from the spread measured in tests/data/golden_spread.json).

The reference is written by ``make golden`` (tests/write_golden.py), the spread by ``make
golden-spread`` (tests/measure_golden_spread.py): commands of their own that report no test
result.  tests/layers.sh runs this file under the default settings and again under its OTHER
ones (OpenBLAS's Prescott kernel, numpy without AVX-512); both are among the measured settings.
"""

from __future__ import annotations

import json
import os
import re

import pytest

from tests import golden
from tests import measure_golden_spread as spread

_FINGERPRINT = golden.fingerprint()
CHANGES = [(name, field) for name, gains in spread.GAINS.items() for field in gains]


def _measured() -> dict:
    return json.loads(spread.SPREAD.read_text())


def test_writing_is_not_a_test():
    """The reference is written by ``make golden``; the old switch would now only mislead."""
    assert os.environ.get("ZSWARM_GOLDEN_WRITE") is None, "ZSWARM_GOLDEN_WRITE is gone: `make golden` writes tests/data/golden_sim.json"


@pytest.mark.parametrize("name", golden.SCENARIOS)
def test_sim_numbers_are_the_references(name, tmp_path):
    ref = golden.reference()
    assert name in ref.get("scenarios", {}), f"{name}: no reference in {golden.GOLDEN} (a new scenario: `make golden` on a known-good commit)"
    same = ref["fingerprint"] == _FINGERPRINT
    problems = golden.compare(golden.run(name, tmp_path), ref["scenarios"][name], same, name)
    where = "this machine (bit for bit)" if same else f"another machine (derived tolerance): reference {ref['fingerprint']}, here {_FINGERPRINT}"
    assert not problems, f"{name} on {where}:\n" + "\n".join(problems[:20])


@pytest.mark.parametrize(("name", "field"), CHANGES, ids=[f"{n}:{f}" for n, f in CHANGES])
def test_a_gain_changed_by_a_millionth_fails_on_any_machine(name, field, tmp_path):
    """The comparison keeps its teeth on every thesis scheme (§3.2, §3.3, §4.5 hybrid pose,
    §5.6 hybrid), here under whatever settings this process runs with: each gain times
    1 + 1e-6 moves a number of the run by SAFETY times its bound or more.  Then it fails on any
    machine whose spread is within the bound (a difference of at least (SAFETY − 1) bounds
    cannot hide in one bound), and on this one, where the comparison may be bit for bit.
    Measured under 14 settings (tests/data/golden_spread.json): the weakest, §3.3's k_R of
    agent 5, moves agent 5's position error by 2.2e3 bounds; the others by 1.8e4 to 8e6."""
    value = spread.GAINS[name][field]
    got = golden.run(name, tmp_path, (spread.changed(field, value),))
    want = golden.reference()["scenarios"][name]
    tol = golden.bounds(name, got, want)
    ratios = sorted(((abs(got["summary"][k] - want["summary"][k]) / tol[k], k) for k in tol), reverse=True)
    assert ratios[0][0] >= golden.SAFETY, ratios[:5]
    assert golden.compare(got, want, same_machine=False, name=name)
    assert golden.compare(got, want, same_machine=True, name=name)


def test_the_bound_covers_the_measured_spread():
    """Every number that moved under a measured setting moved by at most 1/SAFETY of its bound,
    and no count, flag or string moved (the file's margins are the ones these constants give)."""
    doc = _measured()
    ref = golden.reference()["scenarios"]
    assert doc["reference_fingerprint"] == golden.reference()["fingerprint"], "golden_sim.json was rewritten: `make golden-spread` anew"
    now = spread.margins(doc["settings"], ref)
    assert now == doc["margins"], "the bound's constants changed: `python -m tests.measure_golden_spread --margins` (or measure anew)"
    assert doc["bound"] == {"SAFETY": golden.SAFETY, "K_ULPS": golden.K_ULPS, "C_TRACE": golden.C_TRACE, "AMPLIFIED": golden.AMPLIFIED}
    over = [(s, n, m["worst"], m["worst_over_bound"]) for s, x in now.items() for n, m in x["spread"].items() if m["worst_over_bound"] > 1 / golden.SAFETY]
    assert not over, over
    unequal = [(s, n, m["unequal"]) for s, x in now.items() for n, m in x["spread"].items() if m["unequal"]]
    assert not unequal, unequal
    assert set(doc["settings"]["default"]["moved"]) == set(golden.SCENARIOS)  # every scenario measured


def test_the_constants_are_the_derived_ones():
    """K_ULPS, C_TRACE and AMPLIFIED are SAFETY times what was measured, rounded up to a power of
    two (tests/measure_golden_spread.py ``derived``), and a run is in AMPLIFIED only if it needs it."""
    doc = _measured()
    d = spread.derived(doc["settings"], golden.reference()["scenarios"])
    assert d == doc["derived"]
    assert spread.constants(d) == {"K_ULPS": golden.K_ULPS, "C_TRACE": golden.C_TRACE, "AMPLIFIED": golden.AMPLIFIED}, d
    assert all(k > golden.K_ULPS for k in golden.AMPLIFIED.values()), golden.AMPLIFIED


def test_the_bound_is_for_the_length_it_was_measured_at():
    """tests/data/golden_growth.json: at another length the same constants do not hold (so
    ``bounds`` refuses one), and the AMPLIFIED runs grow a turned initial estimate where the
    hybrid observer damps it."""
    doc = json.loads(spread.GROWTH.read_text())
    at = {(s, run): m for s, x in doc["lengths"].items() for run, m in x.items()}
    assert all(m["worst_over_bound"] <= 1 / golden.SAFETY for (s, run), m in at.items() if m["N"] == golden.N_MEASURED), at
    assert max(m["worst_over_bound"] for m in at.values() if m["N"] != golden.N_MEASURED) > 1
    turned = doc["turned"]
    assert turned["thesis-4.5-continuous5"]["gain"] > 100 > 1 > turned["thesis-4.5-hybrid5"]["gain"], turned
    assert turned["thesis-5.6-velocity-free7"]["gain"] > 1, turned


def test_every_measured_gain_change_fails_under_every_setting():
    """Under each of the 14 measured settings, each gain change of the four schemes fails the
    comparison, by SAFETY bounds or more."""
    doc = _measured()
    weak = []
    for setting, x in doc["margins"].items():
        for name, field in CHANGES:
            m = x["gain_changes"][f"{name} {field}"]
            if not (m["fails"] and m["largest_over_bound"] >= golden.SAFETY):
                weak.append((setting, name, field, m))
    assert not weak, weak


def test_the_measured_settings_include_the_suites_own():
    """tests/layers.sh runs this file again under its OTHER settings: those were measured, as
    was each of their parts alone, and the default."""
    text = (golden.ROOT / "tests" / "layers.sh").read_text()
    other = re.search(r'^OTHER="([^"]*)"', text, re.M)
    assert other is not None, "tests/layers.sh has no OTHER= line"
    env = dict(kv.split("=", 1) for kv in other.group(1).split())
    measured = [s["env"] for s in _measured()["settings"].values()]
    assert env in measured and {} in measured, (env, measured)
    assert all({k: v} in measured for k, v in env.items()), (env, measured)


def test_the_tolerance_is_the_derived_one():
    """tests/golden.py's bound, on the cases its docstring derives."""
    u, K, C = golden.U, golden.K_ULPS, golden.C_TRACE
    assert golden.tolerance("agents.3.position_error_final", 0.4, 0.4, 5.0, K) == pytest.approx(K * u * 5.4)
    # one measure: K ulps of 1 + |w| and its floor, exact through its square, never more than sqrt(C u)
    assert golden.tolerance("agents.3.attitude_error_final", 0.5, 0.5, 5.0, K) == pytest.approx(K * u * 1.5 + C * u / 1.0)
    assert golden.tolerance("agents.3.attitude_error_final", 1e-9, 1e-9, 5.0, K) == pytest.approx(K * u * (1 + 1e-9) + (C * u) ** 0.5)
    # an aggregate: at least the largest bound of its terms
    assert golden.tolerance("mean_attitude_error_final", 0.5, 0.5, 5.0, K, 1e-7) == 1e-7
    assert golden.tolerance("synchronization.final", 0.5, 0.5, 5.0, K, 0.0) == pytest.approx(K * u * 1.5 + C * u / 1.0)
    # an amplified run has its own K; a run of another length has none (measured: not a multiple of N)
    assert golden.k_ulps("thesis-3.2-fixed8", golden.N_MEASURED) == K
    assert golden.k_ulps("thesis-4.5-continuous5", golden.N_MEASURED) == golden.AMPLIFIED["thesis-4.5-continuous5"]
    with pytest.raises(ValueError, match="golden-spread"):
        golden.k_ulps("thesis-3.2-fixed8", 2 * golden.N_MEASURED)
    # the §3.3 follower measured between the SkylakeX and Haswell kernels (1.7e-7, 0.25 %) is within it
    g, w = 1.6893630909549037e-07, 1.6936651483911734e-07
    assert abs(g - w) <= golden.tolerance("agents.3.attitude_error_final", w, g, 5.0, K)
