"""Draw docs/figures/architecture.png: zswarm's layers (each subpackage's modules, read from
the package, with its job, in the order tests/unit/test_layers.py enforces) beside the data
path of one run.

    python docs/architecture_figure.py
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.unit.test_layers import LAYERS  # noqa: E402 - the order the test enforces

OUT = ROOT / "docs" / "figures" / "architecture.png"

PATH = (
    ("scenario.toml", "agents, graph, algorithm and gains, world, sensors, clocks, links, faults"),
    ("zswarm.scenario.load", "a typed, checked Scenario (file: field: problem, exit 2)"),
    ("programs", "one per process: AgentProgram (its entry, algorithm, typed gains, links), WorldProgram"),
    ("processes", "world (truth, sensors), one agent per process (AgentNode + the algorithm's step), recorder"),
    ("Zenoh bus", "keys from the graph's edges; at each receiver the link model (delay, jitter, loss, cuts)"),
    ("recorder", "recording.mcap: every message, truth, link events (Foxglove, Rerun)"),
    ("zswarm.results", "summary.json, errors.csv, the family's CSVs and figures, the table"),
    ("zswarm.studies", "many runs: sweep.csv, basin.csv, on sim, run or the batched engine"),
)


def layers() -> list[tuple[str, str, list[str]]]:
    out = []
    for name in LAYERS:
        pkg = ROOT / "zswarm" / name
        mods = sorted(p.stem for p in pkg.glob("*.py") if p.name != "__init__.py")
        out.append((name, LAYERS[name], mods))
    return out


def main() -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

    fig = plt.figure(figsize=(15, 9.2))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, 15)
    ax.set_ylim(0, 9.2)
    ax.axis("off")

    # Left: the layers, bottom up; arrows only point down (tests/unit/test_layers.py).
    rows = [("cli", "the command line: zswarm COMMAND (argparse), above every layer", ["cli", "__main__"]), *reversed(layers())]
    top, h, gap = 8.55, 0.66, 0.08
    ax.text(0.3, 8.95, "zswarm/: layers, bottom up (a module imports its own layer and those below)", fontsize=11, weight="bold", va="center")
    for k, (name, job, mods) in enumerate(rows):
        y = top - k * (h + gap)
        color = "#fde9c9" if name == "cli" else "#e3eef9" if k % 2 else "#d3e3f4"
        ax.add_patch(FancyBboxPatch((0.3, y - h), 7.6, h, boxstyle="round,pad=0.02", fc=color, ec="#4a6a8a", lw=0.8))
        ax.text(0.45, y - 0.2, name, fontsize=10.5, weight="bold", va="center")
        ax.text(1.85, y - 0.2, job, fontsize=8, va="center", color="#333")
        listing = "  ".join(mods)
        # 7.5 pt monospace fills the box's width at about 105 characters: a longer list is set smaller.
        ax.text(0.45, y - 0.48, listing, fontsize=min(7.5, 7.5 * 105 / len(listing)), va="center", family="monospace", color="#1f3d5c")
    y_last = top - len(rows) * (h + gap)
    ax.text(0.3, y_last - 0.05, "agent/ (the agent program, algorithms, the batched engine) and world/ (truth, sensors) import zswarm;\nzswarm imports neither: sim and the batched engine find them by entry point.", fontsize=8, va="top", color="#333")

    # Right: one run's data path.
    ax.text(8.6, 8.95, "one run: from the file to the figures", fontsize=11, weight="bold", va="center")
    bh = 0.74
    bgap = (8.55 - 0.25 - len(PATH) * bh) / (len(PATH) - 1)  # the column fills the page down to its margin
    for k, (what, detail) in enumerate(PATH):
        y = 8.55 - k * (bh + bgap)
        ax.add_patch(FancyBboxPatch((8.6, y - bh), 6.1, bh, boxstyle="round,pad=0.02", fc="#eaf5e4", ec="#4f7a3a", lw=0.8))
        ax.text(8.75, y - 0.25, what, fontsize=10, weight="bold", va="center")
        ax.text(8.75, y - 0.53, detail, fontsize=7.8, va="center", color="#333")
        if k:
            ax.add_patch(FancyArrowPatch((11.65, y + bgap - 0.02), (11.65, y + 0.02), arrowstyle="-|>", mutation_scale=12, color="#4f7a3a"))
    fig.savefig(OUT, dpi=110)
    plt.close(fig)
    return OUT


if __name__ == "__main__":
    print(main())
