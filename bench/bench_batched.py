"""CPU per draw of a basin check: zswarm sim against the batched lockstep engine (issue 31).

For each scheme, in one run: one draw the way ``zswarm basin --engine sim`` runs it
(``basin.run_draw``: sim in memory, the recording decoded, the family's max_k |R̄_k|_I),
then the same draws on the batched engine (``basin.run_chunk``: the draws' scenarios loaded,
stepped together, the same row computed) for M draws at once.  Printed: CPU seconds per
draw and per agent-step, and the ratio sim / batched per draw.  Process CPU time
(time.process_time), so another process on the machine does not count; each figure is
the best of REPEATS.

    .venv/bin/python bench/bench_batched.py [--duration S] [--draws 1,10,100,1000] [--schemes a,b]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from zswarm import basin
from zswarm.scenario import load

ROOT = Path(__file__).resolve().parents[1]
SCHEMES = ("thesis-5.6-continuous7", "thesis-5.6-hybrid7", "thesis-5.6-velocity-free7", "thesis-4.5-continuous5", "thesis-4.5-hybrid5")
REPEATS = 2


def cpu(f, *args):
    best = float("inf")
    for _ in range(REPEATS):
        t0 = time.process_time()
        f(*args)
        best = min(best, time.process_time() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=5.0, help="world seconds per draw (default 5)")
    ap.add_argument("--draws", default="1,10,100,1000", help="batch sizes M (default 1,10,100,1000)")
    ap.add_argument("--schemes", default=",".join(SCHEMES), help="topologies/ stems (default: the §5.6 laws and the §4.5 observers)")
    a = ap.parse_args()
    sizes = [int(x) for x in a.draws.split(",")]
    print(f"CPU per draw of {a.duration:g} s of world time (best of {REPEATS}); agent-steps per draw = agents x ticks")
    print(f"{'scheme':26} {'engine':14} {'M':>5} {'s/draw':>9} {'us/agent-step':>14} {'sim/batched':>12}")
    for stem in a.schemes.split(","):
        topo = str(ROOT / "topologies" / f"{stem}.toml")
        sc = load(topo)
        steps = len(sc.ids) * round(a.duration * sc.agent(1).clock.rate)
        sim_s = cpu(basin.run_draw, topo, 1, 1, a.duration, 0.01)
        print(f"{stem:26} {'sim':14} {1:>5} {sim_s:9.3f} {1e6 * sim_s / steps:14.1f} {'':>12}")
        for m in sizes:
            per = cpu(basin.run_chunk, topo, 1, list(range(1, m + 1)), a.duration, 0.01) / m
            print(f"{stem:26} {'batched':14} {m:>5} {per:9.4f} {1e6 * per / steps:14.2f} {sim_s / per:11.0f}x", flush=True)


if __name__ == "__main__":
    main()
