"""``zswarm sweep``: run a scenario over a grid of field values, repeated with different seeds.

Each run is its own ``zswarm sim`` (or ``zswarm run``) process writing a
results folder under ``<out>/runs/<run id>/``; a crash or a timeout is a
failed row, and the sweep goes on.  ``sweep.csv`` gets one row per finished
run, appended and flushed as each run ends, so a sweep that is interrupted
(Ctrl-C, a killed terminal, a reboot) and started again with the same
arguments and ``--out`` skips the runs it already has.  ``sweep.json`` holds
the sweep's definition; a restart with a different one is refused.

Per run: the varied values, the seed, final mean errors, convergence times
(first time after which the mean error stays below a threshold, judged on a
0.1 s grid: :func:`zswarm.report.convergence_time`), message counts of the
agent→agent edges and of the sensor links; then the columns of the scenario's
experiment family (:class:`zswarm.families.contract.Sweep`).
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import itertools
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zswarm import report, results
from zswarm.families import contract as family
from zswarm.transport import procutil
from zswarm.util import files
from zswarm.scenario import Override, Scenario, ScenarioError, load, loads, parse_field, parse_override
from zswarm.families.contract import DEFAULT_FIGURES
from zswarm.util.quoting import shown

COLUMNS_RESULT = (
    "status",
    "error",
    "final_attitude_error",
    "final_position_error",
    "conv_attitude_s",
    "conv_position_s",
    "edge_sent",
    "edge_delivered",
    "edge_dropped",
    "edge_drop_ratio",
    "edge_latency_p50_ms",
    "sensor_dropped",
    "cmd_sent",
    "cmd_dropped",
    "cmd_drop_ratio",
    "cmd_latency_p50_ms",
    "cmd_expired",
    "jumps",
    "stale_terms",
    "missed_deadlines",
)  # the generic columns of every row; the family's own follow (zswarm.families.contract.Sweep.columns), then wall_s


def columns(sc: Scenario) -> tuple[str, ...]:
    """The result columns of a sweep of ``sc``: the generic ones, its family's, ``wall_s``."""
    return (*COLUMNS_RESULT, *family.of(sc).sweep.columns, "wall_s")


@dataclass(frozen=True)
class Vary:
    field: str  # canonical spelling
    values: tuple[str, ...]  # as given (TOML values)


@dataclass(frozen=True)
class Job:
    run_id: str
    point: int
    repeat: int
    seed: int
    values: tuple[str, ...]  # one per Vary
    overrides: tuple[Override, ...]


def split_values(text: str) -> list[str]:
    """``0,50,100`` -> 3 values; ``0:200:50`` -> 0,50,100,150,200; commas inside
    brackets or quotes do not split (``[1,0,0],[0,1,0]``)."""
    if ":" in text and not any(ch in text for ch in "[]\"'") and text.count(":") == 2:
        try:
            a, b, c = (float(x) for x in text.split(":"))
        except ValueError:
            pass
        else:
            if c <= 0 or b < a:
                raise ValueError(f"range {text!r}: expected START:STOP:STEP with STEP > 0 and STOP >= START")
            n = math.floor((b - a) / c + 1e-9) + 1
            return [_num(a + k * c) for k in range(n)]
    out, depth, quote, cur = [], 0, "", ""
    for ch in text:
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            out.append(cur.strip())
            cur = ""
            continue
        cur += ch
    out.append(cur.strip())
    if any(v == "" for v in out):
        raise ValueError(f"empty value in {text!r}")
    return out


def _num(x: float) -> str:
    r = round(x, 9)
    return str(int(r)) if r == int(r) else repr(r)


def parse_vary(text: str) -> Vary:
    name, eq, vals = text.partition("=")
    if not eq or not name.strip():
        raise ScenarioError(f"--vary {shown(text)}: expected FIELD=v1,v2,... (e.g. links.delay_ms=0,50,100)")
    parse_field(name.strip(), f"--vary {shown(text)}")
    try:
        values = tuple(split_values(vals))
    except ValueError as exc:
        raise ScenarioError(f"--vary {shown(text)}: {exc}") from None
    # The canonical field name, as errors spell it.
    return Vary(parse_override(f"{name.strip()}={values[0]}", "--vary").field, values)


def plan(topology: str, sc: Scenario, sets: Sequence[Override], varies: Sequence[Vary], repeats: int, seed: int) -> list[Job]:
    """Every run of the sweep; each grid point's scenario is loaded once here, so a bad
    value fails before anything runs (exit 2 with ``--vary FIELD=v: field: problem``)."""
    jobs = []
    for point, combo in enumerate(itertools.product(*(v.values for v in varies))):
        ovs = tuple(sets) + tuple(parse_override(f"{v.field}={x}", "--vary") for v, x in zip(varies, combo, strict=True))
        load(topology, ovs)
        for r in range(repeats):
            jobs.append(Job(f"p{point:03d}-r{r}", point, r, seed + r, tuple(combo), ovs))
    return jobs


def definition(topology: str, sc: Scenario, args: dict[str, Any]) -> dict[str, Any]:
    return {
        "topology": topology,
        "scenario_sha256": hashlib.sha256(Path(topology).read_bytes()).hexdigest(),
        "scenario": sc.name,
        **args,
    }


def _column(v: Vary) -> str:
    return v.field


def read_done(path: Path) -> dict[str, dict[str, str]]:
    """Rows of an existing sweep.csv by run id (a torn last line is ignored)."""
    if not path.exists():
        return {}
    done = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            if row.get("run_id") and row.get("status") in ("ok", "failed"):
                done[row["run_id"]] = row
    return done


def _median(xs: list[float]) -> float | None:
    return float(np.median(xs)) if xs else None


def summarize_run(folder: Path, sc: Scenario, duration: float, thresholds: tuple[float, float]) -> dict[str, Any]:
    """The sweep.csv columns of one finished run, from its summary.json and errors/edges CSV."""
    s = json.loads((folder / "summary.json").read_text())
    t, att, pos = _series(folder, sc, duration)
    edges = {k: v for k, v in s["links"].items() if not k.startswith("world->") and not k.endswith("->world")}
    sensors = {k: v for k, v in s["links"].items() if k.startswith("world->")}
    cmds = {k: v for k, v in s["links"].items() if k.endswith("->world")}
    sent = sum(int(v.get("sent", 0)) for v in edges.values())
    dropped = sum(int(v.get("dropped", 0)) for v in edges.values())
    c_sent = sum(int(v.get("sent", 0)) for v in cmds.values())
    # Commands lost on the way: what the link model dropped plus what never arrived (sequence gaps).
    c_lost = sum(int(v.get("dropped", 0)) for v in cmds.values())
    return {
        "final_attitude_error": s.get("mean_attitude_error_final"),
        "final_position_error": s.get("mean_position_error_final"),
        "conv_attitude_s": report.convergence_time(t, att, thresholds[0]),
        "conv_position_s": report.convergence_time(t, pos, thresholds[1]) if np.any(np.isfinite(pos)) else None,
        "edge_sent": sent,
        "edge_delivered": sum(int(v.get("delivered", 0)) for v in edges.values()),
        "edge_dropped": dropped,
        "edge_drop_ratio": dropped / sent if sent else None,
        "edge_latency_p50_ms": _median([float(v["latency_p50_ms"]) for v in edges.values() if "latency_p50_ms" in v]),
        "sensor_dropped": sum(int(v.get("dropped", 0)) for v in sensors.values()),
        "cmd_sent": c_sent if cmds else None,
        "cmd_dropped": c_lost if cmds else None,
        "cmd_drop_ratio": c_lost / c_sent if c_sent else None,
        "cmd_latency_p50_ms": _median([float(v["latency_p50_ms"]) for v in cmds.values() if "latency_p50_ms" in v]),
        "cmd_expired": sum(int(v.get("expired", 0)) for v in s.get("commands", {}).get("per_agent", {}).values()) if cmds else None,
        "jumps": s.get("jumps_total"),
        "stale_terms": sum(int(a.get("stale_terms", 0)) for a in s["agents"].values()),
        "missed_deadlines": sum(int(a.get("missed_deadlines", 0)) for a in s["agents"].values()),
    } | _family_columns(folder, s, sc, t, att)


def _family_columns(folder: Path, s: dict[str, Any], sc: Scenario, t: np.ndarray, att: np.ndarray) -> dict[str, Any]:
    """The family's columns of a finished run (zswarm.families.contract.Sweep.from_run)."""
    sw = family.of(sc).sweep
    return {} if sw.from_run is None else sw.from_run(folder, s, sc, t, att)


def _series(folder: Path, sc: Scenario, duration: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The team's error measure of the run's report family, from the run's files."""
    return family.of(sc).series_from_files(folder, sc, duration)


class Progress:
    """A one-line progress bar on a terminal; a line per finished run otherwise."""

    def __init__(self, total: int, already: int, stream: Any = sys.stderr) -> None:
        self.total, self.done, self.failed = total, already, 0
        self.start_done = already
        self.t0 = time.monotonic()
        self.stream = stream
        self.tty = stream.isatty()

    def update(self, job: Job | None = None, status: str = "") -> None:
        el = time.monotonic() - self.t0
        new = self.done - self.start_done
        eta = el / new * (self.total - self.done) if new else float("nan")
        width = 30
        fill = int(width * self.done / self.total) if self.total else width
        bar = "#" * fill + "-" * (width - fill)
        text = f"[{bar}] {self.done}/{self.total} runs, {self.failed} failed, {_hms(el)} elapsed" + (f", ~{_hms(eta)} left" if new else "")
        if self.tty:
            print("\r" + text, end="", file=self.stream, flush=True)
        elif job is not None:
            print(f"{text}  ({job.run_id}: {status})", file=self.stream, flush=True)

    def close(self) -> None:
        if self.tty:
            print(file=self.stream, flush=True)


def _hms(s: float) -> str:
    if not math.isfinite(s):
        return "?"
    n = round(s)
    return f"{n // 60}:{n % 60:02d}"


def _cmd(engine: str, topology: str, job: Job, folder: Path, duration: float, keep_recordings: bool) -> list[str]:
    py = sys.executable
    sets = [a for o in job.overrides for a in ("--set", o.flag.split(" ", 1)[1])]
    common = [topology, *sets, "--seed", str(job.seed), "--duration", repr(duration), "--out", str(folder)]
    if engine == "sim":
        rec = [] if keep_recordings else ["--no-recording"]
        return [py, "-m", "zswarm", "sim", *common, "--no-plots", "--lean", "--quiet", *rec]
    return [py, "-m", "zswarm", "run", *common, "--quiet"]


def _last_error(log: Path) -> str:
    try:
        lines = [ln.strip() for ln in log.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    for ln in reversed(lines):
        if "error" in ln.lower() or "Error" in ln:
            return ln[-300:]
    return lines[-1][-300:] if lines else ""


def run_sweep(
    topology: str,
    sc: Scenario,
    jobs: list[Job],
    varies: Sequence[Vary],
    out: Path,
    engine: str,
    n_jobs: int,
    duration: float,
    thresholds: tuple[float, float],
    timeout: float,
    keep_recordings: bool,
    stop: Callable[[], bool] = lambda: False,
) -> tuple[int, int, bool]:
    """Run what is not in sweep.csv yet; return (ok, failed, interrupted)."""
    f, w, todo, prog = _open(out, jobs, varies, columns(sc))
    running: dict[str, tuple[Job, subprocess.Popen[bytes], float, Path]] = {}
    ok = failed = 0
    queue = list(todo)
    interrupted = False
    try:
        while queue or running:
            if stop():
                interrupted = True
                break
            while queue and len(running) < n_jobs:
                job = queue.pop(0)
                folder = out / "runs" / job.run_id
                if folder.exists():
                    shutil.rmtree(folder)  # a run cut short by an interruption starts over
                folder.mkdir(parents=True)
                log = open(folder / "log.txt", "wb")  # noqa: SIM115 - the child owns it; closed when reaped
                proc = subprocess.Popen(_cmd(engine, topology, job, folder, duration, keep_recordings), stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, start_new_session=True, env=procutil.child_env())
                log.close()
                running[job.run_id] = (job, proc, time.monotonic(), folder)
            time.sleep(0.05)
            for rid, (job, proc, t0, folder) in list(running.items()):
                rc = proc.poll()
                timed_out = rc is None and time.monotonic() - t0 > timeout
                if rc is None and not timed_out:
                    continue
                if timed_out:
                    _kill(proc)
                wall = time.monotonic() - t0
                del running[rid]
                row = _job_row(job, varies)
                try:
                    if timed_out:
                        raise RuntimeError(f"timed out after {timeout:g} s")
                    problems = _not_completed(folder) if rc == 1 else None
                    if problems is not None:
                        # It ran to its end and wrote its summary, which says why it is not
                        # completed (an agent failing most of its steps): its figures are kept.
                        row.update(summarize_run(folder, sc, duration, thresholds))
                        raise RuntimeError("not completed: " + "; ".join(problems))
                    if rc != 0:
                        raise RuntimeError(f"exit code {rc}: {_last_error(folder / 'log.txt')}")
                    row.update(summarize_run(folder, sc, duration, thresholds))
                    row["status"], row["error"] = "ok", ""
                    ok += 1
                except Exception as exc:  # noqa: BLE001 - any failure of one run is recorded, the sweep goes on
                    row["status"], row["error"] = "failed", str(exc)[:400]
                    failed += 1
                    prog.failed += 1
                row["wall_s"] = round(wall, 2)
                w.writerow({k: _fmt(v) for k, v in row.items()})
                f.flush()
                os.fsync(f.fileno())
                if not keep_recordings:
                    (folder / "recording.mcap").unlink(missing_ok=True)
                prog.done += 1
                prog.update(job, row["status"])
    finally:
        for _job, proc, _t0, _folder in running.values():
            _kill(proc)
        f.close()
        prog.close()
    return ok, failed, interrupted


def _open(out: Path, jobs: list[Job], varies: Sequence[Vary], result: Sequence[str]) -> tuple[Any, csv.DictWriter[str], list[Job], Progress]:
    """sweep.csv opened to append (its header written when new: the run's, the varied fields
    and ``result``; its own kept when resumed), the jobs not in it yet, and the progress line."""
    csv_path = out / "sweep.csv"
    done = read_done(csv_path)
    todo = [j for j in jobs if j.run_id not in done]
    header = ["run_id", "point", "repeat", "seed", *(_column(v) for v in varies), *result]
    new_file = not csv_path.exists() or csv_path.stat().st_size == 0
    if not new_file:
        _repair_tail(csv_path)
        with open(csv_path, newline="") as fh:
            header = next(csv.reader(fh), header)  # a folder begun by an older zswarm keeps its columns
    f = open(csv_path, "a", newline="")  # noqa: SIM115 - the caller closes it
    w = csv.DictWriter(f, fieldnames=header, extrasaction="ignore")
    if new_file:
        w.writeheader()
        f.flush()
    prog = Progress(len(jobs), len(jobs) - len(todo))
    prog.failed = sum(1 for r in done.values() if r["status"] == "failed")
    prog.update()
    return f, w, todo, prog


def _job_row(job: Job, varies: Sequence[Vary]) -> dict[str, Any]:
    row: dict[str, Any] = {"run_id": job.run_id, "point": job.point, "repeat": job.repeat, "seed": job.seed}
    row.update({_column(v): x for v, x in zip(varies, job.values, strict=True)})
    return row


def run_job(text: str, path: str, job: Job, duration: float, thresholds: tuple[float, float]) -> tuple[dict[str, Any], list[str] | None, dict[str, bytes]]:
    """One run of a sweep on sim in this process (a cluster's worker): what ``zswarm sim
    --no-recording --lean --no-plots`` computes and writes, then its sweep.csv columns.
    Returns those, the run's problems when it did not complete (None when it did), and the
    files it wrote (summary.json, errors.csv, the family's CSVs) for the sweep's folder."""
    from zswarm.engines.sim import LEAN_SKIP, simulate

    sc = loads(text, path, job.overrides)
    with tempfile.TemporaryDirectory(prefix="zswarm-sweep-") as d:
        folder = Path(d)
        (folder / "scenario.toml").write_text(sc.text, encoding="utf-8")
        msgs = simulate(sc, folder, duration, job.seed, lean=True, record=False)
        summary = results.make_report(folder, sc, "sim", duration, 0.0, job.seed, plots=False, messages=msgs, not_recorded=LEAN_SKIP)
        row = summarize_run(folder, sc, duration, thresholds)
        problems = None if summary["completed"] else [str(p) for p in summary.get("problems", [])]
        written = {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}
    return row, problems, written


def run_sweep_cluster(
    topology: str,
    jobs: list[Job],
    varies: Sequence[Vary],
    out: Path,
    duration: float,
    thresholds: tuple[float, float],
    cluster: str,
    stop: Callable[[], bool] = lambda: False,
) -> tuple[int, int, bool]:
    """:func:`run_sweep` on the Dask cluster whose scheduler is at ``cluster`` (engine sim, each
    run in a worker's process: :func:`run_job`); each run's files are written into
    ``out/runs/<id>/`` here.  Returns (ok, failed, interrupted)."""
    from concurrent.futures import FIRST_COMPLETED, wait

    from zswarm.engines import cluster as zswarm_cluster

    text = Path(topology).read_text(encoding="utf-8")
    f, w, todo, prog = _open(out, jobs, varies, columns(load(topology, jobs[0].overrides)))
    ok = failed = 0
    interrupted = False
    try:
        with zswarm_cluster.executor(1, cluster) as runner:
            queue = list(todo)
            pending: dict[Any, tuple[Job, float]] = {}
            while queue or pending:
                if stop():
                    interrupted = True
                    runner.abort()
                    break
                while queue and len(pending) < 2 * runner.slots:  # one waiting per thread: no idle worker between runs
                    job = queue.pop(0)
                    pending[runner.pool.submit(run_job, text, topology, job, duration, thresholds)] = (job, time.monotonic())
                finished, _ = wait(list(pending), timeout=0.5, return_when=FIRST_COMPLETED)
                for fut in finished:
                    job, t0 = pending.pop(fut)
                    row = _job_row(job, varies)
                    try:
                        results, problems, written = fut.result()
                        folder = out / "runs" / job.run_id
                        folder.mkdir(parents=True, exist_ok=True)
                        for name, data in written.items():
                            files.write_bytes(folder / name, data)
                        row.update(results)
                        if problems is not None:
                            raise RuntimeError("not completed: " + "; ".join(problems))
                        row["status"], row["error"] = "ok", ""
                        ok += 1
                    except Exception as exc:  # noqa: BLE001 - any failure of one run is recorded, the sweep goes on
                        row["status"], row["error"] = "failed", f"{type(exc).__name__}: {exc}"[:400]
                        failed += 1
                        prog.failed += 1
                    row["wall_s"] = round(time.monotonic() - t0, 2)
                    w.writerow({k: _fmt(v) for k, v in row.items()})
                    f.flush()
                    os.fsync(f.fileno())
                    prog.done += 1
                    prog.update(job, row["status"])
    finally:
        f.close()
        prog.close()
    return ok, failed, interrupted


# --------------------------------------------------------------------------- the batched engine

def batched_problem(sc: Scenario, auto: bool = False) -> str | None:
    """Why ``sc``'s runs cannot go on the batched engine (None: they can); ``auto``: or why
    ``--engine auto`` runs them on sim though the engine can (it is no faster there)."""
    from zswarm.util import plugins

    if family.of(sc).batched is None:
        return f"its experiment family {sc.info.report!r} has no measure on the batched engine (zswarm.families.contract.Batched)"
    engine = plugins.engine("batched")
    why: str | None = engine.problem(sc)
    if why is None and auto:
        why = engine.prefer_sim(sc)
    return why


def plan_batches(topology: str, jobs: Sequence[Job], chunk: int | None, n_jobs: int, auto: bool = False) -> tuple[list[list[Job]], list[tuple[Job, str]]]:
    """The jobs that the batched engine can step together, in batches (runs that share their
    scenario but for seeds, noise variances and starts: the engine's ``group``), and the others
    with the reason (``auto``: those it runs no faster than sim too).  A batch holds at most
    ``chunk`` runs (default: each group shared out among ``n_jobs`` tasks, at most 1000)."""
    from zswarm.util import plugins

    group = plugins.engine("batched").group
    groups: list[tuple[tuple[Any, ...], list[Job]]] = []  # (key, runs): keys compared with == (a Scenario is not hashable)
    rest: list[tuple[Job, str]] = []
    loaded: dict[tuple[Override, ...], Scenario] = {}
    for j in jobs:
        sc = loaded.get(j.overrides)
        if sc is None:
            sc = loaded[j.overrides] = load(topology, j.overrides)
        why = batched_problem(sc, auto)
        if why is not None:
            rest.append((j, why))
            continue
        key = group(sc)
        for k, members in groups:
            if k == key:
                members.append(j)
                break
        else:
            groups.append((key, [j]))
    batches = []
    for _, members in groups:
        size = chunk or min(1000, max(1, math.ceil(len(members) / max(1, n_jobs))))
        batches += [members[i : i + size] for i in range(0, len(members), size)]
    return batches, rest


def run_batch(source: tuple[str, str], batch: Sequence[Job], duration: float, thresholds: tuple[float, float]) -> list[dict[str, Any]]:
    """A batch of runs stepped together on the batched engine (in a worker's process): each
    run's sweep.csv columns, as :func:`summarize_run` reads them from a sim run's files (the
    family's finals of summary.json, its team measure on the 0.1 s grid as its CSV holds it,
    agent/batched.py's Result; the messages and commands sent: lockstep delivers each at once,
    so none is lost, late or expired)."""
    from zswarm.util import plugins
    from zswarm.report import convergence_time

    t0 = time.monotonic()
    text, path = source
    loaded: dict[tuple[Override, ...], Scenario] = {}
    scs = []
    for j in batch:
        if j.overrides not in loaded:
            loaded[j.overrides] = loads(text, path, j.overrides)
        scs.append(loaded[j.overrides])
    sc = scs[0]
    fam = family.of(sc)
    res = plugins.engine("batched").run(scs, duration, 0, fam.basin.grid_s if fam.basin is not None else report.GRID_S, seeds=[j.seed for j in batch], rows=True)
    wall = round((time.monotonic() - t0) / len(batch), 3)
    hybrid = bool(getattr(sc.params, "Xi", ()))  # summary.json's jumps_total: the hybrid schemes' ξ_k
    commanded = res.commands > 0  # the agents command the world: summary.json has their "->world" links
    rows = []
    for n, _job in enumerate(batch):
        att = res.att_coarse[n] if res.att_coarse is not None else None  # (a family's measure may leave the team's errors out)
        pos = res.pos_coarse[n] if res.pos_coarse is not None else None
        final_pos = float(res.final_pos[n]) if res.final_pos is not None and np.isfinite(res.final_pos[n]) else None
        sent, cmds = res.edge_messages, res.commands
        if res.draw_edge_messages is not None and res.draw_commands is not None:  # sensor jitter or loss: each draw sent its own count
            sent, cmds = int(res.draw_edge_messages[n]), int(res.draw_commands[n])
        cmd_dropped, cmd_latency, cmd_expired = 0, 0.0 if cmds else None, 0
        if res.command_links is not None:  # emulated command links: the world's counters of this draw
            links = res.command_links.link_counters(n)
            cmd_dropped = sum(v["dropped"] for v in links.values())
            cmd_latency = _median([v["latency_p50_ms"] for v in links.values() if "latency_p50_ms" in v])
            cmd_expired = int(res.command_links.expired[n].sum())
        c_sent = cmds
        e_delivered, e_dropped, e_latency, stale = sent, 0, 0.0 if sent else None, 0
        if res.edge_links is not None:  # emulated agent→agent links: the receivers' counters of this draw
            elinks = res.edge_links.link_counters(n, res.t_end)
            e_delivered = sum(v["delivered"] for v in elinks.values())
            e_dropped = sum(v["dropped"] for v in elinks.values())
            e_latency = _median([v["latency_p50_ms"] for v in elinks.values() if "latency_p50_ms" in v])
            stale = int(sum(int(st[n]) for st in res.edge_links.stale_terms.values()))
        if res.stale_terms is not None:
            stale = int(res.stale_terms[n])
        rows.append(
            {
                "final_attitude_error": float(res.final_att[n]) if res.final_att is not None and np.isfinite(res.final_att[n]) else None,
                "final_position_error": final_pos,
                "conv_attitude_s": convergence_time(res.t_coarse, att, thresholds[0]) if att is not None else None,
                "conv_position_s": convergence_time(res.t_coarse, pos, thresholds[1]) if pos is not None and np.any(np.isfinite(pos)) else None,
                "edge_sent": sent,
                "edge_delivered": e_delivered,
                "edge_dropped": e_dropped,
                "edge_drop_ratio": e_dropped / sent if sent else None,
                "edge_latency_p50_ms": e_latency,
                "sensor_dropped": int(res.sensor_dropped[n]) if res.sensor_dropped is not None else 0,
                "cmd_sent": c_sent if commanded else None,
                "cmd_dropped": cmd_dropped if commanded else None,
                "cmd_drop_ratio": cmd_dropped / c_sent if c_sent else None,
                "cmd_latency_p50_ms": cmd_latency,
                "cmd_expired": cmd_expired if commanded else None,
                "jumps": int(res.jumps[n]) if hybrid else None,
                "stale_terms": stale,
                "missed_deadlines": 0,
                "wall_s": wall,
            }
            | ({} if fam.sweep.from_batch is None else fam.sweep.from_batch(res, n, sc))
        )
    return rows


def run_sweep_batched(
    topology: str,
    jobs: list[Job],
    batches: list[list[Job]],
    varies: Sequence[Vary],
    out: Path,
    duration: float,
    thresholds: tuple[float, float],
    n_jobs: int,
    cluster: str | None = None,
    stop: Callable[[], bool] = lambda: False,
) -> tuple[int, int, bool]:
    """The batches on the batched engine, ``n_jobs`` local processes or the Dask cluster at
    ``cluster`` (each task a batch, :func:`run_batch`); a row per run appended to sweep.csv as
    its batch ends (a batch that fails makes each of its runs a failed row).  Returns (ok,
    failed, interrupted)."""
    from concurrent.futures import FIRST_COMPLETED, wait

    from zswarm.engines import cluster as zswarm_cluster

    source = (Path(topology).read_text(encoding="utf-8"), topology)
    f, w, _todo, prog = _open(out, jobs, varies, columns(load(topology, jobs[0].overrides)))
    ok = failed = 0
    interrupted = False
    try:
        with zswarm_cluster.executor(n_jobs, cluster) as runner:
            queue = list(batches)
            pending: dict[Any, list[Job]] = {}
            while queue or pending:
                if stop():
                    interrupted = True
                    runner.abort()
                    break
                while queue and len(pending) < runner.slots:
                    batch = queue.pop(0)
                    pending[runner.pool.submit(run_batch, source, batch, duration, thresholds)] = batch
                finished, _ = wait(list(pending), timeout=0.5, return_when=FIRST_COMPLETED)
                for fut in finished:
                    batch = pending.pop(fut)
                    try:
                        results: list[dict[str, Any]] | None = fut.result()
                        error = ""
                    except Exception as exc:  # noqa: BLE001 - a failed batch is recorded, the sweep goes on
                        results, error = None, f"{type(exc).__name__}: {exc}"[:400]
                    for n, job in enumerate(batch):
                        row = _job_row(job, varies)
                        if results is not None:
                            row.update(results[n])
                            row["status"], row["error"] = "ok", ""
                            ok += 1
                        else:
                            row["status"], row["error"] = "failed", error
                            failed += 1
                            prog.failed += 1
                        w.writerow({k: _fmt(v) for k, v in row.items()})
                        prog.done += 1
                        prog.update(job, row["status"])
                    f.flush()
                    os.fsync(f.fileno())
    finally:
        f.close()
        prog.close()
    return ok, failed, interrupted


def _not_completed(folder: Path) -> list[str] | None:
    """The ``problems`` of a run that wrote its summary and is not completed, else None."""
    try:
        s = json.loads((folder / "summary.json").read_text())
    except (OSError, ValueError):
        return None
    if s.get("completed") is not False:
        return None
    return [str(p) for p in s.get("problems", [])] or None


def _repair_tail(path: Path) -> None:
    """Drop a torn last line (a kill during a write) so appended rows stay well-formed."""
    data = path.read_bytes()
    if data and not data.endswith(b"\n"):
        path.write_bytes(data[: data.rfind(b"\n") + 1])


def _kill(proc: subprocess.Popen[bytes]) -> None:
    """Stop a run's process group (its own session) and reap it, by PID."""
    for sig, wait in ((signal.SIGINT, 10.0), (signal.SIGKILL, 5.0)):
        if proc.poll() is not None:
            break
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(wait)
        except subprocess.TimeoutExpired:
            continue
    if proc.poll() is None:
        proc.wait()


def _fmt(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.6g}"
    return v


# --------------------------------------------------------------------------- plots

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


# --------------------------------------------------------------------------- the command (zswarm.cli dispatches here)


def command(args: argparse.Namespace) -> int:
    import os
    import threading

    from zswarm.studies import sweep
    from zswarm.engines.launch import results_dir
    from zswarm.scenario import ScenarioError, parse_override

    thresholds = (0.01, 0.1)
    if args.thresholds is not None:
        parts = args.thresholds.split(",")
        if len(parts) != 2:
            procutil.fail_usage(f"--thresholds: give ATT,POS, e.g. 0.01,0.1 (got {args.thresholds!r})")
        a, p_ = (procutil.number_arg(x, "--thresholds") for x in parts)
        if not (a > 0 and p_ > 0):
            procutil.fail_usage(f"--thresholds: both must be > 0 (got {args.thresholds!r})")
        thresholds = (a, p_)
    try:
        sets = [parse_override(o) for o in args.overrides]
        varies = [sweep.parse_vary(v) for v in args.vary]
    except ScenarioError as exc:
        procutil.fail_usage(str(exc))
    seen: set[str] = set()
    for v in varies:
        if v.field in seen:
            procutil.fail_usage(f"--vary {v.field}: field: given twice")
        seen.add(v.field)
        if v.field in {o.field for o in sets}:
            procutil.fail_usage(f"--vary {v.field}: field: also fixed by --set")
    sc = procutil.load_or_exit(args.topology, sets)
    duration = sc.duration if args.duration is None else args.duration
    procutil.check_faults_in_run(sc, duration, args.duration is not None)
    seed = sc.seed if args.seed is None else args.seed
    try:
        jobs = sweep.plan(args.topology, sc, sets, varies, args.repeats, seed)
    except ScenarioError as exc:
        procutil.fail_usage(str(exc))
    out = args.out if args.out is not None else results_dir(None, sc.name, base=Path("sweeps"))
    out.mkdir(parents=True, exist_ok=True)
    spec = sweep.definition(
        args.topology,
        sc,
        {
            "vary": {v.field: list(v.values) for v in varies},
            "set": [o.flag for o in sets],
            "repeats": args.repeats,
            "engine": args.engine,
            "duration_s": duration,
            "seed": seed,
            "thresholds": list(thresholds),
        },
    )
    n_jobs = args.jobs or ((os.cpu_count() or 1) if args.engine != "run" else 1)
    if args.cluster is not None and args.engine == "run":
        procutil.fail_usage("--cluster: the runs of a sweep on a cluster use the sim or the batched engine (zswarm run's processes stay on this host)")
    done = sweep.read_done(out / "sweep.csv")
    todo = [j for j in jobs if j.run_id not in done]
    batches: list[list[sweep.Job]] = []
    on_sim = todo
    if args.engine in ("auto", "batched"):
        try:
            batches, rest = sweep.plan_batches(args.topology, todo, args.chunk, n_jobs, auto=args.engine == "auto")
        except ScenarioError as exc:
            procutil.fail_usage(str(exc))
        if rest and args.engine == "batched":
            procutil.fail_usage(f"--engine batched: run {rest[0][0].run_id}: {rest[0][1]} (--engine auto runs such runs on sim)")
        if rest:
            print(f"{len(rest)} of {len(todo)} runs on sim: {rest[0][1]}", file=sys.stderr)
        on_sim = [j for j, _ in rest]
    spec_path = out / "sweep.json"
    if spec_path.exists():
        old = json.loads(spec_path.read_text())
        # The engines whose rows agree (batched and sim: tests/component/test_sweep.py) may resume each other's sweeps.
        same_rows = {old.get("engine"), spec.get("engine")} <= {"auto", "batched", "sim"}
        diff = sorted(k for k in set(old) | set(spec) if k != "topology" and not (k == "engine" and same_rows) and old.get(k) != spec.get(k))
        if diff:
            procutil.fail_usage(f"--out {out}: holds a different sweep (differs in: {', '.join(diff)}); use another --out to start a new one")
    else:
        spec_path.write_text(json.dumps(spec, indent=2) + "\n")
    sim_engine = "run" if args.engine == "run" else "sim"
    timeout = args.timeout or (max(120.0, 10.0 * duration) if sim_engine == "sim" else duration + 180.0)
    stop = threading.Event()
    procutil.stop_on_signals_into(stop)
    n_points = len(jobs) // args.repeats
    where = f"the Dask cluster at {args.cluster}" if args.cluster else f"{n_jobs} at a time"
    n_batched = sum(len(b) for b in batches)
    engines = (f"{n_batched} batched in {len(batches)} batches" if batches else "") + (", " if batches and on_sim else "") + (f"{len(on_sim)} on {sim_engine}" if on_sim else "")
    print(f"sweep of {sc.name}: {n_points} grid points x {args.repeats} repeats = {len(jobs)} runs ({engines or 'all done'}), {where}; {out}", file=sys.stderr)
    t0 = time.monotonic()
    from zswarm.engines.cluster import ClusterError

    ok = 0
    interrupted = False
    try:
        if batches:
            ok, _failed, interrupted = sweep.run_sweep_batched(args.topology, jobs, batches, varies, out, duration, thresholds, n_jobs, args.cluster, stop.is_set)
        if on_sim and not interrupted:
            if args.cluster is not None:
                ok2, _failed, interrupted = sweep.run_sweep_cluster(args.topology, jobs, varies, out, duration, thresholds, args.cluster, stop.is_set)
            else:
                ok2, _failed, interrupted = sweep.run_sweep(
                    args.topology, sc, jobs, varies, out, sim_engine, n_jobs, duration, thresholds, timeout, args.keep_recordings, stop.is_set
                )
            ok += ok2
    except ClusterError as exc:
        print(f"zswarm sweep: {exc}", file=sys.stderr)
        return 1
    wall = time.monotonic() - t0
    rows = sweep.load_rows(out / "sweep.csv")
    if interrupted:
        print(f"interrupted: {len(rows)} of {len(jobs)} runs are in {out / 'sweep.csv'}; the same command resumes", file=sys.stderr)
        return 130
    plots = sweep.plot_sweep(out, rows, [v.field for v in varies], duration, family.of(sc).sweep.figures)
    n_failed = sum(1 for r in rows if r["status"] == "failed")
    print(f"{len(rows)} runs ({ok} run now in {wall:.0f} s, {n_failed} failed in all); {out / 'sweep.csv'}; plots: {', '.join(p.name for p in plots) or 'none'}")
    return 0 if n_failed == 0 else 1
