"""python -m world --topology F [--connect ENDPOINT ...]: the world process.

Waits until every agent of the scenario (and, with --wait-for-recorder, the
recorder) holds its liveliness token, announces a common epoch, then samples
the truth and publishes sensor packets on the wall clock until the duration.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time

from world.node import World
from zswarm.scenario.clock import WallClock
from zswarm.scenario.programs import world_program
from zswarm.transport import keys, procutil, run_control
from zswarm.transport.bus import ZenohBus

START_LEAD_S = 0.5  # wall seconds between the start announcement and the epoch
# How late a sample may still be taken rather than skipped.  A busy machine stops the world
# now and then: beside `stress-ng --cpu 1`, §3.2 at time scale 1 (2026-12-03, two runs of
# 40 s) woke more than one 5 ms period late 288 and 207 times, more than two periods late 6
# and 3 times (at most 4.7); and once in CI every process of a §3.3 run stood still for
# ~85 ms (every agent missed 7 ticks, the world 17 samples).  A skipped sample is a hole in
# the agents' gyro and bearing history that no catch-up fills: the 85 ms hole (reproduced
# by SIGSTOPping the world alone for 85 ms at t = 27 s) left agents 4 and 5 of §3.3 (a
# weakly observable direction) a final attitude error of 5-9e-5 against 2.6e-6 without it (CI's
# run: 2.6e-4).  The sensors of the simulated system do not stop when the simulator does:
# up to CATCH_UP_S behind, the world takes every missed sample (at its own time, with its
# own noise draw), and the agents get them late, as if delayed on the link, with nothing
# missing.  Further behind (an overloaded machine, not a stall) it skips to the newest due
# sample instead of bursting through an ever longer backlog.  0.1 s is the report's bound
# for a truth gap (report.TRUTH_GAP_S); 20 samples at 200 Hz cost the world ~5 ms.
CATCH_UP_S = 0.1
CATCH_UP_PERIODS = 2.0  # at least this many periods (a sensor rate below 20 Hz)


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = procutil.ArgumentParser(prog="python -m world", description=__doc__.splitlines()[0])
    p.add_argument("--topology", required=True, help="scenario TOML file")
    procutil.add_run_args(p)
    p.add_argument("--duration", type=procutil.positive_float, default=None, help="world seconds (default: the scenario's)")
    p.add_argument("--time-scale", type=procutil.positive_float, default=1.0, help="world seconds per wall second (default 1)")
    p.add_argument("--wait-for-recorder", action="store_true", help="also wait for the recorder's token before starting")
    p.add_argument("--startup-timeout", type=procutil.positive_float, default=120.0, help="give up if the others are not alive within this many s")
    procutil.add_zenoh_args(p)
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    procutil.die_with_parent()
    args = parse(argv)
    sc = procutil.load_or_exit(args.topology)
    conf = procutil.zenoh_conf(args, "world")
    log = procutil.setup_logging("world")
    seed = sc.seed if args.seed is None else args.seed
    duration = sc.duration if args.duration is None else args.duration
    run = keys.check_run_id(args.run_id)
    program = world_program(sc, seed)  # all this process runs on (it keeps nothing else of the scenario)
    del sc
    with ZenohBus(conf) as bus:
        # Handlers only once the session is open: until then SIGTERM's default
        # action ends the process at once, even inside a connect wait.
        stop = procutil.stop_on_signals()
        world = World(program, bus, run, inc=procutil.incarnation())
        pub_start = bus.publisher(keys.ctl(run, "start"))
        pub_stop = bus.publisher(keys.ctl(run, "stop"), block=True)  # sent once: wait rather than drop
        pub_progress = bus.publisher(keys.ctl(run, "progress"))
        alive: set[tuple[str, int]] = set()
        changed = threading.Event()

        def on_alive(key: str, up: bool) -> None:
            who = keys.parse_alive(key)
            if who:
                (alive.add if up else alive.discard)(who)
                changed.set()

        bus.watch_alive(keys.alive_all(run), on_alive)
        world.counters()  # once: see procutil.warm_up
        procutil.warm_up()
        bus.declare_token(keys.alive(run, "world", 0))
        need = {("agent", i) for i in program.ids} | ({("recorder", 0)} if args.wait_for_recorder else set())
        deadline = time.monotonic() + args.startup_timeout
        log.info("waiting for %d processes on run %r", len(need), run)
        while not need <= alive:
            if stop.is_set():
                return 0
            if time.monotonic() > deadline:
                log.error("not alive after %.0f s: %s", args.startup_timeout, sorted(need - alive))
                return 1
            changed.wait(0.2)
            changed.clear()
        epoch = time.time() + START_LEAD_S / 1.0
        clock = WallClock(epoch, args.time_scale)
        world.now = clock.now  # command arrivals are stamped in world time
        start = run_control.encode_ctl("start", 0, 0, 0.0, inc=world.inc, epoch=epoch, time_scale=args.time_scale, duration=duration, seed=seed, run=run)
        pub_start.put(start)
        log.info("start: epoch %.3f, time scale %g, duration %g s", epoch, args.time_scale, duration)
        next_announce = time.monotonic() + 1.0
        n_progress = 0  # the progress messages' own sequence (a loss count reads the gaps)
        reason = "duration"
        while True:
            t = world.next_time()
            if t > duration + 1e-9:
                break
            if not clock.sleep_until(t, stop):
                reason = "signal"
                break
            now = clock.now()
            if now - t > max(CATCH_UP_S, CATCH_UP_PERIODS * world.period):
                world.skip_to(now)
                if world.next_time() > duration + 1e-9:
                    break
            world.lateness(now - world.next_time())
            world.sample()
            if world.k % max(1, round(program.sensor_rate)) == 0:
                world.publish_stats(t)
            if time.monotonic() >= next_announce:
                # Re-announce so that a late (re)started process can join the run.
                pub_start.put(start)
                pub_progress.put(run_control.encode_ctl("progress", 0, n_progress, t, inc=world.inc, duration=duration))
                n_progress += 1
                next_announce += 0.5
        end_t = min(clock.now(), duration)
        world.publish_stats(end_t, final=True)
        pub_stop.put(run_control.encode_ctl("stop", 0, 0, end_t, inc=world.inc, reason=reason))
        log.info("stopped (%s) at t = %.3f s after %d samples, %d late", reason, end_t, world.samples, world.late)
        # Asked after the stop: once the recorder answers, the router has passed the stop on too.
        if not procutil.confirm_final(bus, keys.recorded(run, "world", 0), log):
            time.sleep(0.1)  # no recorder: give the stop message time to leave before the session closes
    return 0


if __name__ == "__main__":
    sys.exit(main())
