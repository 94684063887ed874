"""Soak: one long `zswarm run`, the memory (RSS) of every process sampled every minute.

Prints a line per sample (RSS in MiB per process) and, at the end, each process's
growth after the warm-up (:func:`evaluate`: the median of the last 5 minutes over the
median of the first 5 after it).  The run passes when every process stays within
--tolerance (10 %).  Writes soak.csv (minute, process, RSS MiB) in --out.

The launcher is SIGKILLed after the last sample (its children stop cleanly on the
SIGTERM the kernel sends them, zswarm/procutil.die_with_parent): an hour of recording
is not transcoded into a report, which a soak does not need.

Usage: python bench/soak.py [--minutes 60] [--warmup 5] [--topology F] [--time-scale X] [--out DIR]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def rss_mib(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def evaluate(rows: list[tuple[float, str, float]], warmup: float, tolerance: float, span: float = 5.0) -> bool:
    """Print each process's growth and say whether all stayed within ``tolerance``.

    Growth is the median RSS of the last ``span`` minutes over the median of the first
    ``span`` minutes after ``warmup``: medians, so that one sample caught in a burst (the
    recorder's RSS jumps by 10 MiB for a minute when it falls behind and catches up) does
    not become the reference (which hid growth: a reference on a spike reads as none) or
    the end.  The largest sample is printed beside it."""
    ok = True
    print(f"\nRSS growth after {warmup:g} min of warm-up (median of the last {span:g} min over the median of the first {span:g} after warm-up):")
    for name in sorted({r[1] for r in rows}):
        after = [(m, v) for m, k, v in rows if k == name and m >= warmup]
        if len(after) < 2:
            continue
        first = statistics.median(v for m, v in after if m <= after[0][0] + span)
        last = statistics.median(v for m, v in after if m >= after[-1][0] - span)
        growth = last / first - 1
        ok &= growth <= tolerance
        print(f"  {name:<16} {first:7.1f} -> {last:7.1f} MiB (max {max(v for _, v in after):7.1f}): {100 * growth:+5.1f} %")
    return ok


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--warmup", type=float, default=5.0, help="minutes before the reference sample")
    ap.add_argument("--every", type=float, default=60.0, help="seconds between samples")
    ap.add_argument("--tolerance", type=float, default=0.10)
    ap.add_argument("--topology", default=str(ROOT / "topologies" / "thesis-3.2-fixed8.toml"))
    ap.add_argument("--time-scale", type=float, default=1.0)
    ap.add_argument("--out", type=Path, default=Path("runs") / f"soak-{time.strftime('%Y%m%d-%H%M%S')}")
    args = ap.parse_args()
    duration = (args.minutes * 60 + 120) * args.time_scale  # world seconds: the run outlasts the samples
    args.out.mkdir(parents=True, exist_ok=True)
    cmd = [
        sys.executable,
        "-m",
        "zswarm",
        "run",
        args.topology,
        "--duration",
        f"{duration:g}",
        "--time-scale",
        f"{args.time_scale:g}",
        "--out",
        str(args.out / "run"),
        "--quiet",
    ]
    with open(args.out / "launcher.log", "wb") as log:
        launcher = subprocess.Popen(cmd, cwd=ROOT, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    rows: list[tuple[float, str, float]] = []
    try:
        procs_file = args.out / "run" / "processes.json"
        while not procs_file.exists():
            if launcher.poll() is not None:
                print((args.out / "launcher.log").read_text())
                return 1
            time.sleep(0.2)
        world_log = args.out / "run" / "logs" / "world.log"
        while not (world_log.exists() and "start:" in world_log.read_text()):
            time.sleep(0.2)
        rec = next((c["pid"] for c in json.loads(procs_file.read_text())["children"] if c["role"] == "recorder"), None)
        if rec is not None:
            try:
                with open(f"/proc/{rec}/maps") as f:
                    print(f"recorder malloc: {'jemalloc' if 'libjemalloc' in f.read() else 'libc'}", flush=True)
            except OSError:
                pass
        t0 = time.monotonic()
        n = 0
        while n * args.every <= args.minutes * 60:
            time.sleep(max(0.0, t0 + n * args.every - time.monotonic()))
            kids = json.loads(procs_file.read_text())["children"]
            pids = {c["name"]: c["pid"] for c in kids} | {"launcher+router": launcher.pid}
            sample = {k: rss_mib(p) for k, p in pids.items()}
            minute = n * args.every / 60
            for k, v in sample.items():
                if v is not None:
                    rows.append((minute, k, v))
            print(f"{minute:6.1f} min  " + "  ".join(f"{k}={v:.1f}" for k, v in sorted(sample.items()) if v is not None), flush=True)
            n += 1
    finally:
        if launcher.poll() is None:
            os.kill(launcher.pid, signal.SIGKILL)  # the children stop on their own (PR_SET_PDEATHSIG)
            launcher.wait()
    with open(args.out / "soak.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["minute", "process", "rss_mib"])
        w.writerows(rows)
    ok = evaluate(rows, args.warmup, args.tolerance)
    print(
        f"\nPASS: every process within {100 * args.tolerance:g} % of its RSS after warm-up"
        if ok
        else f"\nFAIL: some process grew more than {100 * args.tolerance:g} %"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
