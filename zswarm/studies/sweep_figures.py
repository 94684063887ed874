"""The figures of ``zswarm sweep``: each of the family's four metrics against each varied field
(mean and min–max over repeats) and, for two fields, a heatmap."""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from zswarm.families.contract import DEFAULT_FIGURES


def _float(x: str) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")


def _key(x: str) -> Any:
    v = _float(x)
    return (0, v, "") if math.isfinite(v) else (1, 0.0, x)


def load_rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def plot_sweep(out: Path, rows: list[dict[str, str]], fields: Sequence[str], duration: float, metrics: Sequence[tuple[str, str, bool]] = DEFAULT_FIGURES) -> list[Path]:
    """``sweep_<field>.png`` per varied field (each metric against it, mean ± min/max over
    repeats, one line per value of the other field when there are two) and, for two
    fields, ``sweep_heatmap.png``.  A run that never converged counts as ``duration``
    in the means and is marked; failed runs are left out."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if r["status"] == "ok"]
    written: list[Path] = []
    if not ok:
        return written
    metrics = (list(metrics) + [m for m in DEFAULT_FIGURES if m not in metrics])[:4]  # a family's four (fewer: the team's own fill in)

    def val(r: dict[str, str], m: str) -> float:
        v = _float(r[m])
        return duration if (m.startswith("conv_") and not math.isfinite(v)) else v

    for fi, fld in enumerate(fields):
        others = [f for n, f in enumerate(fields) if n != fi]
        groups: dict[str, list[dict[str, str]]] = {}
        for r in ok:
            groups.setdefault(" ".join(f"{o}={r[o]}" for o in others), []).append(r)
        fig, axes = plt.subplots(2, 2, figsize=(11, 7.5))
        for ax, (m, label, log) in zip(axes.ravel(), metrics, strict=True):
            for gname, grs in sorted(groups.items(), key=lambda kv: [_key(kv[1][0][o]) for o in others]):
                xs = sorted({r[fld] for r in grs}, key=_key)
                mean, lo, hi, never = [], [], [], []
                for x in xs:
                    v = np.array([val(r, m) for r in grs if r[fld] == x])
                    v = v[np.isfinite(v)]
                    mean.append(v.mean() if len(v) else np.nan)
                    lo.append(v.min() if len(v) else np.nan)
                    hi.append(v.max() if len(v) else np.nan)
                    never.append(m.startswith("conv_") and any(not math.isfinite(_float(r[m])) for r in grs if r[fld] == x))
                xv = np.array([_float(x) for x in xs])
                if not np.all(np.isfinite(xv)):
                    xv = np.arange(len(xs), dtype=float)
                    ax.set_xticks(xv, xs)
                mean_a, lo_a, hi_a = np.array(mean), np.array(lo), np.array(hi)
                line = ax.errorbar(xv, mean_a, yerr=[np.maximum(mean_a - lo_a, 0), np.maximum(hi_a - mean_a, 0)], marker="o", ms=3, capsize=2, lw=1, label=gname or None)
                nv = np.array(never)
                if nv.any():
                    ax.plot(xv[nv], mean_a[nv], "x", ms=8, color=line[0].get_color())
            if log:
                ax.set_yscale("log")
            if m.startswith("conv_") and any(not math.isfinite(_float(r[m])) for r in ok):
                ax.axhline(duration, color="0.6", lw=0.8, ls=":")  # where "never converged" is drawn
            ax.set_xlabel(fld)
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
        h, lab = axes[0, 0].get_legend_handles_labels()
        if lab and len(lab) <= 12:
            fig.legend(h, lab, loc="upper center", ncol=min(6, len(lab)), fontsize=8)
        fig.suptitle(f"mean and min–max over repeats; x: a repeat that never converged (counted as {duration:g} s)", fontsize=9, y=0.005, va="bottom")
        fig.tight_layout(rect=(0, 0.02, 1, 0.93 if lab else 1))
        p = out / f"sweep_{_safe(fld)}.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        written.append(p)

    if len(fields) == 2:
        fx, fy = fields
        xs = sorted({r[fx] for r in ok}, key=_key)
        ys = sorted({r[fy] for r in ok}, key=_key)
        fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
        for ax, (m, label, log) in zip(axes, (metrics[1], metrics[2], metrics[3]), strict=True):
            Z = np.full((len(ys), len(xs)), np.nan)
            nev = np.zeros_like(Z, dtype=bool)
            for a, y in enumerate(ys):
                for b, x in enumerate(xs):
                    rs = [r for r in ok if r[fx] == x and r[fy] == y]
                    v = np.array([val(r, m) for r in rs])
                    v = v[np.isfinite(v)]
                    if len(v):
                        Z[a, b] = v.mean()
                    nev[a, b] = m.startswith("conv_") and any(not math.isfinite(_float(r[m])) for r in rs)
            norm = matplotlib.colors.LogNorm() if log and np.nanmin(Z) > 0 else None
            im = ax.imshow(Z, origin="lower", aspect="auto", norm=norm, cmap="viridis")
            for a in range(len(ys)):
                for b in range(len(xs)):
                    if math.isfinite(Z[a, b]):
                        txt = f"{Z[a, b]:.3g}"
                        ax.text(b, a, txt + ("*" if nev[a, b] else ""), ha="center", va="center", fontsize=7, color="w")
            ax.set_xticks(range(len(xs)), xs)
            ax.set_yticks(range(len(ys)), ys)
            ax.set_xlabel(fx)
            ax.set_ylabel(fy)
            ax.set_title(label, fontsize=10)
            fig.colorbar(im, ax=ax)
        fig.suptitle(f"mean over repeats; *: some repeat never converged (counted as {duration:g} s)", fontsize=9, y=0.005, va="bottom")
        fig.tight_layout(rect=(0, 0.03, 1, 1))
        p = out / "sweep_heatmap.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        written.append(p)
    return written


def _safe(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "._-" else "_" for ch in name)
