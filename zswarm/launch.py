"""``zswarm run``: an embedded router, the recorder, the world and one process per agent.

Children are started with ``start_new_session=True`` (their own process
group), so a terminal Ctrl-C reaches only the launcher, which then stops
them in order: world and agents first, the recorder last so that it records
the end.  Every child is reaped, by PID, whatever happens.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from zswarm import keys, procutil, report, wire
from zswarm.bus import ZenohBus, zenoh_config
from zswarm.scenario import Scenario


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def results_dir(out: Path | None, name: str, base: Path = Path("runs")) -> Path:
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        return out
    stamp = time.strftime("%Y%m%d-%H%M%S")
    d = base / f"{name}-{stamp}"
    n = 1
    while d.exists():
        n += 1
        d = base / f"{name}-{stamp}-{n}"
    d.mkdir(parents=True)
    return d


@dataclass
class Child:
    name: str
    role: str
    ident: int
    proc: subprocess.Popen[bytes]
    log: IO[bytes]
    exit_code: int | None = None


@dataclass
class Launch:
    sc: Scenario
    topology: str
    out: Path
    duration: float
    time_scale: float
    seed: int
    quiet: bool = False
    children: list[Child] = field(default_factory=list)

    def spawn(self, name: str, role: str, ident: int, cmd: list[str]) -> Child:
        logf = open(self.out / "logs" / f"{name}.log", "wb")  # noqa: SIM115 - closed in reap()
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        if self.sc.module_dir:
            # A user's algorithm module found beside the scenario file: the children read
            # the results folder's copy of the scenario, so they need that folder too.
            env["PYTHONPATH"] = os.pathsep.join(p for p in (self.sc.module_dir, env.get("PYTHONPATH", "")) if p)
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=logf, stderr=subprocess.STDOUT, start_new_session=True, env=env)
        c = Child(name, role, ident, proc, logf)
        self.children.append(c)
        return c

    def signal_all(self, sig: int, roles: tuple[str, ...]) -> None:
        for c in self.children:
            if c.role in roles and c.proc.poll() is None:
                try:
                    os.kill(c.proc.pid, sig)
                except ProcessLookupError:
                    pass

    def wait_all(self, roles: tuple[str, ...], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        for c in self.children:
            if c.role not in roles:
                continue
            left = deadline - time.monotonic()
            try:
                c.proc.wait(max(0.0, left))
            except subprocess.TimeoutExpired:
                return False
        return True

    def stop_all(self, graceful: bool) -> None:
        """Stop every child in order (world+agents, then recorder), escalating to SIGKILL."""
        for roles, t in ((("world", "agent"), 3.0), (("recorder",), 5.0)):
            if graceful:
                # A normal end: they stop by themselves; only nudge the late ones.
                if not self.wait_all(roles, t):
                    self.signal_all(signal.SIGTERM, roles)
            else:
                self.signal_all(signal.SIGINT, roles)
            if not self.wait_all(roles, t):
                self.signal_all(signal.SIGKILL, roles)
                self.wait_all(roles, 2.0)

    def reap(self) -> None:
        for c in self.children:
            if c.proc.poll() is None:
                c.proc.kill()
            c.exit_code = c.proc.wait()
            c.log.close()


def run(
    topology: str,
    sc: Scenario,
    out_base: Path | None,
    duration: float | None,
    time_scale: float,
    seed: int | None,
    quiet: bool = False,
    startup_timeout: float = 60.0,
    live: tuple[str, int] | None = None,
) -> int:
    """Run the scenario over real processes; return the exit code for the CLI."""
    duration = sc.duration if duration is None else duration
    seed = sc.seed if seed is None else seed
    out = results_dir(out_base, sc.name)
    (out / "logs").mkdir(exist_ok=True)
    # Every process reads the scenario as run (with any --set applied) from the results folder.
    (out / "scenario.toml").write_text(sc.text, encoding="utf-8")
    topology = str(out / "scenario.toml")
    run_id = keys.check_run_id(f"r{os.getpid()}-{int(time.time())}")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    la = Launch(sc, topology, out, duration, time_scale, seed, quiet)
    interrupted = threading.Event()
    on_signals = procutil.SignalEvent(interrupted)

    def say(msg: str) -> None:
        if not quiet:
            print(msg, file=sys.stderr, flush=True)

    common = ["--run-id", run_id, "--seed", str(seed), "--connect", endpoint]
    py = sys.executable
    ok_start = False
    try:
        with ZenohBus(zenoh_config("router", listen=[endpoint])) as bus:
            alive: set[tuple[str, int]] = set()
            progress = [0.0]

            def on_alive(key: str, up: bool) -> None:
                who = keys.parse_alive(key)
                if who:
                    (alive.add if up else alive.discard)(who)

            def on_progress(key: str, payload: bytes) -> None:
                try:
                    progress[0] = wire.decode(payload, "progress")["t"]
                except wire.MessageError:
                    pass

            bus.watch_alive(keys.alive_all(run_id), on_alive)
            bus.subscribe(keys.ctl(run_id, "progress"), on_progress)
            say(f"zswarm run: {sc.name}: router on {endpoint}, results in {out}")
            live_args = [] if live is None else ["--live", f"{live[0]}:{live[1]}"]
            la.spawn("recorder", "recorder", 0, [py, "-m", "zswarm", "record", topology, "--out", str(out), "--no-report", *live_args, *common])
            if live is not None:
                say(f"zswarm run: live view on ws://{live[0]}:{live[1]} (Foxglove or Lichtblick: open connection, Foxglove WebSocket)")
            for i in sc.ids:
                la.spawn(f"agent-{i}", "agent", i, [py, "-m", "agent", "--topology", topology, "--id", str(i), *common])
            la.spawn(
                "world",
                "world",
                0,
                [py, "-m", "world", "--topology", topology, "--duration", str(duration), "--time-scale", str(time_scale), "--wait-for-recorder", *common],
            )
            (out / "processes.json").write_text(
                json.dumps(
                    {
                        "router": {"pid": os.getpid(), "endpoint": endpoint},
                        "run_id": run_id,
                        "children": [{"name": c.name, "role": c.role, "id": c.ident, "pid": c.proc.pid} for c in la.children],
                    },
                    indent=2,
                )
            )
            need = {(c.role, c.ident) for c in la.children}
            deadline = time.monotonic() + startup_timeout
            while not need <= alive:
                dead = [c.name for c in la.children if c.proc.poll() is not None]
                if dead or interrupted.is_set() or time.monotonic() > deadline:
                    why = (
                        f"exited during start-up: {', '.join(dead)}"
                        if dead
                        else ("interrupted" if interrupted.is_set() else f"not alive after {startup_timeout:.0f} s: {sorted(need - alive)}")
                    )
                    say(f"zswarm run: {why} (logs in {out / 'logs'})")
                    la.stop_all(graceful=False)
                    return 1
                time.sleep(0.05)
            ok_start = True
            say(f"zswarm run: {len(la.children)} processes alive; running {duration:g} s of world time at time scale {time_scale:g}")
            world = next(c for c in la.children if c.role == "world")
            last_print = 0.0
            tty = sys.stderr.isatty()
            while world.proc.poll() is None and not interrupted.is_set():
                time.sleep(0.1)
                now = time.monotonic()
                if not quiet and (tty or now - last_print > 5.0):
                    n_alive = sum(1 for r, _ in alive if r == "agent")
                    line = f"t = {progress[0]:6.1f} / {duration:g} s   agents alive: {n_alive}/{len(sc.ids)}"
                    print(("\r" + line) if tty else line, end="" if tty else "\n", file=sys.stderr, flush=True)
                    last_print = now
            if tty and not quiet:
                print(file=sys.stderr)
            if interrupted.is_set():
                say("zswarm run: interrupted, stopping every process")
            la.stop_all(graceful=not interrupted.is_set())
    finally:
        la.reap()
        on_signals.close()
    if not ok_start:
        return 1
    codes: dict[str, int | None] = {c.name: c.exit_code for c in la.children}
    try:
        summary = report.make_report(out, sc, "run", duration, time_scale, seed, exit_codes=codes)
    except ValueError as exc:
        say(f"zswarm run: no report: {exc}")
        return 1
    except Exception as exc:  # noqa: BLE001 - the run is over: keep what it left (recording, logs, exit codes)
        # Counters that pass the wire's bounds may still be what the report did not expect.
        say(f"zswarm run: the report failed ({type(exc).__name__}: {exc}); the recording and logs are in {out}")
        summary = {"report_error": f"{type(exc).__name__}: {exc}", "exit_codes": codes, "interrupted": interrupted.is_set()}
        (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
        return 1
    summary["exit_codes"] = codes
    summary["interrupted"] = interrupted.is_set()
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(report.table(summary))
    print(f"results: {out}")
    return 130 if interrupted.is_set() else 0
