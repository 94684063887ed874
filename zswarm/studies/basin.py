"""``zswarm basin``: a Monte-Carlo check of a scheme's global claims on ``sim``.

Theorems 5.1/5.2 (and 4.2 for the §4.5 hybrid observer) claim global
asymptotic stability; the continuous laws (5.24)/(4.8) only almost global.
This draws N initial conditions and runs each on ``sim`` (the same World and
AgentNode objects as every other run, in worker processes):

* draw 0 is the scenario's own start (the thesis' adversarial one: every
  R̄_k on the undesired set);
* draws 1..N-1: for the Chapter 5 laws every R_i(0) uniform on SO(3) (and,
  for the velocity-free law, every Q_i(0) too: Theorem 5.2 is global in the
  auxiliary state as well), ω(0) = 0, ξ(0) = ζ(0) = 0 as in §5.6; for the §4
  observers every estimate R̂_i(0) uniform, the truth as in the scenario;
* or, with ``near = ε``, the same quantities perturbed instead: the
  scenario's own value times exp(ε [n]×), n a uniform unit axis.  Uniform
  draws land on the undesired set with probability 0, so they cannot tell a
  global law from an almost-global one; starts ε from that set can: the
  continuous law needs ≈ ln(1/ε)/λ to leave it (λ its instability rate), the
  hybrid laws jump away at once.

Uniform on SO(3): the unit quaternion of four standard normals (Shoemake's
subgroup algorithm gives the same law), from ``numpy.random.default_rng([seed,
draw])``, so a draw is the same whatever the number of workers.

A draw *settles* when its family's basin measure (:class:`zswarm.families.contract.Basin`:
max_k |R̄_k|_I, of the truth for the laws, of the estimates for the observers)
stays below the threshold (0.01) from some time before the horizon on; the
family names that verdict ("synchronized") and the measure.  Results: ``basin.csv`` (a row per draw, written as they finish;
the same command with the same ``--out`` resumes), ``basin.json`` (fractions,
settle-time quantiles) and ``basin.png`` (the settle times' distribution).
"""

from __future__ import annotations

import argparse
import csv
import functools
import json
import math
import sys
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, wait
from pathlib import Path
from typing import Any

import numpy as np

from zswarm import report
from zswarm.engines import cluster as zswarm_cluster
from zswarm.families import contract as family
from zswarm.families.contract import Basin
from zswarm.report.series import leave_time, settle_time
from zswarm.scenario import Override, Scenario, load, loads, parse_override, with_rotations
from zswarm.studies.sweep import _fmt  # the same CSV cells as sweep.csv
from zswarm.transport import procutil
from zswarm.util import files, rows
from zswarm.util.progress import Progress

# Draws stepped together at most (a chunk: one task of the pool; resume reruns a whole chunk).
# Past ~1000 the per-call cost of numpy is paid off (agent/batched.py's benchmark).
MAX_CHUNK = 1000
PROGRESS_EVERY_S = 30.0  # wall seconds between a running chunk's progress lines
AFTER_VERDICT = ("left_s", "settle_01_s", "settle_s", "final_max", "initial_max", "jumps", "agent_jumps", "wall_s", "status", "error")


def columns(verdict: str) -> tuple[str, ...]:
    """basin.csv's columns: the draw, its kind, the family's verdict (True/False), the rest."""
    return ("draw", "kind", verdict, *AFTER_VERDICT)


def basin_of(sc: Scenario) -> Basin:
    """The scenario's family's part of the basin check; ValueError when it has none."""
    b = family.of(sc).basin
    if b is None:
        raise ValueError(f"{sc.name}: the experiment family of {sc.algorithm}, {sc.info.report!r}, declares no basin check (zswarm.families.contract.Basin)")
    return b


def uniform_rotation(rng: np.random.Generator) -> np.ndarray:
    """A rotation uniform on SO(3) (Haar): the unit quaternion of four standard normals."""
    q = rng.normal(size=4)
    w, x, y, z = (q / np.linalg.norm(q)).tolist()  # Python floats: the same arithmetic as numpy's scalars, a fifth of the time
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def near_rotation(R: np.ndarray, eps: float, rng: np.random.Generator) -> np.ndarray:
    """R exp(ε [n]×), n uniform on the unit sphere (Rodrigues' formula)."""
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    K = np.array([[0.0, -n[2], n[1]], [n[2], 0.0, -n[0]], [-n[1], n[0], 0.0]])
    return R @ (np.eye(3) + math.sin(eps) * K + (1.0 - math.cos(eps)) * (K @ K))


def _rows(R: np.ndarray) -> str:
    return "[" + ", ".join("[" + ", ".join(map(repr, r)) + "]" for r in R.tolist()) + "]"


def starts_of(sc: Scenario) -> list[tuple[str, Any]]:
    """What a draw randomises: the rotations its family names (Basin.start: e.g. the Chapter 5
    laws' R_i(0) and Q_i(0), the §4 observers' R̂_i(0)), with their own values."""
    return basin_of(sc).start(sc)


def draw_overrides(sc: Scenario, seed: int, draw: int, near: float | None = None) -> list[Override]:
    """The ``--set`` overrides of draw ``draw`` (none for draw 0, the scenario's own start):
    uniform rotations, or with ``near`` the scenario's own ones turned by ``near`` rad."""
    if draw == 0:
        return []
    rng = np.random.default_rng([seed % (1 << 63), draw])
    out = []
    for field, own in starts_of(sc):
        R = uniform_rotation(rng) if near is None else near_rotation(np.array(own, dtype=float).reshape(3, 3), near, rng)
        name, keys = _field_keys(field)
        # What parse_override(f"{field}={_rows(R)}", "--draw") gives (repr of a float reads back
        # exactly), without writing each matrix as TOML and parsing it back: 7 parses a draw.
        out.append(Override(f"--draw {field}={_rows(R)}", name, keys, R.tolist()))
    return out


@functools.cache
def _field_keys(field: str) -> tuple[str, tuple[str | int, ...]]:
    o = parse_override(f"{field}=0", "--draw")
    return o.field, o.keys


Source = str | tuple[str, str]  # a scenario file's path, or (its text, its path) for a worker on another host


def _load(topology: Source, overrides: list[Override] | None = None) -> Scenario:
    if isinstance(topology, tuple):
        text, path = topology
        return loads(text, path, overrides or ())
    return load(topology, overrides or ())


def run_seed(sc: Scenario, draw: int) -> int:
    """The run seed of draw ``draw`` (its sensor noise and link losses): the scenario's own,
    or with random links (loss, bursts, jitter) ``seed + draw``, so that each draw has its own
    losses and delays (with one seed every draw would lose the very same messages), and
    draw 0 stays ``zswarm sim`` of the scenario."""
    return sc.seed + draw if sc.random_links else sc.seed


def run_draw(topology: Source, seed: int, draw: int, duration: float, threshold: float, near: float | None = None) -> dict[str, Any]:
    """One draw on ``sim``, in memory; its row of basin.csv."""
    from zswarm.engines.sim import simulate

    t0 = time.monotonic()
    base = _load(topology)
    sc = with_rotations(base, draw_overrides(base, seed, draw, near))
    msgs = simulate(sc, Path("."), duration, run_seed(base, draw), lean=True, record=False)
    rec = report.load_recording(msgs)
    b = basin_of(sc)
    t, mx = b.series(sc, rec)
    return _row(draw, near, t, mx, threshold, len(rec.jumps), len(rec.agent_jumps), round(time.monotonic() - t0, 2), b.verdict)


def _row(draw: int, near: float | None, t: np.ndarray, mx: np.ndarray, threshold: float, jumps: int, agent_jumps: int, wall: float, verdict: str) -> dict[str, Any]:
    """A draw's row of basin.csv from its basin measure's series, whichever engine ran it."""
    settle = settle_time(t, mx, threshold)
    return {
        "draw": draw,
        "kind": _kind(draw, near),
        verdict: settle is not None,
        "left_s": leave_time(t, mx),
        "settle_01_s": settle_time(t, mx, 0.1),
        "settle_s": settle,
        "final_max": float(mx[-1]),
        "initial_max": float(mx[0]),
        "jumps": jumps,
        "agent_jumps": agent_jumps,
        "wall_s": wall,
        "status": "ok",
        "error": "",
    }


def run_chunk(topology: Source, seed: int, draws: list[int], duration: float, threshold: float, near: float | None = None) -> list[dict[str, Any]]:
    """Draws on the batched lockstep engine (agent/batched.py: every draw of the chunk stepped
    together, the same algorithm modules as sim); their rows of basin.csv."""
    from zswarm.util import plugins

    t0 = time.monotonic()
    batched = plugins.engine("batched")
    base = _load(topology)
    scs = [with_rotations(base, draw_overrides(base, seed, d, near)) for d in draws]  # as _load(topology, overrides) loads them
    b = basin_of(base)
    told = [time.monotonic()]

    def tell(t: float) -> None:
        # A chunk of a thousand 150 s draws takes minutes: say how far it is (stderr is the
        # terminal's for a local worker, the worker's log on a cluster).
        if time.monotonic() - told[0] >= PROGRESS_EVERY_S:
            told[0] = time.monotonic()
            print(f"draws {draws[0]}-{draws[-1]}: t = {t:.0f} of {duration:g} s", file=sys.stderr, flush=True)

    res = batched.run(scs, duration, base.seed, b.grid_s, progress=tell, seeds=[run_seed(base, d) for d in draws])
    wall = round((time.monotonic() - t0) / len(draws), 3)
    return [_row(d, near, *res.series(n), threshold, int(res.jumps[n]), int(res.agent_jumps[n]), wall, b.verdict) for n, d in enumerate(draws)]


def engine_problem(sc: Scenario, auto: bool = False) -> str | None:
    """Why ``sc``'s draws cannot run on the batched engine (None: they can); ``auto``: or why
    ``--engine auto`` runs them on sim though the engine can (it is no faster there)."""
    from zswarm.util import plugins

    engine = plugins.engine("batched")
    why: str | None = engine.problem(sc)
    if why is None and auto:
        why = engine.prefer_sim(sc)
    return why


def _kind(draw: int, near: float | None) -> str:
    return "scenario" if draw == 0 else "uniform" if near is None else "near"


def verdict_in(path: Path, default: str = "settled") -> str:
    """The verdict column of a basin.csv (its third: the family's word, e.g. "synchronized")."""
    try:
        with open(path, newline="") as f:
            head = next(csv.reader(f), [])
    except OSError:
        return default
    return head[2] if len(head) > 2 else default


def read_rows(path: Path) -> list[dict[str, str]]:
    """The rows of basin.csv, the newest per draw (a failed draw is run again on resume)."""
    last = {r["draw"]: r for r in rows.read(path).rows if r.get("status") and r.get("draw", "").isdigit()}
    return sorted(last.values(), key=lambda r: int(r["draw"]))


def run_basin(
    topology: str,
    draws: int,
    seed: int,
    duration: float,
    threshold: float,
    out: Path,
    jobs: int,
    stop: Callable[[], bool],
    progress: Callable[[str], None],
    near: float | None = None,
    batched: bool = False,
    chunk: int | None = None,
    cluster: str | None = None,
    text: str | None = None,
    advance: Callable[[int], None] | None = None,
) -> tuple[list[dict[str, str]], bool]:
    """Run the draws not yet in ``out/basin.csv``, ``jobs`` at a time; return every row and
    whether it was interrupted.  ``batched``: in chunks of ``chunk`` draws on the batched engine
    (default: the draws to do shared out among the jobs, at most MAX_CHUNK each), each chunk's
    rows written as it finishes (a resume reruns the unfinished chunks).  ``cluster``: on the
    Dask cluster whose scheduler is there (zswarm.engines.cluster), as many at a time as it has worker
    threads; the same rows as locally (the draws are seeded by their number).  ``text``: the
    scenario's TOML to run instead of the file's (the file with ``--set`` overrides applied).
    ``advance``: told the number of draws done (this run's and a resumed one's) as each finishes.
    basin.csv's third column is the family's verdict (Basin.verdict: its word for a draw that settles)."""
    path = out / "basin.csv"
    verdict = basin_of(_load((text, topology) if text is not None else topology)).verdict
    # Resumed with the file's own columns (a folder written by an older zswarm); its torn rows
    # (a kill or power cut mid-write) are dropped first, so their draws run again.
    f, w, table = rows.open_append(path, columns(verdict))
    if table.torn:
        progress(rows.torn_text(path, table.torn))
    cols = tuple(w.fieldnames)
    verdict = cols[2]
    done = {int(r["draw"]) for r in read_rows(path) if r["status"] == "ok"}
    todo = [d for d in range(draws) if d not in done]
    interrupted = False
    with f:
        with zswarm_cluster.executor(jobs, cluster) as runner:
            pool, jobs = runner.pool, runner.slots
            source: Source = topology if cluster is None and text is None else (text or Path(topology).read_text(encoding="utf-8"), topology)
            progress(f"running on {runner.where}")
            pending: dict[Any, list[int]] = {}
            finished_n = 0
            size = 1
            if batched:
                size = chunk or max(1, min(MAX_CHUNK, math.ceil(len(todo) / jobs)))
            chunks = iter([todo[k : k + size] for k in range(0, len(todo), size)])

            def submit() -> None:
                ds = next(chunks, None)
                if ds is not None:
                    fut = pool.submit(run_chunk, source, seed, ds, duration, threshold, near) if batched else pool.submit(run_draw, source, seed, ds[0], duration, threshold, near)
                    pending[fut] = ds

            for _ in range(jobs):
                submit()
            while pending:
                if stop():
                    interrupted = True
                    for fut in pending:
                        fut.cancel()
                    break
                finished, _ = wait(list(pending), timeout=0.5, return_when=FIRST_COMPLETED)
                for fut in finished:
                    ds = pending.pop(fut)
                    try:
                        got = fut.result()
                        rows_ = got if isinstance(got, list) else [got]
                    except Exception as exc:  # a failed draw (chunk) is recorded, not fatal
                        rows_ = [{"draw": d, "kind": _kind(d, near), "status": "failed", "error": f"{type(exc).__name__}: {exc}"[:300]} for d in ds]
                    rows.append(f, w, *({k: row.get(k) for k in cols} for row in rows_))
                    finished_n += len(rows_)
                    if advance is not None:
                        advance(len(done) + finished_n)
                    if len(rows_) == 1:
                        row = rows_[0]
                        progress(f"draw {row['draw']}: {row.get('status')}, settles at {_fmt(row.get('settle_s')) or 'never'} ({row.get('wall_s')} s)")
                    else:
                        ok = [r for r in rows_ if r.get("status") == "ok"]
                        n_in = sum(1 for r in ok if r.get(verdict))
                        progress(f"draws {ds[0]}-{ds[-1]}: {len(ok)} ok, {n_in} {verdict} ({_fmt(rows_[0].get('wall_s'))} s a draw)")
                    submit()
            if interrupted:  # the draws under way are lost (they rerun on resume), not waited for
                runner.abort()
    return read_rows(path), interrupted


def _f(x: str) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def summarize(rows: list[dict[str, str]], threshold: float, duration: float, near: float | None = None, verdict: str = "settled", measure: str = "the basin measure") -> dict[str, Any]:
    """Fractions and settle-time quantiles (of the drawn starts; the scenario's own start apart).
    ``verdict``: the rows' column of the draws that settled, and the summary's key of their
    count; ``measure``: what settled (both the family's, zswarm.families.contract.Basin)."""
    ok = [r for r in rows if r["status"] == "ok"]
    uni = [r for r in ok if r["kind"] != "scenario"]
    own = next((r for r in ok if r["kind"] == "scenario"), None)
    settled = [r for r in uni if r[verdict] == "True"]
    st = np.array(sorted(_f(r["settle_s"]) for r in settled))
    st1 = np.array(sorted(_f(r["settle_01_s"]) for r in uni if math.isfinite(_f(r["settle_01_s"]))))

    def q(a: np.ndarray) -> dict[str, float] | None:
        if not len(a):
            return None
        p = np.percentile(a, [0, 10, 50, 90, 100])
        return {"min": float(p[0]), "p10": float(p[1]), "median": float(p[2]), "p90": float(p[3]), "max": float(p[4])}

    n = len(uni)
    frac = len(settled) / n if n else None
    # A 95 % Wilson interval on the fraction (so that "100 of 100" reads as ≥ 96.3 %, not 100 %).
    ci = None
    if n:
        z = 1.96
        c = (frac + z * z / (2 * n)) / (1 + z * z / n)  # type: ignore[operator]
        h = z * math.sqrt(frac * (1 - frac) / n + z * z / (4 * n * n)) / (1 + z * z / n)  # type: ignore[operator]
        ci = [max(0.0, c - h), min(1.0, c + h)]
    return {
        "threshold": threshold,
        "horizon_s": duration,
        "start": "uniform" if near is None else "near",
        "near_rad": near,
        "drawn": n,
        "verdict": verdict,
        "measure": measure,
        verdict: len(settled),
        "fraction": frac,
        "fraction_95ci": ci,
        "settle_s": q(st),
        "settle_01_s": q(st1),
        # when the measure first fell below 0.9: the escape from a start near the undesired set
        "left_s": q(np.array(sorted(x for x in (_f(r.get("left_s", "")) for r in uni) if math.isfinite(x)))),
        "jumps": q(np.array([_f(r["jumps"]) for r in uni])),
        "scenario_start": None if own is None else {k: own.get(k, "") for k in (verdict, "left_s", "settle_01_s", "settle_s", "final_max", "jumps")},
        "failed": len(rows) - len(ok),
    }


def plot(out: Path, name: str, rows: list[dict[str, str]], summary: dict[str, Any]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    uni = [r for r in rows if r["status"] == "ok" and r["kind"] != "scenario"]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    for col, label in (("settle_01_s", "below 0.1"), ("settle_s", f"below {summary['threshold']:g}")):
        v = np.sort([_f(r[col]) for r in uni if math.isfinite(_f(r[col]))])
        if len(v):
            a1.step(v, np.arange(1, len(v) + 1) / max(1, len(uni)), where="post", label=f"{summary['measure']} {label}")
    own = summary.get("scenario_start") or {}
    for col, ls in (("settle_01_s", ":"), ("settle_s", "--")):
        x = _f(own.get(col, ""))
        if math.isfinite(x):
            a1.axvline(x, color="k", ls=ls, lw=0.8)
    a1.set_xlabel("settle time (s)")
    a1.set_ylabel(f"fraction of the {_what(summary)}")
    a1.set_xlim(0, summary["horizon_s"])
    a1.set_ylim(0, 1.02)
    if a1.get_legend_handles_labels()[1]:
        a1.legend(fontsize=8)
    a1.grid(alpha=0.3)
    a1.set_title(f"{name}: {summary[summary['verdict']]}/{summary['drawn']} {summary['verdict']} by {summary['horizon_s']:g} s", fontsize=9)
    fm = np.array([_f(r["final_max"]) for r in uni])
    a2.hist(np.log10(np.maximum(fm, 1e-16)), bins=30)
    a2.axvline(math.log10(summary["threshold"]), color="r", lw=0.8)
    a2.set_xlabel(f"log10 final {summary['measure']}")
    a2.set_ylabel("draws")
    a2.grid(alpha=0.3)
    a2.set_title("dashed/dotted: the scenario's own start", fontsize=9)
    fig.tight_layout()
    p = out / "basin.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    return p


def _what(s: dict[str, Any]) -> str:
    return "uniform draws" if s.get("start", "uniform") == "uniform" else f"starts {s['near_rad']:g} rad from the scenario's"


def ci_text(ci: list[float], sep: str = "-") -> str:
    """A 95 % interval in percent, its lower bound rounded down and its upper bound up, with
    as many decimals (up to 4) as it takes for 10,000 of 10,000 not to read "100.0-100.0 %"."""
    lo, hi = 100.0 * ci[0], 100.0 * ci[1]
    d = 1
    while d < 4 and (lo > 100.0 - 10.0**-d or hi < 10.0**-d):
        d += 1
    return f"{math.floor(lo * 10**d) / 10**d:.{d}f}{sep}{math.ceil(hi * 10**d) / 10**d:.{d}f} %"


def table(name: str, s: dict[str, Any]) -> str:
    def qs(q: dict[str, float] | None) -> str:
        return "n/a" if q is None else f"min {q['min']:.1f}, p10 {q['p10']:.1f}, median {q['median']:.1f}, p90 {q['p90']:.1f}, max {q['max']:.1f} s"

    ci = s["fraction_95ci"]
    own = s["scenario_start"] or {}
    lines = [
        f"{name}: {s[s['verdict']]} of {s['drawn']} {_what(s)} {s['verdict']} ({s['measure']} < {s['threshold']:g} from some t ≤ {s['horizon_s']:g} s on)"
        + (f", 95 % CI {ci_text(ci)}" if ci else ""),
        f"  settle below {s['threshold']:g}: {qs(s['settle_s'])}",
        f"  settle below 0.1:  {qs(s['settle_01_s'])}",
        f"  the scenario's own start: {s['verdict']} {own.get(s['verdict'], 'n/a')}, below 0.1 from {own.get('settle_01_s') or 'never'}, below {s['threshold']:g} from {own.get('settle_s') or 'never'}",
    ]
    if s["failed"]:
        lines.append(f"  {s['failed']} draws FAILED (see basin.csv)")
    return "\n".join(lines)


def write(
    out: Path, name: str, rows: list[dict[str, str]], threshold: float, duration: float, near: float | None = None, verdict: str = "settled", measure: str = "the basin measure", plots: bool = True
) -> dict[str, Any]:
    """basin.json (the summary) and, with ``plots``, basin.png; without, a basin.png an earlier
    run left is removed (it would not show this basin.csv)."""
    s = {"scenario": name, **summarize(rows, threshold, duration, near, verdict, measure)}
    files.write_text(out / "basin.json", json.dumps(s, indent=2) + "\n")
    if plots:
        plot(out, name, rows, s)
    else:
        (out / "basin.png").unlink(missing_ok=True)
    return s


# --------------------------------------------------------------------------- the command (zswarm.cli dispatches here)


def command(args: argparse.Namespace) -> int:
    import os
    import threading

    from zswarm.engines.launch import results_dir
    from zswarm.studies import basin

    sc = procutil.load_args(args)
    try:
        b = basin.basin_of(sc)
        basin.starts_of(sc)
    except ValueError as exc:
        procutil.fail_usage(f"{args.topology}: {exc}")
    duration = sc.duration if args.duration is None else args.duration
    out = args.out if args.out is not None else results_dir(None, sc.name, base=Path("basins"))
    out.mkdir(parents=True, exist_ok=True)
    spec = {"topology": str(args.topology), "scenario": sc.name, "seed": args.seed, "duration_s": duration, "threshold": args.threshold, "near": args.near, "set": list(args.overrides), "measure": b.measure}
    spec_path = out / "basin_def.json"
    if spec_path.exists():
        try:
            old = files.read_json_object(spec_path)
        except ValueError as exc:
            procutil.fail_usage(f"{spec_path}: not a basin check's definition ({exc}); use another --out")
        diff = sorted(k for k in spec if k not in ("topology", "measure") and old.get(k, [] if k == "set" else None) != spec[k])
        if diff:
            procutil.fail_usage(f"--out {out}: holds a different basin check (differs in: {', '.join(diff)}); use another --out")
    else:
        files.write_text(spec_path, json.dumps(spec, indent=2) + "\n")  # whole or not at all
    stop = threading.Event()
    procutil.stop_on_signals_into(stop)
    if files.hold(out, "basin check", stop.is_set) is None:  # one at a time in a folder
        return procutil.interrupted_code()
    jobs = args.jobs or (os.cpu_count() or 1)
    why = basin.engine_problem(sc, auto=args.engine == "auto")
    if args.engine == "batched" and why is not None:
        procutil.fail_usage(f"{args.topology}: --engine batched: the batched engine cannot run it: {why}")
    batched = args.engine != "sim" and why is None
    how = "on the batched engine (draws stepped together)" if batched else "on sim" + (f" (not batched: {why})" if args.engine == "auto" else "")
    print(f"basin of {sc.name}: {args.draws} draws ({duration:g} s each) {how}" + ("" if args.cluster else f", {jobs} at a time") + f"; {out}", file=sys.stderr)
    t0 = time.monotonic()
    already = sum(1 for r in basin.read_rows(out / "basin.csv") if r["status"] == "ok")
    bar = Progress(args.draws, "draws", already)
    try:
        rows, interrupted = basin.run_basin(
            str(args.topology), args.draws, args.seed, duration, args.threshold, out, jobs, stop.is_set, bar.line, args.near,
            batched=batched, chunk=args.chunk, cluster=args.cluster, text=sc.text if args.overrides else None, advance=bar.update,
        )
    except zswarm_cluster.ClusterError as exc:
        bar.close()
        print(f"zswarm basin: {exc}", file=sys.stderr)
        return 1
    bar.close()
    if interrupted:
        print(f"interrupted: {len(rows)} of {args.draws} draws are in {out / 'basin.csv'}; the same command resumes", file=sys.stderr)
        return procutil.interrupted_code()
    s = basin.write(out, sc.name, rows, args.threshold, duration, args.near, basin.verdict_in(out / "basin.csv", b.verdict), b.measure, plots=not args.no_plots)
    print(basin.table(sc.name, s))
    print(f"{len(rows)} draws in {out / 'basin.csv'} ({time.monotonic() - t0:.0f} s now); {out / 'basin.json'}" + ("" if args.no_plots else f", {out / 'basin.png'}"))
    return 0 if not s["failed"] else 1
