"""report.overload: when a run says it did not keep up."""

from zswarm.report.table import footer_lines
from zswarm.results import OVERLOAD_PCT, overload, table


def agents(*missed, steps=980, idle=0):
    return {str(i + 1): {"missed_deadlines": m, "steps": steps, "idle_ticks": idle} for i, m in enumerate(missed)}


def test_missed_share_is_of_the_ticks_scheduled():
    ov = overload(agents(20, 0), {"samples": 2000, "late": 0})
    assert ov["agents_missed_pct"] == {"1": 2.0, "2": 0.0}  # 20 of 980 + 20
    assert not ov["overloaded"] and ov["reasons"] == []  # exactly at the threshold is not over it


def test_agents_or_world_over_the_threshold_flag_the_run():
    ov = overload(agents(0, 30, 50, idle=20), {"samples": 2000, "late": 0})
    assert ov["overloaded"] and ov["reasons"] == [f"2 of 3 agents missed more than {OVERLOAD_PCT:g} % of their ticks (worst: agent 3, 4.8 %)"]
    ov = overload(agents(0), {"samples": 1950, "late": 50})
    assert ov["overloaded"] and ov["world_skipped_pct"] == 2.5 and ov["reasons"] == ["the world skipped 2.5 % of its samples"]
    assert not overload(agents(0), {})["overloaded"]  # sim: no world counters, nothing missed


def test_the_table_says_so():
    base = {"scenario": "s", "algorithm": "a", "engine": "run", "duration_s": 1, "seed": 1, "links": {},
            "mean_attitude_error_final": 1e-3, "mean_position_error_final": 1e-2,
            "agents": {"1": {"role": "follower", "alive_at_end": True, "attitude_error_final": 1e-3, "position_error_final": 1e-2,
                             "steps": 90, "step_rate_hz": 90.0, "missed_deadlines": 10}}}
    base["overload"] = overload(base["agents"], {})
    assert "OVERLOADED: 1 of 1 agents missed more than 2 % of their ticks (worst: agent 1, 10.0 %)" in table(base)
    base["overload"] = overload(agents(0), {})
    assert "OVERLOADED" not in table(base)


def test_idle_ticks_are_named_where_they_can_only_mean_late_packets():
    # 60 idle ticks of 1000 scheduled (940 steps) = 6 %: over the threshold, for a watched agent only.
    ov = overload(agents(0, 0, steps=940, idle=60), {"samples": 2000, "late": 0}, watch_idle=("2",))
    assert ov["agents_idle_pct"] == {"2": 6.0}
    assert ov["late"][0].startswith(f"1 of 2 agents found no new sensor packet at more than {OVERLOAD_PCT:g} % of their ticks (worst: agent 2, 6.0 %): ")
    assert not ov["overloaded"] and ov["reasons"] == []  # late data, not errors that are not the algorithm's
    assert overload(agents(0, 0, steps=940, idle=60), {"samples": 2000, "late": 0})["late"] == []  # nobody watched
    assert overload(agents(0, idle=20), {}, watch_idle=("1",))["late"] == []  # 20 of 1000: at the threshold, not over it
    s = {"overload": ov}
    assert any(line.startswith("LATE SENSOR DATA: 1 of 2 agents") for line in footer_lines(s)) and not any("OVERLOADED" in x for x in footer_lines(s))


def test_which_agents_idle_ticks_mean_late_packets(tmp_path):
    from tests.conftest import TOPO
    from zswarm.results.pipeline import idle_means_late
    from zswarm.scenario import load

    sc = load(TOPO / "thesis-3.2-fixed8.toml")  # 200 Hz sensors, 100 Hz agents, clean links, no faults
    assert idle_means_late(sc) == [str(a.id) for a in sc.agents]
    text = (TOPO / "thesis-3.2-fixed8.toml").read_text()
    for extra, why in (
        ("\n[links.sensors]\ndelay_ms = 3.0\n", "a delayed sensor link"),
        ('\n[[faults]]\nkind = "kill"\nagent = 5\nat = 2.0\n', "a fault"),
    ):
        f = tmp_path / "s.toml"
        f.write_text(text + extra)
        assert idle_means_late(load(f)) == [], why
    f.write_text(text.replace("sensor_rate = 200.0", "sensor_rate = 150.0"))
    assert idle_means_late(load(f)) == [], "fewer than two samples a tick"


def test_late_sensor_data_names_its_measured_lateness_and_whether_it_accounts_for_the_idle_ticks():
    # 60 idle ticks of 1000 (6 %): two packets a tick, so over 1 % of agent 2's packets came more
    # than one sensor period (5 ms) late, and its p99 latency must be over 5 ms to account for it.
    world = {"samples": 2000, "late": 0, "taken_late": 60, "max_lateness_s": 0.043}
    ov = overload(agents(0, 0, steps=940, idle=60), world, watch_idle=("2",), links={"world->2": {"latency_p99_ms": 31.0}}, sensor_period_s=0.005)
    assert ov["late_explained"] and ov["late_evidence"] == {"world_taken_late_pct": 3.0, "world_max_lateness_ms": 43.0, "sensor_latency_p99_ms": {"2": 31.0}}
    assert "the world took 3 % of its samples more than a sensor period late (worst 43 ms)" in ov["late"][0] and "reached 31 ms" in ov["late"][0]
    # Packets on time (p99 2 ms) cannot leave 6 % of ticks idle: said, and late_explained false.
    ov = overload(agents(0, 0, steps=940, idle=60), world, watch_idle=("2",), links={"world->2": {"latency_p99_ms": 2.0}}, sensor_period_s=0.005)
    assert not ov["late_explained"] and ov["late"][0].endswith("which does not account for these idle ticks")
    assert overload(agents(0), world, watch_idle=("2",))["late_explained"]  # nothing idle: nothing to account for
