"""Benchmark: ``zswarm sim`` of this tree against an earlier commit, alternately, same machine.

For each round, runs ``python -m zswarm sim SCENARIO --duration D --no-plots`` with this
tree's code and with the code of ``--ref`` (a git worktree made for it), one after the
other, so that a machine whose speed drifts (other work, thermal, a VM neighbour) drifts
for both.  Prints per run the wall time of the whole command and, for this tree, the
phases it reports (the run, the recording written after it, the report), then the
medians and the ratio.  Results are compared too: ``errors.csv`` must be identical
(the in-process engine's changes are bookkeeping, never numerics).

Usage: python bench/bench_sim.py [--ref 631834b] [--topology F] [--duration 40] [--rounds 3]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import sysconfig
import tempfile
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _worktree(ref: str, base: Path) -> Path:
    path = base / f"ref-{ref}"
    if not path.exists():
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-f", str(path), ref], check=True, capture_output=True)
    return path


def _build_kernels(tree: Path) -> None:
    """Compile the tree's C loops (each ``_kernels.c`` under ``zswarm/``) in place, with the flags
    pyproject.toml gives them, so an earlier commit runs with its compiled loops as its install
    had them (a worktree has only the sources; without the loops it would run slower than it was)."""
    suffix = sysconfig.get_config_var("EXT_SUFFIX")
    for src in sorted((tree / "zswarm").rglob("_kernels.c")):
        so = src.with_name("_kernels" + suffix)
        if not so.exists():
            subprocess.run(
                ["gcc", "-shared", "-fPIC", "-O2", "-ffp-contract=off", "-fno-math-errno", "-Wno-psabi", f"-I{sysconfig.get_paths()['include']}", str(src), "-lm", "-o", str(so)],
                check=True,
            )


def _entry_points(tree: Path) -> None:
    """Give the tree its own distribution metadata (its pyproject's entry points: algorithms, report
    families) ahead of the installed one on PYTHONPATH, so an earlier commit finds its own plugins,
    not this tree's."""
    meta = tomllib.loads((tree / "pyproject.toml").read_text())["project"]
    info = tree / f"zswarm-{meta.get('version', '0')}.dist-info"
    info.mkdir(exist_ok=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: zswarm\nVersion: {meta.get('version', '0')}\n")
    groups = meta.get("entry-points", {})
    if "scripts" in meta:
        groups = {"console_scripts": meta["scripts"], **groups}
    (info / "entry_points.txt").write_text("".join(f"[{g}]\n" + "".join(f"{k} = {v}\n" for k, v in eps.items()) + "\n" for g, eps in groups.items()))


def _run(code: Path, topology: str, duration: float, out: Path) -> tuple[float, dict[str, float]]:
    env = dict(os.environ, PYTHONPATH=str(code))
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "zswarm", "sim", topology, "--duration", str(duration), "--no-plots", "--quiet", "--out", str(out)],
        cwd=code, env=env, check=True, capture_output=True,
    )
    wall = time.perf_counter() - t0
    s = json.loads((out / "summary.json").read_text())
    phases = {k: float(s[k]) for k in ("wall_time_s", "wall_time_run_s", "wall_time_recording_s", "wall_time_report_s") if k in s}
    return wall, phases


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ref", default="631834b", help="the commit to compare with (default 631834b, before issue 28)")
    ap.add_argument("--topology", default=str(ROOT / "topologies" / "thesis-3.2-fixed8.toml"))
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="zswarm-bench-sim-") as tmp:
        base = Path(tmp)
        ref = _worktree(args.ref, base)
        _build_kernels(ref)
        _entry_points(ref)
        try:
            walls: dict[str, list[float]] = {"this tree": [], args.ref: []}
            runs: list[float] = []
            for r in range(args.rounds):
                for name, code in (("this tree", ROOT), (args.ref, ref)):
                    out = base / f"{name.replace(' ', '_')}-{r}"
                    topo = Path(args.topology).resolve()
                    if topo.is_relative_to(ROOT):  # the tree's own copy: the scenario format may have changed since
                        topo = code / topo.relative_to(ROOT)
                    wall, ph = _run(code, str(topo), args.duration, out)
                    walls[name].append(wall)
                    extra = ""
                    if "wall_time_run_s" in ph:
                        runs.append(ph["wall_time_run_s"])
                        extra = f"  (run {ph['wall_time_run_s']:.2f} s = {args.duration / ph['wall_time_run_s']:.1f}x real time, recording {ph['wall_time_recording_s']:.2f} s, report {ph['wall_time_report_s']:.2f} s)"
                    elif "wall_time_s" in ph:
                        extra = f"  (simulate {ph['wall_time_s']:.2f} s = {args.duration / ph['wall_time_s']:.1f}x real time, recording included)"
                    print(f"round {r + 1} {name:>10}: {wall:6.2f} s for the command{extra}", flush=True)
                same = (base / f"this_tree-{r}" / "errors.csv").read_bytes() == (base / f"{args.ref.replace(' ', '_')}-{r}" / "errors.csv").read_bytes()
                print(f"round {r + 1} errors.csv {'identical' if same else 'DIFFERENT'}", flush=True)
            m_new, m_ref = statistics.median(walls["this tree"]), statistics.median(walls[args.ref])
            print(f"median command: this tree {m_new:.2f} s, {args.ref} {m_ref:.2f} s: {m_ref / m_new:.2f}x")
            if runs:
                print(f"median run phase of this tree: {statistics.median(runs):.2f} s = {args.duration / statistics.median(runs):.1f}x real time")
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(ref)], check=False, capture_output=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
