"""Where a ``sim`` run's CPU goes: one scenario simulated in this process under cProfile (lean,
no recording file, as a sweep's run and the component tests run it), and the cumulative time of
its parts as shares of the whole: the agents' ticks (of which the law's step, publishing what it
sends, reading its inbox), the world's sampling and stepping, the rest (the engine's loop, the
recorder).  cProfile slows small calls more than large ones, so the shares are its, not a
clock's; the CPU without the profiler is measured first.  Writes docs/data/sim-profile.json.

    .venv/bin/python bench/profile_sim.py [--scenario thesis-5.6-hybrid7] [--duration 30]
"""

from __future__ import annotations

import argparse
import cProfile
import datetime
import json
import pstats
import subprocess
import tempfile
import time
from pathlib import Path

from zswarm.engines.sim import simulate
from zswarm.scenario import load

ROOT = Path(__file__).resolve().parents[1]
# (part, file suffix, function name): cumulative time of that function (every call, not nested in itself)
PARTS = [
    ("agent ticks", "agent/runtime.py", "tick"),
    ("the law's steps", "agent/runtime.py", "_step_part"),
    ("publishing (messages built, checked, delivered)", "zswarm/transport/bus.py", "publish"),
    ("the inbox (links, delivery, release)", "agent/inbox.py", "release_due"),
    ("the world's sampling", "world/node.py", "sample"),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="thesis-5.6-hybrid7")
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "data" / "sim-profile.json")
    a = ap.parse_args()
    sc = load(ROOT / "topologies" / f"{a.scenario}.toml")
    with tempfile.TemporaryDirectory() as d:
        t0 = time.process_time()
        simulate(sc, Path(d), a.duration, sc.seed, lean=True, record=False)
        cpu = time.process_time() - t0
        prof = cProfile.Profile()
        prof.enable()
        simulate(sc, Path(d), a.duration, sc.seed, lean=True, record=False)
        prof.disable()
    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]  # (file, line, name) -> (cc, nc, tt, ct, callers)
    total = sum(tt for (_cc, _nc, tt, _ct, _callers) in stats.values())
    shares = {}
    for part, suffix, name in PARTS:
        ct = sum(v[3] for (file, _line, fn), v in stats.items() if fn == name and file.endswith(suffix))
        shares[part] = round(ct / total, 3)
    ticks = sum(v[1] for (file, _line, fn), v in stats.items() if fn == "tick" and file.endswith("agent/runtime.py"))
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=False).stdout.strip()
    a.out.write_text(json.dumps({
        "what": f"CPU of a {a.duration:g} s {a.scenario} sim run in one process (lean, no recording file) and the shares of its parts under cProfile (cumulative time)",
        "command": f"python bench/profile_sim.py --scenario {a.scenario} --duration {a.duration:g}",
        "measured": datetime.date.today().isoformat(),
        "commit": commit,
        "machine": "this project's 2-core machine, quiet",
        "made_again": "no: CPU seconds of this machine",
        "cpu_s": round(cpu, 2),
        "agent_ticks": ticks,
        "cpu_us_per_agent_tick": round(1e6 * cpu / ticks, 1),
        "shares": shares,
    }, indent=1) + "\n")
    print(json.dumps(shares, indent=1), f"\n{cpu:.2f} s of CPU, {ticks} agent ticks: {1e6 * cpu / ticks:.0f} µs each (the world's share included); {a.out}")


if __name__ == "__main__":
    main()
