"""A link sweep on sim against the batched engine, in one run (issue 46): the README's §3.2
delay × drop sweep (40 grid points × 3 repeats of 40 s; ``--quick`` the issue's 40 runs of
10 s), each engine's ``zswarm sweep`` timed as a user runs it (wall time of the command, plots
included), batched and sim alternately ``--rounds`` times, and their rows compared column by
column (all but wall_s).

    .venv/bin/python bench/bench_links_sweep.py [--quick] [--rounds 1] [--keep DIR]
"""

from __future__ import annotations

import argparse
import csv
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FULL = ["--vary", "links.delay_ms=0,25,50,75,100,125,150,200", "--vary", "links.drop=0,0.125,0.25,0.375,0.5", "--repeats", "3"]
QUICK = ["--vary", "links.delay_ms=0,50,100,200", "--vary", "links.drop=0,0.25", "--set", "links.jitter_ms=10", "--set", "links.ge_p_gb=0.05", "--set", "links.ge_p_bg=0.3", "--repeats", "5", "--duration", "10"]


def sweep(engine: str, args: list[str], out: Path) -> float:
    cmd = [sys.executable, "-m", "zswarm", "sweep", str(ROOT / "topologies" / "thesis-3.2-fixed8.toml"), *args, "--engine", engine, "--out", str(out)]
    t0 = time.monotonic()
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.monotonic() - t0


def rows(out: Path) -> dict[str, dict[str, str]]:
    with open(out / "sweep.csv", newline="") as f:
        return {r["run_id"]: {k: v for k, v in r.items() if k != "wall_s"} for r in csv.DictReader(f)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the issue's 40 runs of 10 s instead of the README's 120 of 40 s")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--keep", type=Path, default=None, help="keep the sweeps' folders here")
    a = ap.parse_args()
    args = QUICK if a.quick else FULL
    tmp = Path(tempfile.mkdtemp(prefix="zswarm-bench-links-"))
    base = a.keep or tmp
    walls: dict[str, list[float]] = {"batched": [], "sim": []}
    try:
        for r in range(a.rounds):
            for engine in ("batched", "sim"):
                out = base / f"{engine}-{r}"
                shutil.rmtree(out, ignore_errors=True)
                walls[engine].append(sweep(engine, args, out))
                print(f"round {r}: {engine:8} {walls[engine][-1]:7.1f} s", flush=True)
            same = rows(base / f"batched-{r}") == rows(base / f"sim-{r}")
            print(f"round {r}: {len(rows(base / f'sim-{r}'))} runs, rows equal column by column (but wall_s): {same}", flush=True)
        b, s = min(walls["batched"]), min(walls["sim"])
        print(f"{' '.join(args)}\nwall time, best of {a.rounds}: sim {s:.1f} s, batched {b:.1f} s: {s / b:.1f}x")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
