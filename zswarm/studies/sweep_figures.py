"""The figures of ``zswarm sweep``: each of the family's four metrics against each varied field
(mean and min–max over repeats) and, for two fields, a heatmap."""

from __future__ import annotations

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
    """sweep.csv's whole rows, one per run (a torn row is left out: zswarm.util.rows)."""
    from zswarm.util import rows

    return list({r.get("run_id", str(n)): r for n, r in enumerate(rows.read(path).rows)}.values())


def remove_figures(out: Path) -> None:
    """Remove the figures :func:`plot_sweep` writes (``sweep_*.png``) from ``out``: an earlier
    run's would not show the folder's sweep.csv once it is written again without them."""
    for old in out.glob("sweep_*.png"):
        old.unlink()


def plot_sweep(
    out: Path, rows: list[dict[str, str]], fields: Sequence[str], duration: float, metrics: Sequence[tuple[str, str, bool]] = DEFAULT_FIGURES, scenario: str = ""
) -> list[Path]:
    """``sweep_<field>.png`` per varied field (each metric against it, mean ± min/max over
    repeats, one line per value of the other field when there are two) and, for two
    fields, ``sweep_heatmap.png``, each titled with ``scenario`` and what varies.  A run that
    never converged counts as ``duration`` in the means and is marked; failed runs are left
    out.  The lines of a numeric field's values go from dark to light (viridis) with a marker
    each, so neighbouring values are told apart past ten lines; a heatmap's numbers are
    black or white by the cell's colour."""
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

    n_runs = len(ok)
    for fi, fld in enumerate(fields):
        others = [f for n, f in enumerate(fields) if n != fi]
        groups: dict[str, list[dict[str, str]]] = {}
        for r in ok:
            groups.setdefault(" ".join(f"{o}={r[o]}" for o in others), []).append(r)
        ordered = sorted(groups.items(), key=lambda kv: [_key(kv[1][0][o]) for o in others])
        colors = plt.cm.viridis(np.linspace(0.0, 0.85, len(ordered))) if len(ordered) > 1 else [None]
        fig, axes = plt.subplots(2, 2, figsize=(11, 7.5))
        for ax, (m, label, log) in zip(axes.ravel(), metrics, strict=True):
            for gi, (gname, grs) in enumerate(ordered):
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
                line = ax.errorbar(
                    xv, mean_a, yerr=[np.maximum(mean_a - lo_a, 0), np.maximum(hi_a - mean_a, 0)],
                    marker=MARKERS[gi % len(MARKERS)], ms=4, capsize=2, lw=1, label=gname or None, color=colors[gi % len(colors)],
                )
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
        per = f", one line per {', '.join(others)}" if others else ""
        fig.suptitle(f"{scenario + ': ' if scenario else ''}against {fld}{per} ({n_runs} runs)", fontsize=12, y=0.995, va="top")
        if lab and len(lab) <= 12:
            fig.legend(h, lab, loc="upper center", bbox_to_anchor=(0.5, 0.955), ncol=min(6, len(lab)), fontsize=8)
        fig.text(0.5, 0.005, f"mean and min–max over repeats; x: a repeat that never converged (counted as {duration:g} s)", fontsize=9, ha="center", va="bottom")
        fig.tight_layout(rect=(0, 0.02, 1, 0.90 if lab else 0.95))
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
            size = 9 if len(xs) <= 8 else 7
            for a in range(len(ys)):
                for b in range(len(xs)):
                    if math.isfinite(Z[a, b]):
                        r_, g_, b_, _ = im.cmap(im.norm(Z[a, b]))
                        ink = "black" if 0.299 * r_ + 0.587 * g_ + 0.114 * b_ > 0.5 else "white"  # legible on the cell's colour
                        ax.text(b, a, f"{Z[a, b]:.3g}" + ("*" if nev[a, b] else ""), ha="center", va="center", fontsize=size, color=ink)
            ax.set_xticks(range(len(xs)), xs)
            ax.set_yticks(range(len(ys)), ys)
            ax.set_xlabel(fx)
            ax.set_ylabel(fy)
            ax.set_title(label, fontsize=10)
            fig.colorbar(im, ax=ax)
        fig.suptitle(f"{scenario + ': ' if scenario else ''}{fy} against {fx} ({n_runs} runs)", fontsize=12, y=0.995, va="top")
        fig.text(0.5, 0.005, f"mean over repeats; *: some repeat never converged (counted as {duration:g} s)", fontsize=9, ha="center", va="bottom")
        fig.tight_layout(rect=(0, 0.03, 1, 0.94))
        p = out / "sweep_heatmap.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        written.append(p)
    return written


MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "h")


def _safe(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "._-" else "_" for ch in name)
