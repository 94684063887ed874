"""``zswarm sweep``, the command (zswarm.cli dispatches here): arguments to a plan, the runs on
the batched engine, sim, run or a Dask cluster, resumed from sweep.csv, then the figures."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from zswarm.families import contract as family
from zswarm.transport import procutil
from zswarm.util import files


def command(args: argparse.Namespace) -> int:
    import os
    import threading

    from zswarm.engines.launch import results_dir
    from zswarm.scenario import ScenarioError, parse_override
    from zswarm.studies import sweep, sweep_batched, sweep_figures

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
            batches, rest = sweep_batched.plan_batches(args.topology, todo, args.chunk, n_jobs, auto=args.engine == "auto")
        except ScenarioError as exc:
            procutil.fail_usage(str(exc))
        if rest and args.engine == "batched":
            procutil.fail_usage(f"--engine batched: run {rest[0][0].run_id}: {rest[0][1]} (--engine auto runs such runs on sim)")
        if rest:
            print(f"{len(rest)} of {len(todo)} runs on sim: {rest[0][1]}", file=sys.stderr)
        on_sim = [j for j, _ in rest]
    spec_path = out / "sweep.json"
    if spec_path.exists():
        try:
            old = files.read_json_object(spec_path)
        except ValueError as exc:
            procutil.fail_usage(f"{spec_path}: not a sweep's definition ({exc}); use another --out to start a new sweep")
        # The engines whose rows agree (batched and sim: tests/component/test_sweep.py) may resume each other's sweeps.
        same_rows = {old.get("engine"), spec.get("engine")} <= {"auto", "batched", "sim"}
        diff = sorted(k for k in set(old) | set(spec) if k != "topology" and not (k == "engine" and same_rows) and old.get(k) != spec.get(k))
        if diff:
            procutil.fail_usage(f"--out {out}: holds a different sweep (differs in: {', '.join(diff)}); use another --out to start a new one")
    else:
        files.write_text(spec_path, json.dumps(spec, indent=2) + "\n")  # whole or not at all
    sim_engine = "run" if args.engine == "run" else "sim"
    timeout = args.timeout or (max(120.0, 10.0 * duration) if sim_engine == "sim" else duration + 180.0)
    stop = threading.Event()
    procutil.stop_on_signals_into(stop)
    # One sweep at a time in a folder; a killed one's runs (which die with it) end first.
    lock = files.hold(out, "sweep", stop.is_set)
    if lock is None:
        return procutil.interrupted_code()
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
            ok, _failed, interrupted = sweep_batched.run_sweep_batched(args.topology, jobs, batches, varies, out, duration, thresholds, n_jobs, args.cluster, stop.is_set)
        if on_sim and not interrupted:
            if args.cluster is not None or (sim_engine == "sim" and not args.keep_recordings):
                ok2, _failed, interrupted = sweep.run_sweep_workers(args.topology, jobs, varies, out, duration, thresholds, n_jobs, args.cluster, stop.is_set, timeout)
            else:
                ok2, _failed, interrupted = sweep.run_sweep(
                    args.topology, sc, jobs, varies, out, sim_engine, n_jobs, duration, thresholds, timeout, args.keep_recordings, stop.is_set, lock
                )
            ok += ok2
    except ClusterError as exc:
        print(f"zswarm sweep: {exc}", file=sys.stderr)
        return 1
    wall = time.monotonic() - t0
    rows = sweep_figures.load_rows(out / "sweep.csv")
    if interrupted:
        print(f"interrupted: {len(rows)} of {len(jobs)} runs are in {out / 'sweep.csv'}; the same command resumes", file=sys.stderr)
        return procutil.interrupted_code()
    if args.no_plots:
        sweep_figures.remove_figures(out)
        plots = []
    else:
        plots = sweep_figures.plot_sweep(out, rows, [v.field for v in varies], duration, family.of(sc).sweep.figures, scenario=sc.name)
    n_failed = sum(1 for r in rows if r["status"] == "failed")
    print(f"{len(rows)} runs ({ok} run now in {wall:.0f} s, {n_failed} failed in all); {out / 'sweep.csv'}; plots: {', '.join(p.name for p in plots) or 'none'}")
    return 0 if n_failed == 0 else 1
