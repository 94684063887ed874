"""report.overload: when a run says it did not keep up."""

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
