"""Where a ``sim`` run's CPU goes: one scenario simulated in this process under cProfile (lean,
no recording file, as a sweep's run and the component tests run it), and the cumulative time of
some of its parts as shares of the whole: the agents' ticks, the law's steps within them, every
publish (the agents' messages and the world's truth and sensor packets: built, checked and
delivered), the agents' inboxes, the world's sampling (its publishes included).  The shares
overlap (a part nested in another is in both) and do not add up to 1.  cProfile slows small
calls more than large ones, so they are its, not a clock's; the CPU without the profiler is
measured first, after a run that warms the process up.  Writes docs/data/sim-profile.json.

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
    ap.add_argument("--machine", default="this project's 2-core machine, quiet", help="what the file says of the machine and its load")
    a = ap.parse_args()
    sc = load(ROOT / "topologies" / f"{a.scenario}.toml")
    with tempfile.TemporaryDirectory() as d:
        simulate(sc, Path(d), min(a.duration, 2.0), sc.seed, lean=True, record=False)  # imports, caches
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
    commit = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=ROOT, capture_output=True, text=True, check=False).stdout.strip()  # -dirty: uncommitted changes
    a.out.write_text(json.dumps({
        "what": f"CPU of a {a.duration:g} s {a.scenario} sim run in one process (lean, no recording file) and the shares of some of its parts under cProfile (cumulative time; they overlap: a part nested in another is in both)",
        "command": f"python bench/profile_sim.py --scenario {a.scenario} --duration {a.duration:g}",
        "measured": datetime.date.today().isoformat(),
        "commit": commit,
        "machine": a.machine,
        "made_again": "no: CPU seconds of this machine",
        "cpu_s": round(cpu, 2),
        "agent_ticks": ticks,
        "cpu_us_per_agent_tick": round(1e6 * cpu / ticks, 1),
        "shares": shares,
    }, indent=1) + "\n")
    print(json.dumps(shares, indent=1), f"\n{cpu:.2f} s of CPU, {ticks} agent ticks: {1e6 * cpu / ticks:.0f} µs each (the world's share included); {a.out}")


if __name__ == "__main__":
    main()
