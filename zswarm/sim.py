"""``zswarm sim``: the very same World and AgentNode objects in one process.

A MemoryBus and a virtual clock: events (sensor samples, agent ticks) are
processed in time order, ties broken world first then by agent id, so a seed
gives bit-identical results.  Runs as fast as the CPU allows.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable
from pathlib import Path

from agent.runtime import AgentNode
from world.node import World
from zswarm import keys, wire
from zswarm.bus import MemoryBus
from zswarm.record import Recorder
from zswarm.scenario import Scenario

LEAN_SKIP = ("sense/", "edge/", "cmd/")


def simulate(
    scenario: Scenario,
    out_dir: Path,
    duration: float,
    seed: int,
    run: str = "sim",
    progress: Callable[[float], None] | None = None,
    kill: dict[int, float] | None = None,
    lean: bool = False,
    record: bool = True,
) -> Path | list[tuple[str, bytes, int]]:
    """Run ``scenario`` for ``duration`` s of world time; return the recording path.

    ``kill`` maps agent ids to world times at which that agent stops (as if
    its process died): its token is withdrawn and it never ticks again.
    ``lean`` leaves the sensor and edge messages out of the recording (a
    quarter of the size; the report needs only truth, estimates and stats).
    ``record=False`` writes no file and returns the recorded messages
    (``(channel, payload, log_time_ns)``, what :func:`zswarm.record.read` yields).
    """
    bus = MemoryBus()
    t_now = [0.0]
    rec_path = out_dir / "recording.mcap"
    recorder = Recorder(
        bus,
        run,
        rec_path if record else None,
        now_ns=lambda: int(round(t_now[0] * 1e9)),
        metadata={"engine": "sim", "scenario": scenario.name},
        skip=LEAN_SKIP if lean else (),
        scenario=scenario,
    )
    world = World(scenario, bus, run, seed, now=lambda: t_now[0])
    agents = {i: AgentNode(scenario, i, bus, run, seed, now=lambda: t_now[0]) for i in scenario.ids}
    ctl_start = bus.publisher(keys.ctl(run, "start"))
    ctl_stop = bus.publisher(keys.ctl(run, "stop"))
    bus.declare_token(keys.alive(run, "world", 0))
    for i in agents:
        bus.declare_token(keys.alive(run, "agent", i))
    ctl_start.put(wire.encode("start", 0, 0, 0.0, epoch=0.0, time_scale=0.0, duration=duration, seed=seed, run=run))

    # (time, priority, id): world samples have priority 0, agent ticks 1.
    queue: list[tuple[float, int, int]] = [(world.next_time(), 0, 0)]
    for i, a in agents.items():
        queue.append((a.clock.first_tick(0.0), 1, i))
    heapq.heapify(queue)
    kill = dict(kill or {})
    next_flush = 1.0
    next_stats = {i: 1.0 for i in agents}
    while queue:
        t, prio, who = heapq.heappop(queue)
        if t > duration + 1e-9:
            break
        for i, tk in list(kill.items()):
            if tk <= t:
                bus.undeclare_token(keys.alive(run, "agent", i))
                agents[i].publish_stats(tk)
                del kill[i]
                agents.pop(i)
        t_now[0] = t
        if prio == 0:
            world.sample()
            if world.k % max(1, round(scenario.sensor_rate)) == 0:
                world.publish_stats(t)
            heapq.heappush(queue, (world.next_time(), 0, 0))
        elif who in agents:
            a = agents[who]
            a.tick(t)
            if t >= next_stats[who]:
                a.publish_stats(t)
                next_stats[who] += 1.0
            tn, missed = a.clock.next_tick(t)
            a.missed += missed
            heapq.heappush(queue, (tn, 1, who))
        if t >= next_flush:
            recorder.flush()
            next_flush += 1.0
            if progress:
                progress(t)
    t_now[0] = duration
    ctl_stop.put(wire.encode("stop", 0, 0, duration, reason="duration"))
    world.publish_stats(duration, final=True)
    for a in agents.values():
        a.publish_stats(duration, final=True)
    bus.declare_token(keys.alive(run, "recorder", 0))
    recorder.close()
    bus.close()
    return rec_path if record else recorder.messages
