"""``zswarm basin-compare``: basin folders side by side — a Markdown table of their fractions
and settle times, the settle-time differences of folders that drew the same starts, and one
figure (the distributions; with ``--near`` folders, the time to leave against ε)."""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import math
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np

from zswarm.scenario import load
from zswarm.studies.basin import _f, ci_text, read_rows, starts_of, summarize, verdict_in
from zswarm.transport import procutil


def load_dir(d: Path) -> tuple[dict[str, Any], list[dict[str, str]]]:
    """A basin folder's definition (basin_def.json) and rows; ValueError naming what is missing."""
    spec_path, csv_path = d / "basin_def.json", d / "basin.csv"
    for p in (spec_path, csv_path):
        if not p.exists():
            raise ValueError(f"{d}: no {p.name} (not a zswarm basin folder)")
    try:
        spec = json.loads(spec_path.read_text())
        spec["scenario"], spec["threshold"], spec["duration_s"]
    except (ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{spec_path}: unreadable ({exc})") from exc
    return spec, read_rows(csv_path)


def _name(entry: dict[str, Any]) -> str:
    """A compared folder's name: its scenario and its ``--set`` overrides."""
    return str(entry.get("name") or entry["scenario"])


def compare(dirs: list[Path]) -> list[dict[str, Any]]:
    """One summary per basin folder (its scenario, start and settle-time quantiles), plus its
    drawn rows under ``"_rows"`` for the plot."""
    out = []
    for d in dirs:
        spec, rows = load_dir(d)
        words = (verdict_in(d / "basin.csv"), spec.get("measure", "the basin measure"))
        s = {"scenario": spec["scenario"], "dir": str(d), **summarize(rows, spec["threshold"], spec["duration_s"], spec.get("near"), *words)}
        s["name"] = " ".join([spec["scenario"], *spec.get("set", [])])  # with its --set overrides: one scenario under several link models
        s["_rows"] = [r for r in rows if r["status"] == "ok" and r["kind"] != "scenario"]
        s["_draws"] = (spec["seed"], spec.get("near"), sc_kind(spec))
        out.append(s)
    return out


def sc_kind(spec: dict[str, Any]) -> str:
    """What a folder's draws randomise, from its scenario's file when it can be read: two
    folders with the same seed, ``near`` and this drew the very same starts."""
    try:
        sc = load(spec["topology"])
    except Exception:  # noqa: BLE001 - moved or edited since: no pairing, the table still stands
        return "?"
    starts = starts_of(sc)
    own = [v for _, v in starts]
    digest = hashlib.sha256(np.round(np.array(own, dtype=float), 12).tobytes()).hexdigest()[:12]
    # the fields, with the agents' indexes left out: "agents[].R+agents[].estimate.Q"
    fields = "+".join(dict.fromkeys(re.sub(r"\[\d+\]", "[]", f) for f, _ in starts))
    return fields + "@" + digest


def paired(entries: list[dict[str, Any]]) -> list[str]:
    """For folders that drew the same starts (same seed, ``near`` and randomised attitudes) but
    ran different schemes: the settle-time differences draw by draw."""
    lines = []
    for i, a in enumerate(entries):
        for b in entries[i + 1 :]:
            if a["_draws"] != b["_draws"] or "?" in a["_draws"][2] or _name(a) == _name(b):
                continue
            sa = {r["draw"]: _f(r["settle_s"]) for r in a["_rows"]}
            sb = {r["draw"]: _f(r["settle_s"]) for r in b["_rows"]}
            d = np.array([sa[k] - sb[k] for k in sa.keys() & sb.keys() if math.isfinite(sa[k]) and math.isfinite(sb[k])])
            if len(d):
                how = "" if a.get("near_rad") is None else f" {a['near_rad']:g} rad from their own"
                lines.append(
                    f"paired on {len(d)} identical starts{how}: {_name(a)} − {_name(b)} settle time: median {np.median(d):+.2f} s, "
                    f"mean {d.mean():+.2f} s, from {d.min():+.2f} to {d.max():+.2f} s; {_name(a)} earlier in {int((d < 0).sum())} of {len(d)}"
                )
    return lines


def compare_table(entries: list[dict[str, Any]]) -> str:
    """A Markdown table: a row per basin folder."""

    def q(x: dict[str, float] | None, *keys: str, fmt: str = ".1f") -> str:
        return "–" if x is None else " / ".join(format(x[k], fmt) for k in keys)

    def own_settle(own: dict[str, Any]) -> str:
        if not own:
            return "–"
        t = _f(own.get("settle_s", ""))
        return f"{t:.2f}" if math.isfinite(t) else "never"

    verdicts = {s["verdict"] for s in entries}
    word = verdicts.pop() if len(verdicts) == 1 else "settled"
    lines = [
        f"| scenario | start | {word} | 95 % CI | below threshold, min / median / p90 / max (s) | below 0.1, median (s) | below 0.9, median (s) | jumps, median / max | its own start, below threshold (s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for s in entries:
        ci = s["fraction_95ci"]
        start = "uniform" if s["start"] == "uniform" else f"{s['near_rad']:g} rad from its own"
        own = s["scenario_start"] or {}
        lines.append(
            f"| {s['name']} | {start} | {s[s['verdict']]} of {s['drawn']} (< {s['threshold']:g} by {s['horizon_s']:g} s) | "
            + (ci_text(ci, "–") if ci else "–")
            + f" | {q(s['settle_s'], 'min', 'median', 'p90', 'max')} | {q(s['settle_01_s'], 'median')} | {q(s.get('left_s'), 'median')} | {q(s['jumps'], 'median', 'max', fmt='g')} | {own_settle(own)} |"
        )
    return "\n".join(lines)


SCENARIO_CMAPS = ("Blues", "Oranges", "Greens", "Purples", "Reds", "Greys")  # a hue per scenario of a comparison


def plot_compare(entries: list[dict[str, Any]], path: Path) -> Path:
    """Left: each folder's settle times (below its threshold) as a distribution; right (when
    some folders start near the scenario's start): settle time against the distance ε."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    near = [s for s in entries if s["start"] == "near"]
    names = list(dict.fromkeys(s["scenario"] for s in entries))
    fig, axes = plt.subplots(1, 2 if near else 1, figsize=(14 if near else 9, 4.6), squeeze=False)
    a1 = axes[0][0]
    # One hue per scenario, and within it a shade per folder (darkest: the smallest ε), so no two
    # curves share a colour however many folders there are (a 10-colour cycle repeated at 11).
    shades: dict[int, Any] = {}
    for name, cmap in zip(names, itertools.cycle(SCENARIO_CMAPS)):
        mine = [n for n, s in enumerate(entries) if s["scenario"] == name]
        mine.sort(key=lambda n: entries[n].get("near_rad") or math.inf)
        for k, n in enumerate(mine):
            shades[n] = plt.get_cmap(cmap)(0.95 - 0.6 * k / max(1, len(mine) - 1)) if len(mine) > 1 else plt.get_cmap(cmap)(0.8)
    for n, s in enumerate(entries):
        v = np.sort([_f(r["settle_s"]) for r in s["_rows"] if r[s["verdict"]] == "True"])
        label = f"{s['name']}, " + ("uniform" if s["start"] == "uniform" else f"ε = {s['near_rad']:g}") + f" ({s[s['verdict']]}/{s['drawn']})"
        a1.step(np.r_[0.0, v], np.r_[0.0, np.arange(1, len(v) + 1)] / max(1, s["drawn"]), where="post", label=label, color=shades[n])
        own = _f((s["scenario_start"] or {}).get("settle_s", ""))
        if math.isfinite(own):
            a1.axvline(own, color=shades[n], ls=":", lw=1)
    a1.set_xlabel("settle time below the threshold (s); dotted: the scenario's own start")
    verdicts = {s["verdict"] for s in entries}
    a1.set_ylabel(f"fraction of the draws {verdicts.pop() if len(verdicts) == 1 else 'settled'}")
    a1.set_xlim(0, max(s["horizon_s"] for s in entries))
    a1.set_ylim(0, 1.02)
    a1.grid(alpha=0.3)
    a1.legend(fontsize=6.5, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    if near:
        # Right: how long each start took to leave the undesired set (the measure < 0.9) against
        # ε, which is what ε changes (a saddle's escape grows like ln 1/ε); the settle times are left.
        a2 = axes[0][1]

        def band(ss: list[dict[str, Any]], key: str) -> tuple[np.ndarray, ...]:
            return tuple(np.array([math.nan if s.get(key) is None else s[key][k] for s in ss]) for k in ("median", "min", "max"))

        for (name, cmap), marker in zip(zip(names, itertools.cycle(SCENARIO_CMAPS)), itertools.cycle("osD^v")):
            ss = sorted((s for s in near if s["scenario"] == name), key=lambda s: s["near_rad"])
            if not ss:
                continue
            color = plt.get_cmap(cmap)(0.8)
            eps = np.array([s["near_rad"] for s in ss])
            med, lo, hi = band(ss, "left_s")
            a2.plot(eps, med, marker=marker, ls="-", color=color, label=f"{name} (median, min–max)")
            a2.fill_between(eps, lo, hi, color=color, alpha=0.2)
            own = _f((ss[0]["scenario_start"] or {}).get("left_s", ""))
            if math.isfinite(own):
                a2.axhline(own, color=color, ls="-.", lw=1, label=f"{name}: its own start, {own:g} s")
        a2.set_xscale("log")
        a2.set_xlabel("ε: distance of the start from the scenario's own (rad)")
        measures = {s["measure"] for s in near}
        a2.set_ylabel(f"time to leave: {measures.pop() if len(measures) == 1 else 'the measure'} < 0.9 (s)")
        a2.set_ylim(bottom=0)
        a2.grid(alpha=0.3, which="both")
        a2.legend(fontsize=7)
    what = "settle times" + (" and the time to leave the start against its distance ε" if near else "")
    fig.suptitle(f"{', '.join(names)}: {what}", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path



def compare_command(args: argparse.Namespace) -> int:
    try:
        entries = compare(args.dirs)
    except ValueError as exc:
        procutil.fail_usage(str(exc))
    print(compare_table(entries))
    for line in paired(entries):
        print(f"\n{line}")
    sys.stdout.flush()  # the table before the figure's line on stderr, also through a pipe
    if args.out.parent != Path(""):
        args.out.parent.mkdir(parents=True, exist_ok=True)
    print(f"figure: {plot_compare(entries, args.out)}", file=sys.stderr)
    return 0
