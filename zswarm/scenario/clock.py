"""Clocks: world time on the wall clock (time-scaled), a virtual clock, agents' own clocks.

*World time* ``t`` is the simulated time of the run, 0 at the common epoch.
``WallClock`` maps it to the wall clock: ``t = (unix_time - epoch) * time_scale``.
An agent's *own clock* reads ``(1 + drift_ppm·1e-6)·t + offset``; the agent
schedules its ticks and measures its ``dt`` on that clock only.
"""

from __future__ import annotations

import threading
import time
from typing import Annotated, Any, Protocol

import msgspec
import numpy as np

from zswarm.scenario.reading import _Ctx
from zswarm.scenario.schema import Table, bounds

# An agent's own clock reads (1 + drift)·t + offset and stamps its messages (t_local): past
# ±1e10 s a double resolves it to no better than 2 µs, and 2e12 put every message beyond the
# wire's ±MAX_ABS (all dropped, exit 0); 1e300 froze the clock (t + dt == t: sim hung).
MAX_CLOCK_OFFSET_S = 1e10


class ClockSpec(Table, frozen=True, kw_only=True):
    """An agent's clock: tick rate on its own clock, tick jitter, drift and offset; the
    scenario's ``[clock]`` and an agent's ``[agents.clock]``, as the file declares them."""

    rate: Annotated[float, bounds(positive=True, maxv=10000.0)] = 100.0  # Hz
    jitter: Annotated[float, bounds(nonneg=True)] = 0.0  # s, standard deviation of each tick's wake-up time
    drift_ppm: Annotated[float, bounds(within=1e5, within_open=True, unit=" ppm")] = 0.0  # own clock runs (1 + drift_ppm·1e-6) times world time
    offset: Annotated[float, bounds(within=MAX_CLOCK_OFFSET_S, unit=" s", why="the own clock's resolution stays under 2 µs")] = 0.0  # s, own clock reading at world time 0


def _clock(c: _Ctx, d: Any, f: str, base: ClockSpec) -> ClockSpec:
    """``[clock]`` (``base``: the defaults) or an agent's ``[agents.clock]`` (``base``: the scenario's)."""
    spec = c.typed(d, f, ClockSpec, msgspec.structs.asdict(base))
    # A bound that depends on another field: jitter under half the period.
    if spec.jitter >= 0.5 / spec.rate:
        raise c.err(f"{f}.jitter", f"must be < half the period ({0.5 / spec.rate:g} s)", spec.jitter)
    return spec


class Clock(Protocol):
    def now(self) -> float:
        """Current world time, s."""
        ...


class WallClock:
    """World time on this host's wall clock, started at ``epoch`` (Unix seconds)."""

    def __init__(self, epoch: float, time_scale: float = 1.0) -> None:
        if time_scale <= 0:
            raise ValueError(f"time_scale must be > 0 (got {time_scale})")
        self.epoch = epoch
        self.time_scale = time_scale
        # Monotonic base fixed once, so an NTP step mid-run does not move world time.
        self._mono_epoch = time.monotonic() + (epoch - time.time())

    def now(self) -> float:
        return (time.monotonic() - self._mono_epoch) * self.time_scale

    def wall_delay(self, t: float) -> float:
        """Wall seconds until world time ``t`` (negative if past)."""
        return (self._mono_epoch + t / self.time_scale) - time.monotonic()

    def sleep_until(self, t: float, stop: threading.Event) -> bool:
        """Sleep until world time ``t``; return False if ``stop`` was set meanwhile."""
        while True:
            d = self.wall_delay(t)
            if d <= 0:
                return not stop.is_set()
            if stop.wait(min(d, 0.5)):
                return False


class ManualClock:
    """A clock the caller sets: the virtual clock of ``zswarm sim`` and of tests."""

    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def now(self) -> float:
        return self.t

    def set(self, t: float) -> None:
        self.t = t


class AgentClock:
    """An agent's own clock and tick schedule (rate, jitter, drift, offset).

    Ticks are nominally every ``1/rate`` s *of the agent's own clock*; each
    wake-up is perturbed by zero-mean Gaussian jitter (std ``jitter``, clipped
    to ±0.45 period so ticks stay ordered).  The schedule is a pure function
    of the spec and seed, so ``sim`` and ``run`` use the same tick times.
    """

    def __init__(self, spec: ClockSpec, seed: int) -> None:
        self.spec = spec
        self.scale = 1.0 + spec.drift_ppm * 1e-6
        self.is_identity = self.scale == 1.0 and spec.offset == 0.0  # local(t) == t exactly
        self.period = 1.0 / spec.rate
        self._seed = seed
        self.k = 0

    def local(self, t_world: float) -> float:
        """The agent's own clock reading at world time ``t_world``."""
        return self.scale * t_world + self.spec.offset

    def world(self, t_local: float) -> float:
        return (t_local - self.spec.offset) / self.scale

    def first_tick(self, t_world_start: float) -> float:
        """World time of the first tick at or after ``t_world_start``; resets the schedule."""
        loc = self.local(t_world_start)
        self.k = int(np.ceil(loc / self.period - 1e-9))
        return self._tick_world(self.k)

    def next_tick(self, t_world_now: float) -> tuple[float, int]:
        """World time of the next tick after the current one, and how many were skipped.

        Ticks whose time already passed at ``t_world_now`` (the process was
        late by more than a period) are skipped and counted as missed.
        """
        self.k += 1
        missed = 0
        while self._tick_world(self.k) < t_world_now - self.period / self.scale:
            self.k += 1
            missed += 1
        return self._tick_world(self.k), missed

    def _tick_world(self, k: int) -> float:
        j = 0.0
        if self.spec.jitter > 0:
            # One draw per tick index, reproducible however the ticks are visited.
            j = float(np.clip(np.random.default_rng([k % (1 << 63), self._seed % (1 << 63)]).normal(0.0, self.spec.jitter), -0.45 * self.period, 0.45 * self.period))
        return self.world(k * self.period + j)
