"""Link emulation on ``zswarm sim`` (issue 4): exact on the virtual clock."""

import math

import pytest

from tests.conftest import TOPO
from zswarm.engines.sim import simulate
from zswarm.results import make_report
from zswarm.scenario import loads


def sim_with(tmp_path, links_toml, duration=5.0):
    text = (TOPO / "thesis-3.2-fixed8.toml").read_text() + "\n" + links_toml
    sc = loads(text, "x.toml")
    msgs = simulate(sc, tmp_path, duration, sc.seed, record=False)  # in memory: the report needs no file
    return make_report(tmp_path, sc, "sim", duration, 0.0, sc.seed, plots=False, messages=msgs)


def test_drop_and_delay_are_applied_exactly(tmp_path):
    s = sim_with(
        tmp_path,
        '[links]\ndelay_ms = 50\ndrop = 0.3\n[links.sensors]\ndelay_ms = 50\ndrop = 0.3\n[links.per_link."1->3"]\ndrop = 0.0\n',
    )
    assert len(s["links"]) == 22  # 8 sensor links, 14 edges
    for name, c in s["links"].items():
        p = 0.0 if name == "1->3" else 0.3
        assert abs(c["link_dropped"] / c["offered"] - p) <= 3 * math.sqrt(p * (1 - p) / c["offered"]) + 1e-12, (name, c)
        assert c["applied_delay_p50_ms"] == pytest.approx(50.0)
        assert c["latency_p50_ms"] == pytest.approx(50.0, abs=1e-6)  # on the virtual clock: exactly the applied delay
        # Every loss the receiver sees as a sequence gap is one the link model made;
        # the difference is what it cannot see yet: messages still held at the end
        # (50 ms × 200 Hz = 10 on sensor links) and losses after them.
        assert 0 <= c["link_dropped"] - c["dropped"] <= 20, (name, c)


def test_all_zero_links_reproduce_the_run_without_links(tmp_path):
    """Issue 4: everything zero gives the foundation's results exactly (same estimates, bit for bit)."""
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    sim_with(tmp_path / "a", "", duration=3.0)
    sim_with(tmp_path / "b", "[links]\ndelay_ms = 0\ndrop = 0\njitter_ms = 0\n", duration=3.0)
    assert (tmp_path / "a" / "errors.csv").read_text() == (tmp_path / "b" / "errors.csv").read_text()


def test_links_defaults_are_for_edges_and_sensors_have_their_own(tmp_path):
    s = sim_with(tmp_path, "[links]\ndrop = 0.3\n", duration=2.0)
    for name, c in s["links"].items():
        if name.startswith("world->"):
            assert "offered" not in c and c["dropped"] == 0, (name, c)  # no model on the sensor links
        else:
            assert c["link_dropped"] > 0, (name, c)
