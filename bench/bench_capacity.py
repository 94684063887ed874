"""Capacity: how many agents fit on this machine, zswarm run beside a raw zenoh-python swarm.

For each N (alternating: raw swarm, then ``zswarm run``, then the next N) a
§3.2-style scenario from ``zswarm generate bearing-fixed -n N`` (leaders 1
and 2, followers with 3 lower-numbered in-neighbours, 100 Hz agents, 200 Hz
sensors) runs for ``--duration`` s at time scale 1.  The raw swarm
(``bench/raw_swarm.py``) has the same graph, rates, payload sizes (measured
on the same scenario in ``sim``), keys and transport settings, an embedded
router in the driving process and a recorder; no estimator math and no
validation.  Prints per N: missed deadlines (% of the agents' ticks), the
median over edges of each edge's p99 latency, per-agent CPU (mean over
agents, % of a core, over a mid-run window), the world's, the recorder's and
the router's CPU, and what the recording lacks; then the largest N with
< 1 % missed deadlines for each.

Usage: python bench/bench_capacity.py [--n 4 8 12 16 24] [--duration 20] [--seed 1] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from bench_runtime import cpu_seconds  # noqa: E402

from zswarm.scenario import Scenario  # noqa: E402
from zswarm.studies import generate  # noqa: E402


def thread_seconds(pid: int) -> dict[str, float]:
    """CPU seconds of each thread kind of process ``pid``: its main thread ("main", the agent's
    ticks) and the others by name (Zenoh's runtime threads, "python" for the threads
    zenoh-python runs callbacks on, and so on), summed over the threads of a name."""
    out: dict[str, float] = {}
    try:
        tids = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return out
    for tid in tids:
        try:
            with open(f"/proc/{pid}/task/{tid}/stat") as f:
                head, tail = f.read().rsplit(")", 1)
        except OSError:
            continue
        name = "main" if tid == str(pid) else head.split("(", 1)[1]
        name = name.rstrip("0123456789-") or name  # rx-0, rx-1 -> rx
        parts = tail.split()
        out[name] = out.get(name, 0.0) + (int(parts[11]) + int(parts[12])) / os.sysconf("SC_CLK_TCK")
    return out


def cpu_window(pids: dict[str, int], start: float, window: float, threads: dict[str, float] | None = None) -> dict[str, float]:
    """% of a core each pid used from ``start`` (monotonic) for ``window`` s; ``threads``: filled
    with the agents' mean % of a core per thread kind (:func:`thread_seconds`)."""
    time.sleep(max(0.0, start - time.monotonic()))
    agents = {k: p for k, p in pids.items() if k.startswith("agent-")}
    t0 = {k: thread_seconds(p) for k, p in agents.items()}
    c0 = {k: cpu_seconds(p) for k, p in pids.items()}
    w0 = time.monotonic()
    time.sleep(window)
    c1 = {k: cpu_seconds(p) for k, p in pids.items()}
    t1 = {k: thread_seconds(p) for k, p in agents.items()}
    w = time.monotonic() - w0
    if threads is not None and agents:
        for k in agents:
            for name, sec in t1[k].items():
                threads[name] = threads.get(name, 0.0) + 100 * (sec - t0[k].get(name, 0.0)) / w / len(agents)
    return {k: 100 * (c1[k] - c0[k]) / w for k in pids if c0.get(k) is not None and c1.get(k) is not None}  # type: ignore[operator]


def payload_sizes(sc: Scenario, seed: int) -> dict[str, Any]:
    """Mean payload size per key of a short ``sim`` of ``sc`` (what zswarm puts on the wire)."""
    import zswarm.engines.sim as sim
    from zswarm.transport.bus import MemoryBus

    sizes: dict[str, list[int]] = {}

    class Sizing(MemoryBus):
        def put(self, key: str, payload: bytes) -> None:
            sizes.setdefault(key.split("/", 2)[2], []).append(len(payload))
            super().put(key, payload)

    real = sim.MemoryBus
    sim.MemoryBus = Sizing  # type: ignore[misc]
    try:
        with tempfile.TemporaryDirectory() as d:
            sim.simulate(sc, Path(d), 0.5, seed, record=False)
    finally:
        sim.MemoryBus = real  # type: ignore[misc]
    mean = {k: int(round(np.mean(v))) for k, v in sizes.items()}
    agents = {}
    for a in sc.agents:
        i = a.id
        agents[str(i)] = {
            "sense": mean[f"sense/{i}"],
            "est": mean[f"est/{i}"],
            "in": list(a.neighbors),
            "out": {str(j): mean.get(f"edge/{i}/{j}", 0) for j in sc.out_neighbors(i)},
        }
    return {"agents": agents, "truth": mean["truth"]}


def row(missed: int, ticks: int, edge_p99_ms: list[float], cpu: dict[str, float], sc: Scenario, **extra: Any) -> dict[str, Any]:
    """One swarm's figures at one N: missed deadlines (% of the agents' ticks), the median
    and the largest of the edges' p99 latencies, mean per-agent CPU and the other processes'."""
    return {
        "missed_pct": 100 * missed / ticks,
        "edge_p99_ms": float(np.median(edge_p99_ms)),
        "edge_p99_max_ms": float(max(edge_p99_ms)),
        "agent_cpu_pct": float(np.mean([cpu[f"agent-{i}"] for i in sc.ids])),
        "world_cpu_pct": cpu["world"],
        "recorder_cpu_pct": cpu["recorder"],
        "router_cpu_pct": cpu["router"],
    } | extra


def run_raw(sc: Scenario, sizes: dict[str, Any], duration: float) -> dict[str, Any]:
    from zswarm.engines.launch import free_port
    from zswarm.transport.bus import ZenohBus, zenoh_config

    ep = f"tcp/127.0.0.1:{free_port()}"
    cfg = sizes | {"rate": sc.agents[0].clock.rate, "sensor_rate": sc.sensor_rate, "duration": duration}
    with tempfile.TemporaryDirectory() as d, ZenohBus(zenoh_config("router", listen=[ep])):
        cfg_path = Path(d) / "cfg.json"
        cfg_path.write_text(json.dumps(cfg))
        script = str(ROOT / "bench" / "raw_swarm.py")
        procs: dict[str, subprocess.Popen[bytes]] = {}

        def start(name: str, *args: str) -> None:
            procs[name] = subprocess.Popen([sys.executable, script, *args], start_new_session=True)

        try:
            start("recorder", "recorder", str(cfg_path), ep, f"{d}/recorder.json")
            for i in sc.ids:
                start(f"agent-{i}", "agent", str(cfg_path), ep, f"{d}/agent-{i}.json", str(i))
            start("world", "world", str(cfg_path), ep, f"{d}/world.json")
            t_start = time.monotonic() + 3.0  # sessions up, start announced 1 s after the last token
            threads: dict[str, float] = {}
            cpu = cpu_window({k: p.pid for k, p in procs.items()} | {"router": os.getpid()}, t_start + duration / 4, duration / 2, threads)
            for p in procs.values():
                p.wait(duration + 120)
        finally:
            for p in procs.values():
                if p.poll() is None:
                    p.kill()
                    p.wait()
        res = {k: json.loads(Path(f"{d}/{k}.json").read_text()) for k in procs}
    agents = [res[f"agent-{i}"] for i in sc.ids]
    ticks = sum(a["ticks"] + a["missed"] for a in agents)
    p99 = [v["p99_ms"] for a in agents for k, v in a["links"].items() if k.startswith("edge/")]
    return row(sum(a["missed"] for a in agents), ticks, p99, cpu, sc, lost_in_recording=None, world_late=res["world"]["late"], agent_threads=threads)


def run_zswarm(topology: Path, sc: Scenario, duration: float, out: Path) -> dict[str, Any]:
    cmd = [sys.executable, "-m", "zswarm", "run", str(topology), "--duration", str(duration), "--out", str(out), "--quiet"]
    launcher = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        while not (out / "processes.json").exists():
            if launcher.poll() is not None:
                raise RuntimeError(launcher.stdout.read().decode() if launcher.stdout else "zswarm run failed")
            time.sleep(0.1)
        kids = json.loads((out / "processes.json").read_text())["children"]
        pids = {c["name"]: c["pid"] for c in kids} | {"router": launcher.pid}
        wlog = out / "logs" / "world.log"
        while not (wlog.exists() and "start:" in wlog.read_text()):
            if launcher.poll() is not None:
                raise RuntimeError(launcher.stdout.read().decode() if launcher.stdout else "zswarm run failed")
            time.sleep(0.1)
        threads: dict[str, float] = {}
        cpu = cpu_window(pids, time.monotonic() + 1.0 + duration / 4, duration / 2, threads)
        text = launcher.communicate(timeout=duration + 180)[0].decode()
    finally:
        if launcher.poll() is None:
            os.killpg(launcher.pid, 9)
            launcher.wait()
    if launcher.returncode != 0:
        raise RuntimeError(text)
    s = json.loads((out / "summary.json").read_text())
    ag = s["agents"].values()
    ticks = sum(a["steps"] + a["missed_deadlines"] + a.get("idle_ticks", 0) for a in ag)
    p99 = [v["latency_p99_ms"] for k, v in s["links"].items() if not k.startswith("world->") and not k.endswith("->world") and "latency_p99_ms" in v]
    return row(
        sum(a["missed_deadlines"] for a in ag),
        ticks,
        p99,
        cpu,
        sc,
        lost_in_recording=(s.get("recording") or {}).get("missing_total"),
        world_late=s["world"].get("late"),
        alive_at_end=sum(1 for a in ag if a.get("alive_at_end")),
        agent_threads=threads,
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[4, 8, 12, 16, 24])
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores; python {sys.version.split()[0]}; {args.duration:g} s per run at time scale 1", flush=True)
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as d:
        for n in args.n:
            text, sc = generate.generate("bearing-fixed", n, args.seed, duration=args.duration)
            topo = Path(d) / f"gen{n}.toml"
            topo.write_text(text)
            sizes = payload_sizes(sc, args.seed)
            raw = run_raw(sc, sizes, args.duration)
            print(f"N={n:3d} raw    missed {raw['missed_pct']:6.2f} %  edge p99 {raw['edge_p99_ms']:7.1f} ms  agent CPU {raw['agent_cpu_pct']:5.1f} %", flush=True)
            zs = run_zswarm(topo, sc, args.duration, Path(d) / f"run{n}")
            print(f"N={n:3d} zswarm missed {zs['missed_pct']:6.2f} %  edge p99 {zs['edge_p99_ms']:7.1f} ms  agent CPU {zs['agent_cpu_pct']:5.1f} %", flush=True)
            rows.append({"n": n, "raw": raw, "zswarm": zs})
    print()
    print("| N | zswarm missed | zswarm edge p99 | raw missed | raw edge p99 | agent CPU zswarm / raw (% of a core) | world | recorder | router | recording lacks | alive at end |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        z, w = r["zswarm"], r["raw"]
        print(
            f"| {r['n']} | {z['missed_pct']:.2f} % | {z['edge_p99_ms']:.1f} ms | {w['missed_pct']:.2f} % | {w['edge_p99_ms']:.1f} ms | "
            f"{z['agent_cpu_pct']:.1f} / {w['agent_cpu_pct']:.1f} = {z['agent_cpu_pct'] / max(w['agent_cpu_pct'], 1e-9):.2f}x | "
            f"{z['world_cpu_pct']:.0f} / {w['world_cpu_pct']:.0f} % | {z['recorder_cpu_pct']:.0f} / {w['recorder_cpu_pct']:.0f} % | "
            f"{z['router_cpu_pct']:.0f} / {w['router_cpu_pct']:.0f} % | {z['lost_in_recording']} | {z['alive_at_end']}/{r['n']} |"
        )
    print()
    print("An agent's CPU by thread (% of a core, mean over agents): main = its ticks; python = zenoh-python's callback threads; the rest Zenoh's runtime")
    for r in rows:
        z, w = r["zswarm"]["agent_threads"], r["raw"]["agent_threads"]
        names = sorted(set(z) | set(w), key=lambda k: -(z.get(k, 0.0) + w.get(k, 0.0)))
        print(f"N={r['n']}: " + ", ".join(f"{k} {z.get(k, 0.0):.2f} / {w.get(k, 0.0):.2f}" for k in names if z.get(k, 0.0) + w.get(k, 0.0) >= 0.05) + "  (zswarm / raw)")
    for who in ("zswarm", "raw"):
        ok = [r["n"] for r in rows if r[who]["missed_pct"] < 1.0]
        print(f"largest N with < 1 % missed deadlines, {who}: {max(ok) if ok else 'none'} (of {args.n})")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
