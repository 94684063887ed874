import numpy as np
import pytest

from zswarm.scenario import ClockSpec
from zswarm.scenario.clock import AgentClock, ManualClock


def test_drift_and_offset_map_world_to_own_clock():
    c = AgentClock(ClockSpec(rate=100.0, drift_ppm=500.0, offset=0.25), seed=1)
    assert c.local(10.0) == pytest.approx(10.0 * 1.0005 + 0.25, abs=1e-12)
    assert c.world(c.local(3.7)) == pytest.approx(3.7, abs=1e-12)
    # Ticks are evenly spaced on the own clock, so 1/(rate·(1+drift)) apart in world time.
    t0 = c.first_tick(0.0)
    t1, missed = c.next_tick(t0)
    assert missed == 0 and t1 - t0 == pytest.approx(0.01 / 1.0005, rel=1e-9)


def test_jitter_is_bounded_zero_mean_and_reproducible():
    spec = ClockSpec(rate=100.0, jitter=0.002)
    a, b = AgentClock(spec, seed=7), AgentClock(spec, seed=7)
    ta = [a.first_tick(0.0)] + [a.next_tick(0.0)[0] for _ in range(2000)]
    tb = [b.first_tick(0.0)] + [b.next_tick(0.0)[0] for _ in range(2000)]
    assert ta == tb
    dev = np.array(ta) - 0.01 * np.arange(len(ta))
    assert np.all(np.abs(dev) <= 0.45 * 0.01 + 1e-12)
    assert abs(dev.mean()) < 3 * 0.002 / np.sqrt(len(dev))  # 3 standard errors
    assert dev.std() == pytest.approx(0.002, rel=0.1)
    assert np.all(np.diff(ta) > 0)


def test_late_wakeup_skips_and_counts_missed_ticks():
    c = AgentClock(ClockSpec(rate=100.0), seed=0)
    c.first_tick(0.0)
    t, missed = c.next_tick(0.055)  # woke 55 ms late: ticks at 10..40 ms are gone
    assert missed == 4 and t == pytest.approx(0.05)


def test_manual_clock():
    m = ManualClock()
    m.set(2.5)
    assert m.now() == 2.5
