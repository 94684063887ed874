"""``zswarm run``: an embedded router, the recorder, the world and one process per agent.

Children are started with ``start_new_session=True`` (their own process
group), so a terminal Ctrl-C reaches only the launcher, which then stops
them in order: world and agents first, the recorder last so that it records
the end.  Every child is reaped, by PID, whatever happens.
"""

from __future__ import annotations

import json
import os
import resource
import secrets
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from zswarm import results
from zswarm.scenario import Fault, Scenario, fault_actions
from zswarm.transport import keys, procutil, run_control, wire
from zswarm.transport import secure as sec
from zswarm.transport.bus import ZenohBus, zenoh_config
from zswarm.util import files
from zswarm.util.quoting import one_line


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def results_dir(out: Path | None, name: str, base: Path = Path("runs")) -> Path:
    """The results folder (``out``, or ``runs/<name>-<stamp>``), made and checked writable
    before anything runs: a read-only folder would otherwise show only at the first write
    (OSError, the caller's one line: cli.main)."""
    if out is not None:
        d = out
        d.mkdir(parents=True, exist_ok=True)
    else:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        d = base / f"{name}-{stamp}"
        n = 1
        while d.exists():
            n += 1
            d = base / f"{name}-{stamp}-{n}"
        d.mkdir(parents=True)
    probe = d / ".zswarm-write-check"
    with open(probe, "wb") as f:
        f.write(b"1")
    probe.unlink()
    return d


@dataclass
class Child:
    name: str
    role: str
    ident: int
    proc: subprocess.Popen[bytes]
    log: IO[bytes]
    exit_code: int | None = None
    cmd: list[str] = field(default_factory=list)
    replaced: bool = False  # killed by a fault (and perhaps restarted as a new child)
    cpu_s: float = 0.0  # user + system CPU time, the last reading of /proc/<pid>/stat (see Launch.sample_cpu)

    def read_cpu(self) -> None:
        """Take ``cpu_s`` from /proc while the process is not reaped (its PID is still its
        own; a zombie's entry holds its total)."""
        if self.proc.returncode is None:
            v = _proc_cpu(self.proc.pid)
            if v is not None:
                self.cpu_s = v


_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def _proc_cpu(pid: int) -> float | None:
    """User + system CPU seconds of ``pid`` from /proc (a zombie's too: its last value); None if gone."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / _TICKS  # utime, stime: fields 14 and 15 of stat
    except (OSError, IndexError, ValueError):
        return None


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
    fault_log: list[dict[str, object]] = field(default_factory=list)  # what the launcher did for [[faults]], when
    endpoint: str = ""
    run_id: str = ""
    cpu: dict[str, Any] = field(default_factory=dict)  # what processes.json says of the CPU (set at the end)

    def sample_cpu(self) -> None:
        """Read each running child's CPU time (the launcher's loop does, every 0.1 s; and
        before each child is reaped, when a zombie's /proc entry still holds its total)."""
        for c in self.children:
            c.read_cpu()

    def write_processes(self, endpoint: str, run_id: str) -> None:
        """results/processes.json: every child ever started (restarts too), by PID."""
        self.endpoint, self.run_id = endpoint, run_id
        (self.out / "processes.json").write_text(
            json.dumps(
                {
                    "router": {"pid": os.getpid(), "endpoint": endpoint},
                    "run_id": run_id,
                    "children": [
                        {"name": c.name, "role": c.role, "id": c.ident, "pid": c.proc.pid} | ({"cpu_s": round(c.cpu_s, 2)} if self.cpu else {}) for c in self.children
                    ],
                }
                | ({"cpu": self.cpu} if self.cpu else {}),
                indent=2,
            )
        )

    def spawn(self, name: str, role: str, ident: int, cmd: list[str], log_name: str | None = None) -> Child:
        logf = open(self.out / "logs" / f"{log_name or name}.log", "wb")  # noqa: SIM115 - closed in reap()
        env = procutil.child_env(dict(os.environ, PYTHONUNBUFFERED="1"))  # dies with this launcher
        if self.sc.module_dir:
            # A user's algorithm module found beside the scenario file: the children read
            # the results folder's copy of the scenario, so they need that folder too.
            env["PYTHONPATH"] = os.pathsep.join(p for p in (self.sc.module_dir, env.get("PYTHONPATH", "")) if p)
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=logf, stderr=subprocess.STDOUT, start_new_session=True, env=env)
        c = Child(name, role, ident, proc, logf, cmd=cmd)
        self.children.append(c)
        return c

    def child(self, role: str, ident: int) -> Child | None:
        """The current process of (role, id): the newest one of that name."""
        return next((c for c in reversed(self.children) if c.role == role and c.ident == ident and not c.replaced), None)

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
            while c.proc.returncode is None and not _exited(c.proc.pid):
                if time.monotonic() >= deadline:
                    return False
                time.sleep(0.01)
            self._reaped(c)
        return True

    def _reaped(self, c: Child) -> None:
        """Reap an exited child, reading its final CPU time first (a zombie keeps it)."""
        c.read_cpu()
        c.proc.wait()

    def stop_all(self, graceful: bool) -> None:
        """Stop every child in order (world+agents, then recorder), escalating to SIGKILL."""
        self.signal_all(signal.SIGCONT, ("world", "agent", "recorder"))  # one stopped by a fault could not stop
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
            if c.proc.returncode is None and not _exited(c.proc.pid):
                c.proc.kill()
                _exited(c.proc.pid, block=True)
            self._reaped(c)
            c.exit_code = c.proc.returncode
            c.log.close()


def _ended(pid: int) -> str | None:
    """How child ``pid`` ended ("exited with 1", "killed by signal 9"), None while it runs;
    without reaping it (its /proc entry, and the CPU time read from it, stay)."""
    try:
        info = os.waitid(os.P_PID, pid, os.WEXITED | os.WNOWAIT | os.WNOHANG)
    except ChildProcessError:
        return "exited"  # reaped already
    if info is None:
        return None
    if info.si_code == os.CLD_EXITED:
        return f"exited with {info.si_status}"
    return f"killed by signal {info.si_status}"


def _exited(pid: int, block: bool = False) -> bool:
    """Whether child ``pid`` has exited, without reaping it (its /proc entry stays readable)."""
    try:
        info = os.waitid(os.P_PID, pid, os.WEXITED | os.WNOWAIT | (0 if block else os.WNOHANG))
    except ChildProcessError:
        return True  # reaped already
    return info is not None


class _Router:
    """The run's router: this process's own Zenoh session in router mode, which a
    ``router`` fault closes and opens again on the same endpoint (the clients reconnect
    within about 0.5 s, with their subscriptions and tokens).  It also watches the run:
    liveliness, progress, the world's start."""

    def __init__(self, endpoint: str, run_id: str, certs: Path | None = None, procs: list[tuple[str, int]] | None = None) -> None:
        self.endpoint, self.run_id = endpoint, run_id
        self.certs, self.procs = certs, procs or []
        self.bus: ZenohBus | None = None
        self.alive: set[tuple[str, int]] = set()
        self.progress = [0.0]
        self.start: dict[str, float] = {}

    def open(self) -> None:
        if self.certs is not None:
            conf = zenoh_config("router", listen=[self.endpoint], secure=(str(self.certs), sec.ROUTER), acl=sec.acl(self.run_id, self.procs))
        else:
            conf = zenoh_config("router", listen=[self.endpoint])
        self.bus = ZenohBus(conf)
        self.bus.watch_alive(keys.alive_all(self.run_id), self._on_alive)
        self.bus.subscribe(keys.ctl(self.run_id, "progress"), self._on_progress)
        self.bus.subscribe(keys.ctl(self.run_id, "start"), self._on_start)

    def close(self) -> None:
        if self.bus is not None:
            self.bus.close()
            self.bus = None
            self.alive.clear()

    def _on_alive(self, key: str, up: bool) -> None:
        who = keys.parse_alive(key)
        if who:
            (self.alive.add if up else self.alive.discard)(who)

    def _on_progress(self, key: str, payload: bytes) -> None:
        try:
            self.progress[0] = run_control.decode_ctl(payload, "progress")["t"]
        except wire.MessageError:
            pass

    def _on_start(self, key: str, payload: bytes) -> None:
        try:
            m = run_control.decode_ctl(payload, "start")
        except wire.MessageError:
            return
        self.start.update(epoch=m["epoch"], time_scale=m["time_scale"])

    def world_time(self) -> float | None:
        """The run's world time now (None before the world's start)."""
        if not self.start:
            return None
        return (time.time() - self.start["epoch"]) * self.start["time_scale"]


class FaultRunner:
    """Carries out ``[[faults]]`` on real processes at their world times: SIGKILL (and a
    new process of the same command for a restart), SIGSTOP/SIGCONT, the router closed and
    opened again.  A cut is the link emulation's (zswarm/scenario/links.py), nothing to do here.
    Every action is logged with the world time it was taken at (summary.json
    ``fault_actions``)."""

    def __init__(self, la: Launch, router: _Router, faults: tuple[Fault, ...], say: Callable[[str], None]) -> None:
        self.la, self.router, self.say = la, router, say
        self.todo = fault_actions(faults)
        self.restarts: dict[int, int] = {}

    def wait(self, most: float) -> float:
        """How long the launcher may sleep before the next action (at most ``most``)."""
        t = self.router.world_time()
        if not self.todo or t is None:
            return most
        return max(0.0, min(most, (self.todo[0][0] - t) / self.router.start["time_scale"]))

    def poll(self) -> None:
        t = self.router.world_time()
        while self.todo and t is not None and self.todo[0][0] <= t:
            t_plan, _, action, f = self.todo.pop(0)
            self._do(action, f)
            t = self.router.world_time() if self.router.start else t
            self.la.fault_log.append({"action": action, "planned_at": t_plan, "taken_at": None if t is None else round(t, 4), "what": f.describe()})

    def finish(self) -> None:
        """The run ended: what is left undone is logged as not taken (a router is opened again)."""
        for t_plan, _, action, f in self.todo:
            if action == "router_up":
                self._do(action, f)
            self.la.fault_log.append({"action": action, "planned_at": t_plan, "taken_at": None, "what": f.describe(), "note": "after the run's end"})
        self.todo.clear()

    def _do(self, action: str, f: Fault) -> None:
        la = self.la
        if action == "router_down":
            self.say(f"zswarm run: fault: router down ({f.describe()})")
            self.router.close()
            return
        if action == "router_up":
            self.router.open()
            self.say("zswarm run: fault: router up again")
            return
        assert f.agent is not None
        c = la.child("agent", f.agent)
        if action == "restart":
            n = self.restarts[f.agent] = self.restarts.get(f.agent, 0) + 1
            self.say(f"zswarm run: fault: agent {f.agent} restarted")
            old = next(x for x in reversed(la.children) if x.role == "agent" and x.ident == f.agent)
            la.spawn(f"agent-{f.agent}", "agent", f.agent, old.cmd, log_name=f"agent-{f.agent}.restart{n}")
            la.write_processes(la.endpoint, la.run_id)
            return
        if c is None or c.proc.poll() is not None:
            self.say(f"zswarm run: fault: agent {f.agent} is not running; {action} skipped")
            return
        sig = {"kill": signal.SIGKILL, "stop": signal.SIGSTOP, "cont": signal.SIGCONT}[action]
        self.say(f"zswarm run: fault: {action} agent {f.agent} (pid {c.proc.pid})")
        if action == "kill":
            c.replaced = True
            c.name = f"{c.name}~killed{self.restarts.get(f.agent, 0) + 1}"
        os.kill(c.proc.pid, sig)


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
    secure: Path | bool | None = None,
    rerun: str | None = None,
    plots: bool = True,
) -> int:
    """Run the scenario over real processes; return the exit code for the CLI."""
    duration = sc.duration if duration is None else duration
    seed = sc.seed if seed is None else seed
    out = results_dir(out_base, sc.name)
    (out / "logs").mkdir(exist_ok=True)
    # Every process reads the scenario as run (with any --set applied) from the results folder.
    files.write_text(out / "scenario.toml", sc.text)  # whole or not at all
    topology = str(out / "scenario.toml")
    run_id = keys.check_run_id(f"r{os.getpid()}-{int(time.time())}")
    certs: Path | None = None
    if secure:
        # Mutual TLS and access control (zswarm/transport/secure.py): a certificate per process, made now.
        certs = (out / "secure") if secure is True else Path(secure)
        sec.make_certs(certs, sec.certificate_names(sc.ids))
    endpoint = f"{'tls' if certs else 'tcp'}/127.0.0.1:{free_port()}"
    # The run's secret (keys.SECRET_ENV): its children inherit it, so that only they can
    # start or stop the run and stand for its processes (one given by the user is kept, to
    # add processes started by hand).
    os.environ.setdefault(keys.SECRET_ENV, secrets.token_hex(16))
    la = Launch(sc, topology, out, duration, time_scale, seed, quiet)
    interrupted = threading.Event()
    on_signals = procutil.SignalEvent(interrupted)

    def say(msg: str) -> None:
        if not quiet:
            print(msg, file=sys.stderr, flush=True)

    common = ["--run-id", run_id, "--seed", str(seed), "--connect", endpoint] + (["--secure", str(certs)] if certs else [])
    py = sys.executable
    ok_start = False
    router = _Router(endpoint, run_id, certs, sec.processes(sc.ids))
    try:
        router.open()
        alive, progress = router.alive, router.progress
        say(f"zswarm run: {sc.name}: router on {endpoint}, results in {out}")
        live_args = ([] if live is None else ["--live", f"{live[0]}:{live[1]}"]) + ([] if rerun is None else ["--rerun", rerun])
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
        la.write_processes(endpoint, run_id)
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
        faults = FaultRunner(la, router, sc.faults, say)
        last_print = 0.0
        tty = sys.stderr.isatty()
        la.sample_cpu()
        t_run, cpu0 = time.monotonic(), {id(c): c.cpu_s for c in la.children}
        own0 = resource.getrusage(resource.RUSAGE_SELF)
        told: set[int] = set()
        while world.proc.poll() is None and not interrupted.is_set():
            time.sleep(faults.wait(0.1))
            faults.poll()
            la.sample_cpu()
            for c in la.children:  # a death told when it happens, from the child's own exit status
                if id(c) not in told and c.role != "world" and (how := _ended(c.proc.pid)) is not None and (how != "exited with 0" or c.role == "recorder"):
                    told.add(id(c))
                    lost = "; the run goes on, but nothing more of it is recorded" if c.role == "recorder" else ""
                    print(f"zswarm run: {c.name} {how} at t = {progress[0]:.1f} s{lost}", file=sys.stderr, flush=True)  # even --quiet
            now = time.monotonic()
            if not quiet and (tty or now - last_print > 5.0):
                # Alive: its token is up (it is running and connected) and its process, this
                # launcher's child, has not exited (a token a peer copied cannot hide that).
                n_alive = sum(1 for r, i in alive if r == "agent" and (c := la.child("agent", i)) is not None and id(c) not in told)
                line = f"t = {progress[0]:6.1f} / {duration:g} s   agents alive: {n_alive}/{len(sc.ids)}"
                print(("\r" + line) if tty else line, end="" if tty else "\n", file=sys.stderr, flush=True)
                last_print = now
        if tty and not quiet:
            print(file=sys.stderr)
        if interrupted.is_set():
            say("zswarm run: interrupted, stopping every process")
        faults.finish()
        run_wall = time.monotonic() - t_run
        la.sample_cpu()
        own1 = resource.getrusage(resource.RUSAGE_SELF)
        run_cpu = {c.name: c.cpu_s - cpu0.get(id(c), 0.0) for c in la.children}
        run_cpu["launcher+router"] = (own1.ru_utime + own1.ru_stime) - (own0.ru_utime + own0.ru_stime)
        la.stop_all(graceful=not interrupted.is_set())
    finally:
        la.reap()
        router.close()
        on_signals.close()
    if not ok_start:
        return 1
    # The CPU of the run: each process's CPU time over the run proper (from every process
    # alive to the world's end: /proc readings 0.1 s apart, this process's own rusage), and
    # over the whole command (the kernel's total of the reaped children: start-up, the
    # final stats and their confirmation too).
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    cores = os.cpu_count() or 1
    in_run = sum(run_cpu.values())
    la.cpu = {
        "run_wall_s": round(run_wall, 2),
        "run_cpu_s": {k: round(v, 2) for k, v in run_cpu.items()},
        "run_cpu_total_s": round(in_run, 2),
        "cores": cores,
        "run_share_of_cores": round(in_run / (run_wall * cores), 4) if run_wall > 0 else 0.0,
        "command_children_cpu_s": round(kids.ru_utime + kids.ru_stime, 2),
        "command_launcher_cpu_s": round(own.ru_utime + own.ru_stime, 2),
    }
    codes: dict[str, int | None] = {c.name: c.exit_code for c in la.children}
    try:
        la.write_processes(la.endpoint, la.run_id)
        summary = results.make_report(out, sc, "run", duration, time_scale, seed, exit_codes=codes, plots=plots)
    except ValueError as exc:
        say(f"zswarm run: no report: {exc}")
        return 1
    except Exception as exc:  # noqa: BLE001 - the run is over: keep what it left (recording, logs, exit codes)
        problem = procutil.write_problem(exc)
        if problem is not None:  # a full disk, a read-only folder: every process is stopped and reaped already
            print(f"zswarm run: {one_line(problem)} (the run itself ran; every process has exited and is reaped; what was written is in {out})", file=sys.stderr)
            return 1
        # Counters that pass the wire's bounds may still be what the report did not expect.
        say(f"zswarm run: the report failed ({type(exc).__name__}: {exc}); the recording and logs are in {out}")
        summary = {"report_error": f"{type(exc).__name__}: {exc}", "exit_codes": codes, "interrupted": interrupted.is_set(), "completed": False}
        results.write_summary(out / "summary.json", summary)
        return 1
    summary["exit_codes"] = codes
    summary["interrupted"] = interrupted.is_set()
    summary["cpu"] = la.cpu
    if la.fault_log:
        summary["fault_actions"] = la.fault_log
    results.write_summary(out / "summary.json", summary)
    print(results.table(summary))
    print(f"results: {out}")
    if interrupted.is_set():
        return procutil.interrupted_code()
    return 0 if summary["completed"] else 1
