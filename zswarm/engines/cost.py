"""What a run would cost before it starts: CPU time estimated from its world steps and agent
ticks, and the refusal of one far beyond reason (``zswarm sim`` and ``zswarm run``;
``--allow-long`` runs it anyway).

A scenario with ``world.step = 1e-6`` and ``duration = 1e5`` (1e11 world steps) started
silently and ran until killed.
"""

from __future__ import annotations

from zswarm.scenario import Scenario
from zswarm.transport import procutil

# CPU per agent per world step, and per agent tick (its step, messages, sensor packets and the
# recorder's share), on ``zswarm sim``: a linear fit to sims of 4 s at world.step 1e-3, 1e-4 and
# 1e-5 (time.process_time, 2026-12-07, this 2-core machine shared with other work):
#   §3.3 moving5 (prescribed motion)   0.29 µs a step, 0.21 ms a tick
#   §5.6 hybrid7 (rigid-body dynamics) 0.73 µs a step, 0.20 ms a tick
#   §3.2 fixed8 (prescribed motion)    0.21 µs a step, 0.16 ms a tick
# The smallest of each, rounded down: the estimate is a floor of what the run costs (a real run's
# processes cost more a tick than sim: Zenoh, decoding), so a run refused would take at least that.
CPU_PER_AGENT_STEP_S = 0.2e-6
CPU_PER_TICK_S = 0.15e-3

# Refused beyond a day of one core: far beyond any run of the thesis' scenarios (§5.6's 150 s
# is ~40 s of CPU) or a sweep's run, and still a run a user may ask for with --allow-long.  The
# case that ran until killed (1e11 steps of 5 agents) is at least 30 h by this floor; §3.2 for
# 1e5 s at its own step (tests/component/test_cli_interrupt.py interrupts one) is 3.4 h.
MAX_CPU_S = 24 * 3600.0


def estimate_cpu_s(sc: Scenario, duration: float) -> tuple[float, float, float]:
    """``(cpu_s, world_steps, agent_ticks)`` of a run of ``sc`` for ``duration`` world seconds:
    a floor of its CPU time (see CPU_PER_AGENT_STEP_S), the truth's steps (at least one per
    sensor sample) and the agents' ticks over the run."""
    steps = duration * max(1.0 / sc.step, sc.sensor_rate)
    ticks = duration * sum(a.clock.rate for a in sc.agents)
    return steps * len(sc.agents) * CPU_PER_AGENT_STEP_S + ticks * CPU_PER_TICK_S, steps, ticks


def _hours(s: float) -> str:
    return f"{s / 3600:.3g} h" if s < 1e6 * 3600 else f"{s / (365.25 * 86400):.3g} years"


def too_long(sc: Scenario, duration: float | None) -> str | None:
    """Why a run of ``sc`` for ``duration`` (from ``--duration``; None: the scenario's) is beyond
    reason (more than MAX_CPU_S of CPU), in one line naming its cost; None when it is not."""
    where = f"scenario.duration = {sc.duration:g} s" if duration is None else f"--duration {duration:g}"
    cpu, steps, ticks = estimate_cpu_s(sc, sc.duration if duration is None else duration)
    if cpu <= MAX_CPU_S:
        return None
    return (
        f"{where} at world.step = {sc.step:g} s is {steps:.3g} world steps for {len(sc.agents)} agents and {ticks:.3g} agent ticks: "
        f"at least {_hours(cpu)} of CPU, over the {_hours(MAX_CPU_S)} zswarm starts without --allow-long"
    )


def refuse_if_too_long(sc: Scenario, path: str, duration: float | None, allow: bool) -> None:
    """Exit 2 with :func:`too_long`'s line (the file ``path`` named) when a run of ``sc`` for
    ``duration`` is beyond reason, unless ``allow`` (``--allow-long``)."""
    why = None if allow else too_long(sc, duration)
    if why is not None:
        procutil.fail_usage(f"{path}: {why} (pass it to run this anyway)")
