"""CPU per draw of a basin check and per run of a sweep: zswarm sim against the batched
lockstep engine (issue 31).

Basins (the §5.6 laws, the §4.5 observers), for each scheme in one run: one draw the way
``zswarm basin --engine sim`` runs it (``basin.run_draw``: sim in memory, the recording
decoded, the family's max_k |R̄_k|_I), then the same draws on the batched engine
(``basin.run_chunk``: the draws' scenarios loaded, stepped together, the same row computed)
for M draws at once.  Sweeps (the §3 observers, which have no basin): one run the way
``zswarm sweep --engine sim`` runs it on a cluster's worker (``sweep.run_job``: sim in memory,
the report's files, the row), then M runs of the same sweep point (their seeds differ; the
noiseless scenario, so they share a batch) on the batched engine (``sweep_batched.run_batch``).
Links (issue 46): the §5.6 basins once more with emulated command links (``--links``, by
default 2 ms of delay and 10 % loss: each draw its own losses, sim's numbers), and once with
lossy sensor links (``--sensor-links``, by default 3 ms of delay, 2 ms of jitter and 10 % loss:
each draw's agents step at packets of their own), sim against batched the same way.
Printed: CPU seconds per draw and per agent-step, and the ratio sim / batched per draw.
Process CPU time (time.process_time), so another process on the machine does not count;
each figure is the best of REPEATS.

    .venv/bin/python bench/bench_batched.py [--duration S] [--draws 1,10,100,1000] [--schemes a,b] [--sweep-schemes a,b] [--links "F=V F=V"] [--sensor-links "F=V F=V"]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from agent import batched
from zswarm.report.base import THRESHOLDS
from zswarm.scenario import load, parse_override
from zswarm.studies import basin, sweep, sweep_batched

ROOT = Path(__file__).resolve().parents[1]
SCHEMES = ("thesis-5.6-continuous7", "thesis-5.6-hybrid7", "thesis-5.6-velocity-free7", "thesis-4.5-continuous5", "thesis-4.5-hybrid5")
SWEEP_SCHEMES = ("thesis-3.2-fixed8", "thesis-3.2-fixed8-filtered", "thesis-3.3-moving5")
REPEATS = 2
LINKS = "links.commands.delay_ms=2 links.commands.drop=0.1"
SENSOR_LINKS = "links.sensors.delay_ms=3 links.sensors.jitter_ms=2 links.sensors.drop=0.1"


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
    ap.add_argument("--schemes", default=",".join(SCHEMES), help="topologies/ stems of basins (default: the §5.6 laws and the §4.5 observers)")
    ap.add_argument("--sweep-schemes", default=",".join(SWEEP_SCHEMES), help="topologies/ stems of sweeps (default: the §3 observers; '' for none)")
    ap.add_argument("--links", default=LINKS, help=f"overrides of the link case of the §5.6 basins, space-separated (default {LINKS!r}; '' for none)")
    ap.add_argument("--sensor-links", default=SENSOR_LINKS, help=f"overrides of the sensor-link case of the §5.6 basins (default {SENSOR_LINKS!r}; '' for none)")
    a = ap.parse_args()
    sizes = [int(x) for x in a.draws.split(",")]
    print(f"CPU per draw of {a.duration:g} s of world time (best of {REPEATS}); agent-steps per draw = agents x ticks")
    print(f"{'scheme':26} {'engine':14} {'M':>5} {'s/draw':>9} {'us/agent-step':>14} {'sim/batched':>12}")
    cases: list[tuple[str, str, str | tuple[str, str], list]] = [(stem, "", str(ROOT / "topologies" / f"{stem}.toml"), []) for stem in a.schemes.split(",")]
    for tag, text in ((" +links", a.links), (" +sensors", a.sensor_links)):
        sets = [parse_override(o) for o in text.split()]
        for stem in a.schemes.split(",") if sets else ():
            path = str(ROOT / "topologies" / f"{stem}.toml")
            sc = load(path, sets)
            # the agents command the world (command links), or the world's bodies move by the laws (lossy sensor links)
            if sc.info.command and batched.problem(sc) is None:
                cases.append((stem, tag, (sc.text, path), sets))
        if sets:
            print(f"{tag.strip()}: {text}")
    for stem, tag, topo, sets in cases:
        sc = load(topo) if isinstance(topo, str) else load(topo[1], sets)
        steps = len(sc.ids) * round(a.duration * sc.agent(1).clock.rate)
        sim_s = cpu(basin.run_draw, topo, 1, 1, a.duration, 0.01)
        print(f"{stem:26} {'sim' + tag:14} {1:>5} {sim_s:9.3f} {1e6 * sim_s / steps:14.1f} {'':>12}")
        for m in sizes:
            per = cpu(basin.run_chunk, topo, 1, list(range(1, m + 1)), a.duration, 0.01) / m
            print(f"{stem:26} {'batched' + tag:14} {m:>5} {per:9.4f} {1e6 * per / steps:14.2f} {sim_s / per:11.0f}x", flush=True)
    for stem in filter(None, a.sweep_schemes.split(",")):
        topo = ROOT / "topologies" / f"{stem}.toml"
        sc = load(topo)
        steps = len(sc.ids) * round(a.duration * sc.agent(1).clock.rate)
        source = (topo.read_text(encoding="utf-8"), str(topo))
        jobs = [sweep.Job(f"p000-r{k}", 0, k, k + 1, (), ()) for k in range(max(sizes))]
        sim_s = cpu(sweep.run_job, *source, jobs[0], a.duration, THRESHOLDS)
        print(f"{stem:26} {'sim (sweep)':14} {1:>5} {sim_s:9.3f} {1e6 * sim_s / steps:14.1f} {'':>12}")
        for m in sizes:
            per = cpu(sweep_batched.run_batch, source, jobs[:m], a.duration, THRESHOLDS) / m
            print(f"{stem:26} {'batched':14} {m:>5} {per:9.4f} {1e6 * per / steps:14.2f} {sim_s / per:11.0f}x", flush=True)


if __name__ == "__main__":
    main()
