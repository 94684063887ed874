"""``zswarm sweep`` on the batched engine: the runs that share a scenario but for seeds, noise
variances and starts stepped together (agent/batched.py, found by entry point), each run's
sweep.csv row as :func:`zswarm.studies.sweep.summarize_run` reads it from a sim run's files."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from zswarm.families import contract as family
from zswarm.scenario import Override, Scenario, load, loads
from zswarm.studies.sweep import Job, Vary, _fmt, _job_row, _median, _open, columns


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
    from zswarm.report import convergence_time
    from zswarm.util import plugins

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
    res = plugins.engine("batched").run(scs, duration, 0, fam.grid_s, seeds=[j.seed for j in batch], rows=True)
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
