"""PrescribedMotion.plan (issue 28): ω_i(t) and v_i(t) evaluated for many world samples in
one call per expression give the truth of evaluating them sample by sample, bit for bit
(the same midpoints by the same float operations; numpy's elementwise functions give an
element the same value in an array of any length).  Bit for bit, not a tolerance: the
plan is a change of bookkeeping, not of the integration."""

from __future__ import annotations

import numpy as np
import pytest

from world.motion import PrescribedMotion
from zswarm.math.so3 import exp
from zswarm.scenario.expr import parse

OMEGA = [["-cos(2*t)", "sin(9*t)", "1"], ["sqrt(1+t)", "abs(sin(3*t))**1.5", "tan(0.1*t)"], ["exp(-t)", "2", "-t/3"]]
VEL = [["cos(t)", "0", "0.5"], None, ["t**2/10", "sin(t)", "-1"]]


def _motion(velocity: bool, formation: bool = False) -> PrescribedMotion:
    R0 = np.stack([exp(np.array([0.1 * k, -0.2, 0.3])) for k in range(3)])
    p0 = np.array([[0.0, 0, 0], [1, 2, 3], [-1, 0, 2]])
    omega = [[parse(e) for e in w] for w in OMEGA]
    vel = [None if v is None else [parse(e) for e in v] for v in VEL] if velocity else None
    return PrescribedMotion(R0, p0, omega, 0.001, formation=(np.array([0.0, 0, 1]), 0.5) if formation else None, velocity=vel)


@pytest.mark.parametrize("velocity, formation", [(False, False), (True, False), (False, True)])
def test_planned_samples_are_the_unplanned_ones_bit_for_bit(velocity, formation):
    period = 1.0 / 200
    a, b = _motion(velocity, formation), _motion(velocity, formation)
    for k in range(1, 700):
        t = k * period
        if k % 150 == 1:  # as World.sample plans: the next samples from here
            a.plan(np.arange(k, k + 150) * period)
            assert len(a._planned) == 150  # every interval planned: the comparison below is not of two unplanned runs
        a.advance_to(t)
        b.advance_to(t)
        assert a.R.tobytes() == b.R.tobytes() and a.p.tobytes() == b.p.tobytes(), k
        assert a.omega_now().tobytes() == b.omega_now().tobytes(), k
        assert a.velocity().tobytes() == b.velocity().tobytes(), k


def test_a_grid_the_step_does_not_divide_is_left_unplanned():
    """Samples every 0.0015 s with a 1 ms step end each interval with a part step: the
    plan takes none of them and each is computed as it comes (same result)."""
    a, b = _motion(True), _motion(True)
    a.plan(np.arange(1, 50) * 0.0015)
    assert not a._planned
    for k in range(1, 50):
        a.advance_to(k * 0.0015)
        b.advance_to(k * 0.0015)
    assert a.R.tobytes() == b.R.tobytes() and a.p.tobytes() == b.p.tobytes()
