"""The three sweeps docs/running.md times ("zswarm sweep"), each as a user runs it on the batched
engine and on sim (``--jobs`` at its default, ``--no-plots``): wall time of the command and CPU
(its own and its children's), and whether the two engines' rows are the same column by column
(all but wall_s).  Writes docs/data/sweep-examples.json; tests/component/test_publications_more.py
holds the page's numbers to it.

    .venv/bin/python bench/bench_sweep_examples.py [--out docs/data/sweep-examples.json]
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# (what the page calls it, the scenario, the sweep's arguments)
EXAMPLES = [
    ("§5.6 hybrid law with noise", "thesis-5.6-hybrid7-noisy", ["--vary", "noise.rel_att_var=0.005,0.02", "--repeats", "10", "--duration", "10"]),
    ("noisy §3.2 observer", "thesis-3.2-fixed8-noisy", ["--vary", "noise.bearing_var=0.001,0.004", "--repeats", "10", "--duration", "10"]),
    ("gain sweep of the noisy §5.6 hybrid law", "thesis-5.6-hybrid7-noisy", ["--vary", "algorithm.gains.k_R=0.2,0.3,0.4,0.5,0.6", "--repeats", "4", "--duration", "10"]),
]


def children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def sweep(stem: str, args: list[str], engine: str, out: Path) -> tuple[float, float]:
    """Wall time and CPU (the command and every process it started) of one sweep."""
    cmd = [sys.executable, "-m", "zswarm", "sweep", str(ROOT / "topologies" / f"{stem}.toml"), *args, "--engine", engine, "--no-plots", "--out", str(out)]
    c0, t0 = children_cpu(), time.monotonic()
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.monotonic() - t0, children_cpu() - c0


def rows(out: Path) -> dict[str, dict[str, str]]:
    with open(out / "sweep.csv", newline="") as f:
        return {r["run_id"]: {k: v for k, v in r.items() if k != "wall_s"} for r in csv.DictReader(f)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "data" / "sweep-examples.json")
    ap.add_argument("--machine", default="this project's 2-core machine, quiet", help="what the file says of the machine and its load")
    a = ap.parse_args()
    commit = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=ROOT, capture_output=True, text=True, check=False).stdout.strip()  # -dirty: uncommitted changes
    found = []
    with tempfile.TemporaryDirectory() as d:
        for what, stem, args in EXAMPLES:
            got = {}
            for engine in ("batched", "sim"):
                out = Path(d) / f"{stem}-{len(found)}-{engine}"
                wall, cpu = sweep(stem, args, engine, out)
                got[engine] = (round(wall, 1), round(cpu, 1), rows(out))
                print(f"{what:45} {engine:8} {wall:7.1f} s wall {cpu:7.1f} s CPU", flush=True)
            same = got["batched"][2] == got["sim"][2]
            found.append({"what": what, "scenario": stem, "args": args, "runs": len(got["sim"][2]), "same_rows": same,
                          "batched_wall_s": got["batched"][0], "batched_cpu_s": got["batched"][1], "sim_wall_s": got["sim"][0], "sim_cpu_s": got["sim"][1]})
    a.out.write_text(json.dumps({
        "what": "docs/running.md's three sweeps, each timed as a user runs it (zswarm sweep --no-plots, --jobs at its default) on the batched engine and on sim",
        "command": "python bench/bench_sweep_examples.py",
        "measured": datetime.date.today().isoformat(),
        "commit": commit,
        "machine": a.machine,
        "made_again": "no: wall-clock and CPU seconds of this machine",
        "page": "docs/running.md",
        "rows": found,
    }, indent=1) + "\n")
    print(f"written: {a.out}")


if __name__ == "__main__":
    main()
