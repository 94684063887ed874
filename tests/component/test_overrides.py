"""``--set FIELD=VALUE`` overrides and the stale-data policy in scenarios (issue 4)."""

import math
import subprocess
import sys

import pytest

from tests.conftest import ROOT, TOPO
from zswarm.scenario import ScenarioError, load, loads, parse_override

FIXED8 = TOPO / "thesis-3.2-fixed8.toml"


def with_sets(*sets):
    return load(FIXED8, [parse_override(s) for s in sets])


def test_overrides_reach_every_kind_of_field():
    sc = with_sets(
        "links.delay_ms=50",
        "links.jitter=exponential",  # not TOML: taken as a string
        'links.per_link."1->3".drop=0.5',
        "links.sensors.drop=0.1",
        "agents[2].clock.rate=50",
        "scenario.duration=12.5",
        "algorithm.gains.k_R=2",
        "agents[3].p=[0, 2, 3.5]",
        "algorithm.stale.policy=drop",
    )
    assert sc.links.delay_ms == 50 and sc.links.jitter == "exponential"
    assert sc.link_spec("1->3").drop == 0.5 and sc.link_spec("1->3").delay_ms == 50  # on top of [links]
    assert sc.link_spec("world->3").drop == 0.1 and sc.link_spec("world->3").delay_ms == 0  # sensors: their own defaults
    assert sc.agent(3).clock.rate == 50 and sc.agent(4).clock.rate == 100
    assert sc.duration == 12.5 and sc.gains["k_R"] == 2
    assert sc.agent(4).p == (0, 2, 3.5)
    assert sc.stale.policy == "drop"


def test_overridden_scenario_text_loads_back_to_the_same_scenario():
    sc = with_sets("links.delay_ms=50", 'links.per_link."1->3".drop=0.5', "agents[2].clock.rate=50")
    assert sc.text.startswith(f"# {FIXED8}, with --set links.delay_ms=50")
    again = loads(sc.text, "again.toml")
    for f in ("links", "sensor_links", "link_overrides", "agents", "duration", "gains", "stale"):
        assert getattr(again, f) == getattr(sc, f), f


@pytest.mark.parametrize(
    ("setting", "message"),
    [
        ("links.dealy_ms=5", "--set links.dealy_ms=5: links.dealy_ms: unknown key; did you mean 'delay_ms'? (allowed: "),
        ("links.jitter=normall", "links.jitter: must be one of normal, exponential; did you mean 'normal'? (got 'normall')"),
        ("links.delay_ms=-5", "--set links.delay_ms=-5: links.delay_ms: must be >= 0"),
        ("links.drop=1.5", "--set links.drop=1.5: links.drop: must be a probability in [0, 1]"),
        ("links.sensors.ge_p_gb=-0.1", "links.sensors.ge_p_gb: must be a probability"),
        ('links.per_link."9->3".drop=0.1', '--set links.per_link."9->3".drop=0.1: links.per_link."9->3": unknown key'),
        ("agents[20].p=[1,2,3]", "agents[20]: no such element (the array has 8)"),
        ("nosuch.x=1", "--set nosuch.x=1: nosuch: unknown key (allowed: "),  # nothing close: no guess
        ("clock.rate=0", "--set clock.rate=0: clock.rate: must be > 0"),
        ("algorithm.stale.policy=forget", "algorithm.stale.policy: must be one of hold, drop (got"),
        ("algorithm.stale.policy=holds", "algorithm.stale.policy: must be one of hold, drop; did you mean 'hold'?"),
        ("links.delay_ms", "expected FIELD=VALUE"),
        ("=3", "expected FIELD=VALUE"),
    ],
)
def test_bad_overrides_name_the_flag_and_the_field(setting, message):
    with pytest.raises(ScenarioError) as e:
        with_sets(setting)
    assert message in str(e.value)
    assert str(FIXED8) not in str(e.value).split(":")[0]  # the flag is blamed, not the file


def test_cli_set_unknown_field_exits_2_with_the_flag(tmp_path):
    p = subprocess.run(
        [sys.executable, "-m", "zswarm", "sim", str(FIXED8), "--set", "links.dealy_ms=5", "--out", str(tmp_path / "o")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert p.returncode == 2
    assert "--set links.dealy_ms=5: links.dealy_ms: unknown key" in p.stderr


def test_cli_set_is_applied_and_stored_in_the_results_folder(tmp_path):
    out = tmp_path / "o"
    p = subprocess.run(
        [sys.executable, "-m", "zswarm", "sim", str(FIXED8), "--set", "links.drop=0.3", "--duration", "1", "--no-plots", "--lean", "--quiet", "--out", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert p.returncode == 0, p.stderr
    assert p.stdout == ""  # --quiet
    stored = load(out / "scenario.toml")
    assert stored.links.drop == 0.3
    import json

    s = json.loads((out / "summary.json").read_text())
    assert s["links"]["1->3"]["link_dropped"] > 0
    assert "sense" not in s["recorded_messages"]  # --lean


def test_stale_policy_defaults_per_algorithm():
    assert load(FIXED8).stale.policy == "hold"
    assert load(TOPO / "thesis-3.3-moving5.toml").stale.policy == "drop"
    assert load(TOPO / "thesis-4.5-hybrid5.toml").stale.policy == "drop"
    assert math.isclose(load(FIXED8).stale.max_age, 0.2)
