"""Benchmark: zswarm over real processes beside raw zenoh-python pub/sub, same machine, same run.

Prints:
  * raw zenoh-python pub/sub latency (client -> router -> client, 100 Hz, the
    payload size of a zswarm edge message), p50/p99, over TCP and over mutual TLS
    with the router's access control (what `zswarm run --secure` uses);
  * for `zswarm run` of the §3.2 scenario: sensor->agent and agent->neighbour
    latency p50/p99 (receiver's arrival clock minus sender's send stamp; one
    host, clocks without offset or drift), agent step compute time, achieved
    step rates, missed deadlines, and CPU per process (from /proc, over a
    window in the middle of the run); then the same with --secure (the cost of the
    authenticated profile).

Usage: python bench/bench_runtime.py [--duration S] [--topology F] [--time-scale X]
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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

RAW_PUB = r"""
import sys, time, msgpack, zenoh
from zswarm.transport.bus import zenoh_config
ep, n, size = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
sec = (sys.argv[4], "pub") if len(sys.argv) > 4 else None
with zenoh.open(zenoh_config("client", connect=[ep], secure=sec)) as s:
    pub = s.declare_publisher("bench/raw", congestion_control=zenoh.CongestionControl.DROP, priority=zenoh.Priority.REAL_TIME)
    time.sleep(1.0)
    pad = b"x" * size
    t = time.monotonic()
    for k in range(n):
        pub.put(msgpack.packb({"k": k, "t": time.time(), "pad": pad}))
        t += 0.01
        time.sleep(max(0.0, t - time.monotonic()))
    time.sleep(0.5)
"""

RAW_SUB = r"""
import sys, time, json, threading, msgpack, zenoh
from zswarm.transport.bus import zenoh_config
ep, n, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
sec = (sys.argv[4], "sub") if len(sys.argv) > 4 else None
lat = []
done = threading.Event()
def cb(sample):
    now = time.time()
    m = msgpack.unpackb(sample.payload.to_bytes())
    lat.append(now - m["t"])
    if len(lat) >= n:
        done.set()
with zenoh.open(zenoh_config("client", connect=[ep], secure=sec)) as s:
    sub = s.declare_subscriber("bench/raw", cb)
    done.wait(n * 0.01 + 30)
    sub.undeclare()
json.dump(lat, open(out, "w"))
"""


def cpu_seconds(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/stat") as f:
            parts = f.read().rsplit(")", 1)[1].split()
        return (int(parts[11]) + int(parts[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def raw_zenoh(n: int, size: int, secure: bool = False) -> np.ndarray:
    """Latencies of raw pub/sub via a router; ``secure``: mutual TLS, and an access control
    that lets the publisher put on its key only (as zswarm.transport.secure.acl does per process)."""
    from zswarm.engines.launch import free_port
    from zswarm.transport import secure as sec
    from zswarm.transport.bus import ZenohBus, zenoh_config

    ep = f"{'tls' if secure else 'tcp'}/127.0.0.1:{free_port()}"
    with tempfile.TemporaryDirectory() as d:
        extra: list[str] = []
        conf = zenoh_config("router", listen=[ep])
        if secure:
            sec.make_certs(Path(d), ["pub", "sub"])
            rules = [
                {"id": "read", "permission": "allow", "flows": ["ingress", "egress"], "messages": ["declare_subscriber"], "key_exprs": ["bench/**"]},
                {"id": "deliver", "permission": "allow", "flows": ["egress"], "messages": ["put"], "key_exprs": ["bench/**"]},
                {"id": "pub", "permission": "allow", "flows": ["ingress"], "messages": ["put"], "key_exprs": ["bench/raw"]},
            ]
            acl = {
                "enabled": True,
                "default_permission": "deny",
                "rules": rules,
                "subjects": [{"id": "anyone"}, {"id": "pub", "cert_common_names": ["pub"]}],
                "policies": [{"rules": ["read", "deliver"], "subjects": ["anyone"]}, {"rules": ["pub"], "subjects": ["pub"]}],
            }
            conf = zenoh_config("router", listen=[ep], secure=(d, sec.ROUTER), acl=acl)
            extra = [d]
        router = ZenohBus(conf)
        out = Path(d) / "lat.json"
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        sub = subprocess.Popen([sys.executable, "-c", RAW_SUB, ep, str(n), str(out), *extra], env=env)
        pub = subprocess.Popen([sys.executable, "-c", RAW_PUB, ep, str(n), str(size), *extra], env=env)
        try:
            pub.wait(n * 0.01 + 60)
            sub.wait(60)
        finally:
            for p in (pub, sub):
                if p.poll() is None:
                    p.kill()
                    p.wait()
            router.close()
        return np.array(json.loads(out.read_text()))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--topology", default=str(ROOT / "topologies" / "thesis-3.2-fixed8.toml"))
    ap.add_argument("--time-scale", type=float, default=1.0)
    args = ap.parse_args()

    print(f"machine: {os.cpu_count()} cores; python {sys.version.split()[0]}")
    for secure in (False, True):
        raw = raw_zenoh(1500, 250, secure)
        how = "mutual TLS + access control" if secure else "TCP"
        print(f"raw zenoh-python pub/sub via router, {how}, 100 Hz, 250 B pad: n={raw.size} p50 {1e3 * np.percentile(raw, 50):.3f} ms  p99 {1e3 * np.percentile(raw, 99):.3f} ms")
    for secure in (False, True):
        if run_zswarm(args, secure):
            return 1
    return 0


def run_zswarm(args: argparse.Namespace, secure: bool) -> int:
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "run"
        cmd = [sys.executable, "-m", "zswarm", "run", args.topology, "--duration", str(args.duration), "--time-scale", str(args.time_scale), "--out", str(out), "--quiet"]
        cmd += ["--secure"] if secure else []
        launcher = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            while not (out / "processes.json").exists():
                if launcher.poll() is not None:
                    print(launcher.stdout.read().decode() if launcher.stdout else "")
                    return 1
                time.sleep(0.1)
            kids = json.loads((out / "processes.json").read_text())["children"]
            pids = {c["name"]: c["pid"] for c in kids} | {"launcher+router": launcher.pid}
            while not ((out / "logs" / "world.log").exists() and "start:" in (out / "logs" / "world.log").read_text()):
                time.sleep(0.1)
            window = min(10.0, args.duration / (2 * args.time_scale))
            time.sleep(min(3.0, args.duration / (4 * args.time_scale)))
            c0 = {k: cpu_seconds(p) for k, p in pids.items()}
            w0 = time.monotonic()
            time.sleep(window)
            c1 = {k: cpu_seconds(p) for k, p in pids.items()}
            w1 = time.monotonic()
            text = launcher.communicate(timeout=args.duration / args.time_scale + 120)[0].decode()
        finally:
            if launcher.poll() is None:
                os.killpg(launcher.pid, 9)
                launcher.wait()
        if launcher.returncode != 0:
            print(text)
            return 1
        s = json.loads((out / "summary.json").read_text())

    def pct(links: dict, pred) -> str:
        p50 = [v["latency_p50_ms"] for k, v in links.items() if pred(k) and "latency_p50_ms" in v]
        p99 = [v["latency_p99_ms"] for k, v in links.items() if pred(k) and "latency_p99_ms" in v]
        return f"p50 {np.median(p50):.3f} ms (links: {min(p50):.3f}-{max(p50):.3f})  p99 {np.median(p99):.3f} ms (max {max(p99):.3f})"

    print(f"\nzswarm run {'--secure ' if secure else ''}{Path(args.topology).name}: {args.duration:g} s at time scale {args.time_scale:g}, {len(s['agents'])} agents")
    print(f"  sensor->agent   latency {pct(s['links'], lambda k: k.startswith('world->'))}")
    print(f"  agent->neighbour latency {pct(s['links'], lambda k: not k.startswith('world->'))}")
    comp = [a["compute_mean_us"] for a in s["agents"].values()]
    print(f"  agent step compute time: mean over agents {np.mean(comp):.0f} us (per agent {min(comp):.0f}-{max(comp):.0f} us)")
    rates = [a["step_rate_hz"] for a in s["agents"].values()]
    print(f"  achieved step rate: {min(rates):.2f}-{max(rates):.2f} Hz (configured {s['agents']['1']['configured_rate_hz']:g}); missed deadlines: {sum(a['missed_deadlines'] for a in s['agents'].values())}")
    print(f"  world: {s['world'].get('samples')} samples, {s['world'].get('late')} late")
    print(f"  CPU per process over {w1 - w0:.1f} s mid-run (% of one core):")
    total = 0.0
    for k in sorted(pids):
        if c0.get(k) is not None and c1.get(k) is not None:
            u = 100 * (c1[k] - c0[k]) / (w1 - w0)
            total += u
            print(f"    {k:<16} {u:6.1f} %")
    print(f"    {'total':<16} {total:6.1f} %")
    print(f"  final mean errors over followers: attitude {s['mean_attitude_error_final']:.2e}, position {s['mean_position_error_final']:.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
