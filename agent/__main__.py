"""python -m agent --topology F --id I [--connect ENDPOINT ...]: one agent process.

Declares its subscriptions, then its liveliness token, waits for the world's
start announcement, and steps on its own clock until the run ends, the world
stays away longer than ``--world-grace`` (a crash; a network partition shorter
than that is ridden out and the agent re-joins), or SIGINT/SIGTERM.
"""

from __future__ import annotations

import argparse
import sys
import threading
from typing import Any

from agent.runtime import AgentNode, run_realtime
from zswarm.scenario.clock import WallClock
from zswarm.scenario.programs import agent_program
from zswarm.transport import keys, procutil, run_control, wire
from zswarm.transport.bus import ZenohBus


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = procutil.ArgumentParser(prog="python -m agent", description=__doc__.splitlines()[0])
    p.add_argument("--topology", required=True, help="scenario TOML file")
    p.add_argument("--id", type=int, required=True, help="agent id in the scenario")
    procutil.add_run_args(p)
    p.add_argument("--startup-timeout", type=procutil.positive_float, default=120.0, help="give up if no start within this many s")
    p.add_argument("--world-grace", type=procutil.positive_float, default=10.0, help="s to go on after the world's token is lost before stopping (default 10)")
    procutil.add_zenoh_args(p)
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    procutil.die_with_parent()
    args = parse(argv)
    sc = procutil.load_or_exit(args.topology)
    if args.id not in sc.ids:
        procutil.fail_usage(f"--id: no agent {args.id} in {args.topology} (ids: {list(sc.ids)})")
    conf = procutil.zenoh_conf(args, f"agent-{args.id}")
    log = procutil.setup_logging(f"agent-{args.id}")
    run = keys.check_run_id(args.run_id)
    seed = sc.seed if args.seed is None else args.seed
    program = agent_program(sc, args.id, seed)  # all this process runs on (it keeps nothing else of the scenario)
    del sc
    clock: list[WallClock] = []
    started = threading.Event()
    start: dict[str, Any] = {}
    world_seen = threading.Event()

    ignored_ctl = [0]  # malformed or foreign control messages, dropped

    def on_start(key: str, payload: bytes) -> None:
        if started.is_set():
            return
        try:
            start.update(run_control.decode_ctl(payload, "start"))
        except wire.MessageError as exc:
            ignored_ctl[0] += 1
            log.warning("ignored malformed start on %s: %s", key, exc)
            return
        started.set()

    def on_stop(key: str, payload: bytes) -> None:
        try:
            run_control.decode_ctl(payload, "stop")
        except wire.MessageError as exc:
            ignored_ctl[0] += 1
            if ignored_ctl[0] <= 3:
                log.warning("ignored malformed stop on %s: %s", key, exc)
            return
        stop.set()

    lost: list[threading.Timer] = []
    # Set once this agent's run is over (its duration reached; `stop` covers the world's stop and signals):
    # the world's token going then is the end of the run, not a loss.
    ended = threading.Event()

    def world_gone() -> None:
        log.warning("the world did not come back within %g s: stopping", args.world_grace)
        stop.set()

    def run_over() -> bool:
        """The run's duration is reached on the run's clock (the world's, too): the world's
        token going then is the world stopping at the end, even if this agent, behind its
        schedule on a loaded machine, has not yet taken its last step or seen the stop."""
        return ended.is_set() or stop.is_set() or bool(clock) and clock[0].now() >= start["duration"]

    def on_world(key: str, up: bool) -> None:
        if up:
            if lost:
                lost.pop().cancel()
                log.info("the world is back")
            world_seen.set()
        elif world_seen.is_set() and not lost and not run_over():
            # A crash, or a partition of the network (this host's link down longer than
            # the lease): go on, on this agent's own clock, for the world to come back.
            log.warning("lost the world's token: going on for up to %g s for it to come back", args.world_grace)
            timer = threading.Timer(args.world_grace, world_gone)
            timer.daemon = True
            lost.append(timer)
            timer.start()

    with ZenohBus(conf) as bus:
        # Handlers only once the session is open: until then SIGTERM's default
        # action ends the process at once, even inside a connect wait.
        stop = procutil.stop_on_signals()
        node = AgentNode(program, bus, run, now=lambda: clock[0].now() if clock else 0.0, inc=procutil.incarnation())
        node.run_over = run_over
        bus.subscribe(keys.ctl(run, "start"), on_start)
        bus.subscribe(keys.ctl(run, "stop"), on_stop)
        bus.watch_alive(keys.alive(run, "world", 0), on_world)
        node.counters()  # once: what the stats at t = 1 s cost the first time is paid here
        procutil.warm_up()
        bus.declare_token(keys.alive(run, "agent", args.id))
        log.info("ready on run %r, waiting for start", run)
        waited = 0.0
        while not started.wait(0.2):
            waited += 0.2
            if stop.is_set():
                return 0
            if waited > args.startup_timeout:
                log.error("no start within %.0f s", args.startup_timeout)
                return 1
        clock.append(WallClock(start["epoch"], start["time_scale"]))
        log.info("started: time scale %g, duration %g s", start["time_scale"], start["duration"])
        try:
            run_realtime(node, clock[0].now, lambda t: clock[0].sleep_until(t, stop), start["duration"])
        finally:
            ended.set()
        # Final stats only on a clean exit: a crashed agent published them from `finally` and
        # a manual run reported it alive at the end.
        node.publish_stats(min(clock[0].now(), start["duration"]), final=True)
        c = node.counters()
        log.info("stopped after %d steps (%.2f Hz, %d missed deadlines)", c["steps"], c["step_rate_hz"], c["missed_deadlines"])
        procutil.confirm_final(bus, keys.recorded(run, "agent", args.id), log)
    return 0


if __name__ == "__main__":
    sys.exit(main())
