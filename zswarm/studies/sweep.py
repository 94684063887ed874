"""``zswarm sweep``: run a scenario over a grid of field values, repeated with different seeds.

Each run writes a results folder under ``<out>/runs/<run id>/``: on sim, in one of
``--jobs`` worker processes that run one run after another (or on a Dask cluster's); on
``run`` (and on sim with ``--keep-recordings``), as its own ``zswarm run`` (``zswarm sim``)
process.  A crash or a timeout is a failed row, and the sweep goes on.  ``sweep.csv`` gets one row per finished
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
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zswarm import report, results
from zswarm.families import contract as family
from zswarm.scenario import Override, Scenario, ScenarioError, load, loads, parse_field, parse_override
from zswarm.transport import procutil
from zswarm.util import files, progress, rows
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
    """The whole rows of an existing sweep.csv by run id (a torn row is left out: zswarm.util.rows)."""
    return _done(rows.read(path).rows)


def _done(table_rows: list[dict[str, str]]) -> dict[str, dict[str, str]]:
    """The finished runs (ok or failed) among sweep.csv's whole rows, by run id."""
    return {r["run_id"]: r for r in table_rows if r.get("run_id") and r.get("status") in ("ok", "failed")}


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


class Progress(progress.Progress):
    """The sweep's progress (zswarm.util.progress): runs done and failed; in a log, a line per
    finished run."""

    def __init__(self, total: int, already: int, stream: Any = None) -> None:
        super().__init__(total, "runs", already, stream)
        self.failed = 0

    def update(self, job: Job | None = None, status: str = "") -> None:  # type: ignore[override]
        note = f"{job.run_id}: {status}" if job is not None and not self.tty else None
        super().update(self.done, extra=f"{self.failed} failed", note=note)


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
    lock: int | None = None,
) -> tuple[int, int, bool]:
    """Run what is not in sweep.csv yet; return (ok, failed, interrupted).  ``lock``: the
    folder's lock (files.hold), held by each run's process too while it writes its folder."""
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
                proc = subprocess.Popen(_cmd(engine, topology, job, folder, duration, keep_recordings), stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, start_new_session=True, env=procutil.child_env(), pass_fds=() if lock is None else (lock,))
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
                        row.update(summarize_run(folder, load(topology, job.overrides), duration, thresholds))
                        raise RuntimeError("not completed: " + "; ".join(problems))
                    if rc != 0:
                        raise RuntimeError(f"exit code {rc}: {_last_error(folder / 'log.txt')}")
                    row.update(summarize_run(folder, load(topology, job.overrides), duration, thresholds))  # the run's own scenario, as run_job's
                    row["status"], row["error"] = "ok", ""
                    ok += 1
                except Exception as exc:  # noqa: BLE001 - any failure of one run is recorded, the sweep goes on
                    row["status"], row["error"] = "failed", str(exc)[:400]
                    failed += 1
                    prog.failed += 1
                row["wall_s"] = round(wall, 2)
                rows.append(f, w, row)
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
    and ``result``; its own kept when resumed, its torn rows dropped so their runs run again),
    the jobs not in it yet, and the progress line."""
    csv_path = out / "sweep.csv"
    header = ["run_id", "point", "repeat", "seed", *(_column(v) for v in varies), *result]
    f, w, table = rows.open_append(csv_path, header)
    if table.torn:
        print(rows.torn_text(csv_path, table.torn), file=sys.stderr)
    done = _done(table.rows)
    todo = [j for j in jobs if j.run_id not in done]
    prog = Progress(len(jobs), len(jobs) - len(todo))
    prog.failed = sum(1 for r in done.values() if r["status"] == "failed")
    prog.update()
    return f, w, todo, prog


def _job_row(job: Job, varies: Sequence[Vary]) -> dict[str, Any]:
    row: dict[str, Any] = {"run_id": job.run_id, "point": job.point, "repeat": job.repeat, "seed": job.seed}
    row.update({_column(v): x for v, x in zip(varies, job.values, strict=True)})
    return row


def run_job(text: str, path: str, job: Job, duration: float, thresholds: tuple[float, float], scratch: str | None = None) -> tuple[dict[str, Any], list[str] | None, dict[str, bytes]]:
    """One run of a sweep on sim in this process (a worker's): what ``zswarm sim --no-recording
    --lean --no-plots`` computes and writes, then its sweep.csv columns.  Returns those, the
    run's problems when it did not complete (None when it did), and the files it wrote
    (summary.json, errors.csv, the family's CSVs) for the sweep's folder.  ``scratch``: the
    folder its temporary folder goes in (a local sweep's, which it clears of what killed
    workers left; None: the system's).  A run whose estimated cost ``zswarm sim`` refuses
    without ``--allow-long`` (zswarm.engines.cost) is refused here too (ValueError)."""
    from zswarm.engines import cost
    from zswarm.engines.sim import LEAN_SKIP, simulate

    sc = loads(text, path, job.overrides)
    why = cost.too_long(sc, duration)
    if why is not None:
        raise ValueError(why)
    with tempfile.TemporaryDirectory(prefix="zswarm-sweep-", dir=scratch) as d:
        folder = Path(d)
        files.write_text(folder / "scenario.toml", sc.text)
        msgs = simulate(sc, folder, duration, job.seed, lean=True, record=False)
        summary = results.make_report(folder, sc, "sim", duration, 0.0, job.seed, plots=False, messages=msgs, not_recorded=LEAN_SKIP)
        row = summarize_run(folder, sc, duration, thresholds)
        problems = None if summary["completed"] else [str(p) for p in summary.get("problems", [])]
        written = {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}
    return row, problems, written


# A run whose worker process died (killed by the kernel, a crash) takes the pool with it: every
# run in flight then fails with BrokenProcessPool, whichever killed it.  They start again in a
# new pool; a run in flight at this many breaks is a failed row.
MAX_BREAKS = 2


def run_sweep_workers(
    topology: str,
    jobs: list[Job],
    varies: Sequence[Vary],
    out: Path,
    duration: float,
    thresholds: tuple[float, float],
    n_jobs: int,
    cluster: str | None = None,
    stop: Callable[[], bool] = lambda: False,
    timeout: float | None = None,
) -> tuple[int, int, bool]:
    """:func:`run_sweep` on sim in worker processes that each run one run after another
    (:func:`run_job`): ``n_jobs`` local processes, or the Dask cluster whose scheduler is at
    ``cluster``; each run's files are written into ``out/runs/<id>/`` here (a failed run's
    traceback into its log.txt).  A local run still running ``timeout`` s after it began is a
    failed row: the workers are killed (a run in a process cannot be stopped alone), and the
    runs they held that had not ended start again in new ones, as after a worker's death
    (MAX_BREAKS).  Returns (ok, failed, interrupted).

    A process per run, as :func:`run_sweep` starts, costs its interpreter and imports
    (0.4-0.5 s of CPU here, 2026-12-07): as much as a 2 s §5.6 run itself."""
    from concurrent.futures import FIRST_COMPLETED, BrokenExecutor, Future, wait

    from zswarm.engines import cluster as zswarm_cluster

    text = Path(topology).read_text(encoding="utf-8")
    f, w, todo, prog = _open(out, jobs, varies, columns(load(topology, jobs[0].overrides)))
    ok = failed = 0
    interrupted = False
    queue = list(todo)
    breaks: dict[str, int] = {}
    scratch = None if cluster is not None else out / ".work"  # the runs' temporary folders
    if cluster is not None:
        timeout = None  # the cluster's scheduler retries and moves its tasks (zswarm.engines.cluster)

    def clear_scratch(again: bool) -> str | None:
        """``scratch`` emptied of what killed workers left (made again when ``again``)."""
        if scratch is None:
            return None
        shutil.rmtree(scratch, ignore_errors=True)
        if again:
            scratch.mkdir(parents=True)
        return str(scratch)

    def record(job: Job, t0: float, outcome: tuple[dict[str, Any], list[str] | None, dict[str, bytes]] | BaseException | str) -> None:
        nonlocal ok, failed
        row = _job_row(job, varies)
        folder = out / "runs" / job.run_id
        if folder.exists():
            shutil.rmtree(folder)  # what an earlier try left
        if isinstance(outcome, tuple):
            res, problems, written = outcome
            folder.mkdir(parents=True)
            for name, data in written.items():
                files.write_bytes(folder / name, data)
            row.update(res)
            error = None if problems is None else "not completed: " + "; ".join(problems)
        else:
            error = outcome if isinstance(outcome, str) else f"{type(outcome).__name__}: {outcome}"
            if isinstance(outcome, BaseException):  # its traceback (a worker's comes as the cause's text)
                cause = outcome.__cause__
                tb = str(getattr(cause, "tb", "")) or "".join(traceback.format_exception(outcome))
                folder.mkdir(parents=True)
                files.write_text(folder / "log.txt", tb)
        if error is None:
            row["status"], row["error"] = "ok", ""
            ok += 1
        else:
            row["status"], row["error"] = "failed", error[:400]
            failed += 1
            prog.failed += 1
        row["wall_s"] = round(time.monotonic() - t0, 2)
        rows.append(f, w, row)
        prog.done += 1
        prog.update(job, row["status"])

    def ended(fut: Future[Any]) -> bool:
        """It ended by itself: its result, or the run's own exception (not its pool's end)."""
        return fut.done() and not fut.cancelled() and not isinstance(fut.exception(), BrokenExecutor)

    def outcome(fut: Future[Any]) -> tuple[dict[str, Any], list[str] | None, dict[str, bytes]] | BaseException:
        """What an ended run gave: :func:`run_job`'s result, or its exception."""
        exc = fut.exception()
        return exc if exc is not None else fut.result()

    try:
        while queue and not interrupted:
            sdir = clear_scratch(again=True)
            with zswarm_cluster.executor(n_jobs, cluster) as runner:
                # One waiting per thread on a cluster (no idle worker between runs); locally one
                # per process, so that a run's clock starts when it does (its timeout).
                cap = runner.slots if cluster is None else 2 * runner.slots
                pending: dict[Future[Any], tuple[Job, float]] = {}
                broken = False
                while queue or pending:
                    if stop():
                        interrupted = True
                        runner.abort()
                        break
                    try:
                        while queue and len(pending) < cap:
                            job = queue[0]
                            pending[runner.pool.submit(run_job, text, topology, job, duration, thresholds, sdir)] = (job, time.monotonic())
                            queue.pop(0)
                    except BrokenExecutor:
                        broken = True
                    if not broken:
                        # Up to the first run's timeout at most: a run not ended by then is late
                        # at once (a finer poll than 0.5 s for a short --timeout, as the
                        # per-process path's 0.05 s), and one ended by then is never taken for late.
                        wait_s = 0.5 if timeout is None or not pending else min(0.5, max(0.0, min(t0 for _job, t0 in pending.values()) + timeout - time.monotonic()))
                        done, _ = wait(list(pending), timeout=wait_s, return_when=FIRST_COMPLETED)
                        for fut in done:
                            if ended(fut):
                                job, t0 = pending.pop(fut)
                                record(job, t0, outcome(fut))
                            else:
                                broken = True  # a worker died: the pool is gone
                    now = time.monotonic()
                    late = {fut for fut, (_job, t0) in pending.items() if timeout is not None and not fut.done() and now - t0 > timeout}
                    if not (late or broken):
                        continue
                    runner.abort()  # kills the workers: what they held and had not ended starts again
                    if broken:
                        prog.line(f"a worker process died (killed, or a crash): the {sum(not ended(fut) for fut in pending)} runs it and the others held start again in new ones")
                    again: list[Job] = []
                    for fut, (job, t0) in pending.items():
                        if fut in late:
                            record(job, t0, f"timed out after {timeout:g} s")
                        elif ended(fut):
                            record(job, t0, outcome(fut))
                        elif broken and (n := breaks.get(job.run_id, 0) + 1) >= MAX_BREAKS:
                            record(job, t0, f"its worker process died (in flight at {n} deaths of the pool's workers; a crash or the kernel's OOM killer?)")
                        else:
                            if broken:
                                breaks[job.run_id] = breaks.get(job.run_id, 0) + 1
                            again.append(job)
                    queue[:0] = again
                    pending.clear()
                    break
    finally:
        f.close()
        prog.close()
        clear_scratch(again=False)
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


_fmt = rows.cell  # the cells of sweep.csv and basin.csv
