"""The §5.6 basins under command delay and loss: what Theorem 5.1's global synchronization
still gives when the torques travel over a network.

For each of the three §5.6 laws (continuous, hybrid, velocity-free) and each command delay
(``--delays``, ms) and loss (``--losses``), ``zswarm basin`` draws ``--draws`` uniform starts
(the same starts in every cell: the draws are seeded by their number) on the batched engine,
the delay and loss on the agent→world command links (``links.commands``); with loss each draw
loses its own commands.  Each cell is a basin folder under ``--out`` (an existing one
resumes), then one figure (the fraction that synchronizes with its 95 % Wilson interval, and
the settle-time median with its 10-90 % band, against the delay), the table's rows as CSV
(``--csv``) and the Markdown table printed from them (:func:`markdown`, which
tests/component/test_publications.py holds the page's table to)::

    .venv/bin/python docs/examples/basin_under_delay.py --draws 1001 --out basins/delay \\
        --figure docs/figures/basin-delay-5.6.png --csv docs/data/basin-delay-5.6.csv
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import resource
import subprocess
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
LAWS = ("thesis-5.6-continuous7", "thesis-5.6-hybrid7", "thesis-5.6-velocity-free7")


def cell(out: Path, law: str, delay: float, loss: float) -> Path:
    return out / f"{law}-d{delay:g}-p{loss:g}"


def run(out: Path, law: str, delay: float, loss: float, draws: int, jobs: int | None) -> float:
    """One basin folder (resumed if there); the CPU seconds of its command (children included)."""
    d = cell(out, law, delay, loss)
    cmd = [sys.executable, "-m", "zswarm", "basin", str(ROOT / "topologies" / f"{law}.toml"), "--draws", str(draws), "--engine", "batched", "--out", str(d)]
    cmd += ["--set", f"links.commands.delay_ms={delay:g}", "--set", f"links.commands.drop={loss:g}"]
    if jobs:
        cmd += ["--jobs", str(jobs)]
    t0 = time.monotonic()
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    print(f"{d.name}: {time.monotonic() - t0:.0f} s of wall time, {cpu:.0f} s of CPU", file=sys.stderr, flush=True)
    return cpu


def summary(d: Path) -> dict:
    return json.loads((d / "basin.json").read_text())


# The table's columns: a cell (law, delay, loss), its counts, the Wilson interval in percent, the
# settle-time quantiles of the synchronized draws (blank: none), the ξ-jump quantiles, and where
# the cell's per-draw rows are (its basin folder).
COLUMNS = ("law", "delay_ms", "loss", "drawn", "synchronized", "ci95_lo_pct", "ci95_hi_pct", "settle_p10_s", "settle_median_s", "settle_p90_s", "jumps_median", "jumps_max", "rows")


def row(d: Path, law: str, delay: float, loss: float) -> dict:
    """A cell's row of the table, from its basin.json."""
    s = summary(d)
    ci = s.get("fraction_95ci") or [math.nan, math.nan]
    st = s.get("settle_s") or {}
    j = s.get("jumps") or {}
    return {
        "law": law.removeprefix("thesis-5.6-").removesuffix("7"),
        "delay_ms": f"{delay:g}",
        "loss": f"{loss:g}",
        "drawn": s["drawn"],
        "synchronized": s["synchronized"],
        "ci95_lo_pct": 100 * ci[0],
        "ci95_hi_pct": 100 * ci[1],
        **{f"settle_{q}_s": st.get(q, "") for q in ("p10", "median", "p90")},
        "jumps_median": j.get("median", ""),
        "jumps_max": j.get("max", ""),
        "rows": str(d / "basin.csv"),
    }


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def markdown(rows: list[dict]) -> str:
    """The Markdown table of the rows (as written or as read back from the CSV): times to 0.1 s,
    the interval to 0.1 %, "–" where no draw synchronized and for the continuous law's jumps (it
    has no ξ)."""

    def f1(x: object) -> str:
        return "–" if x in ("", None) else f"{float(x):.1f}"

    lines = [
        "| law | command delay (ms) | loss | synchronized | 95 % CI | settle < 0.01: p10 / median / p90 (s) | ξ jumps, median / max |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        settle = "–" if r["settle_median_s"] in ("", None) else " / ".join(f1(r[f"settle_{q}_s"]) for q in ("p10", "median", "p90"))
        jumps = "–" if r["law"] == "continuous" else f"{float(r['jumps_median']):g} / {float(r['jumps_max']):g}"
        ci = f"{f1(r['ci95_lo_pct'])}–{f1(r['ci95_hi_pct'])} %"
        lines.append(f"| {r['law']} | {r['delay_ms']} | {r['loss']} | {r['synchronized']} of {r['drawn']} | {ci} | {settle} | {jumps} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=1000)
    ap.add_argument("--delays", default="0,1,2,5", help="command delays, ms (default 0,1,2,5)")
    ap.add_argument("--losses", default="0,0.1", help="command loss probabilities (default 0,0.1)")
    ap.add_argument("--laws", default=",".join(LAWS))
    ap.add_argument("--jobs", type=int, default=None)
    ap.add_argument("--out", type=Path, default=Path("basins/delay"))
    ap.add_argument("--figure", type=Path, default=Path("basin-delay-5.6.png"))
    ap.add_argument("--csv", type=Path, default=None, help="write the table's rows there too (docs/data/basin-delay-5.6.csv)")
    a = ap.parse_args()
    delays = [float(x) for x in a.delays.split(",")]
    losses = [float(x) for x in a.losses.split(",")]
    laws = a.laws.split(",")
    cpu = 0.0
    for law in laws:
        for loss in losses:
            for delay in delays:
                cpu += run(a.out, law, delay, loss, a.draws, a.jobs)
    print(f"CPU of this invocation: {cpu:.0f} s ({cpu / 3600:.2f} h)", file=sys.stderr)

    table = [row(cell(a.out, law, delay, loss), law, delay, loss) for law in laws for loss in losses for delay in delays]
    print(markdown(table))
    if a.csv is not None:
        a.csv.parent.mkdir(parents=True, exist_ok=True)
        with open(a.csv, "w", newline="") as f:
            w = csv.DictWriter(f, COLUMNS, lineterminator="\n")
            w.writeheader()
            w.writerows(table)
        print(f"table: {a.csv}", file=sys.stderr)

    fig, axes = plt.subplots(2, len(laws), figsize=(4.2 * len(laws), 6.4), sharex=True, squeeze=False)
    for c, law in enumerate(laws):
        for loss, style in zip(losses, ("o-", "s--", "^:"), strict=False):
            frac, lo, hi, med, p10, p90 = [], [], [], [], [], []
            for delay in delays:
                s = summary(cell(a.out, law, delay, loss))
                ci = s.get("fraction_95ci") or [np.nan, np.nan]
                n, k = s["drawn"], s["synchronized"]
                frac.append(k / n)
                lo.append(ci[0])
                hi.append(ci[1])
                st = s.get("settle_s") or {}
                med.append(st.get("median", np.nan))
                p10.append(st.get("p10", np.nan))
                p90.append(st.get("p90", np.nan))
            x = np.array(delays)
            f = np.array(frac)
            axes[0, c].errorbar(x, f, yerr=[f - np.array(lo), np.array(hi) - f], fmt=style, capsize=3, label=f"loss {loss:g}")
            axes[1, c].plot(x, med, style, label=f"loss {loss:g}: median")
            axes[1, c].fill_between(x, p10, p90, alpha=0.2)
        axes[0, c].set_title(law.removeprefix("thesis-5.6-").removesuffix("7") + " law (§5.6)")
        axes[0, c].set_ylim(-0.03, 1.03)
        axes[0, c].set_ylabel("fraction synchronized (< 0.01 by 150 s)")
        axes[1, c].set_ylabel("settle time below 0.01 (s), 10–90 %")
        axes[1, c].set_xlabel("command delay (ms)")
        for ax in axes[:, c]:
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
    fig.suptitle(f"§5.6 basins under command delay and loss: {a.draws - 1} uniform starts per point (batched engine)")
    fig.tight_layout()
    a.figure.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(a.figure, dpi=110)
    print(f"figure: {a.figure}", file=sys.stderr)


if __name__ == "__main__":
    main()
