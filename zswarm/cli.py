"""The ``zswarm`` command: run, sim, sweep, basin, basin-compare, router, compose, record, replay, report, design-hybrid, generate."""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from pathlib import Path
from typing import Any

from zswarm import keys, procutil
from zswarm.text import one_line


def _common_run_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("topology", help="scenario TOML file (see topologies/)")
    p.add_argument("--duration", type=procutil.positive_float, default=None, help="world seconds (default: the scenario's)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: the scenario's)")
    p.add_argument("--out", type=Path, default=None, help="results folder (default runs/<scenario>-<timestamp>/)")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        dest="overrides",
        help="override a scenario field, e.g. --set links.delay_ms=50 --set 'links.per_link.\"1->3\".drop=0.5' (repeatable; VALUE is TOML)",
    )
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="KIND,FIELD=VALUE,...",
        dest="faults",
        help="one more [[faults]] entry, e.g. --fault kill,agent=5,at=10,restart_at=15; stop,agent=3,at=5,duration=2; router,at=8,duration=1; cut,link=1->3,at=4,duration=3 (repeatable)",
    )


def _live_arg(p: argparse.ArgumentParser, what: str) -> None:
    """``--live [HOST:PORT]``: a Foxglove WebSocket server, on the default address without a value."""
    p.add_argument(
        "--live",
        nargs="?",
        type=procutil.host_port,
        const=procutil.host_port(procutil.LIVE_DEFAULT),
        default=None,
        metavar="HOST:PORT",
        help=f"{what} (default {procutil.LIVE_DEFAULT})",
    )


def _load(args: argparse.Namespace) -> Any:
    """The scenario of ``args.topology`` with the ``--set`` overrides (exit 2 on any error)."""
    from zswarm.scenario import ScenarioError, fault_override, parse_override

    try:
        overrides = [parse_override(o) for o in args.overrides] + [fault_override(f) for f in getattr(args, "faults", [])]
    except ScenarioError as exc:
        procutil.fail_usage(str(exc))
    return procutil.load_or_exit(args.topology, overrides)


def build_parser() -> argparse.ArgumentParser:
    p = procutil.ArgumentParser(prog="zswarm", description="Multi-agent distributed estimation over Zenoh: one process per agent.")
    sub = p.add_subparsers(dest="cmd", required=True, metavar="COMMAND")

    r = sub.add_parser("run", help="run a scenario over real processes (router, world, agents, recorder)")
    _common_run_args(r)
    r.add_argument("--time-scale", type=procutil.positive_float, default=1.0, help="world seconds per wall second (default 1)")
    r.add_argument("--quiet", action="store_true", help="no progress output")
    _live_arg(r, "serve the recording's channels on a Foxglove WebSocket server while the run goes on (open it in Foxglove or Lichtblick)")
    r.add_argument(
        "--secure",
        nargs="?",
        const="",
        default=None,
        metavar="DIR",
        help="mutual TLS and access control: certificates made for the run in DIR (default: the results folder's secure/); each process may publish only its own keys",
    )

    s = sub.add_parser("sim", help="run the same world and agents in one process on a virtual clock")
    _common_run_args(s)
    s.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    s.add_argument("--lean", action="store_true", help="leave sensor and edge messages out of the recording (a quarter of the size)")
    s.add_argument("--quiet", action="store_true", help="print nothing but errors")
    s.add_argument("--no-recording", action="store_true", help="write no recording.mcap (the report is made from memory; zswarm sweep uses this)")

    sw = sub.add_parser(
        "sweep",
        help="run a scenario over a grid of field values (repeated with different seeds) and plot the results",
        description="Runs every combination of the --vary values, --repeats times each (seed, seed+1, ...), "
        "each as its own zswarm sim/run process; writes sweep.csv (a row per run) and plots.  Interrupted and "
        "started again with the same arguments and --out, it resumes where it stopped.",
    )
    sw.add_argument("topology", help="scenario TOML file")
    sw.add_argument(
        "--vary",
        action="append",
        required=True,
        metavar="FIELD=V1,V2,...",
        help="a field and its values, e.g. links.delay_ms=0,50,100 or links.drop=0:0.5:0.1 (START:STOP:STEP); repeatable",
    )
    sw.add_argument("--repeats", type=procutil.positive_int, default=1, help="runs per grid point, seeds differing (default 1)")
    sw.add_argument("--engine", choices=("sim", "run"), default="sim", help="zswarm sim (default) or zswarm run (real processes over Zenoh)")
    sw.add_argument("--jobs", type=procutil.positive_int, default=None, help="runs at a time (default: the number of cores for sim, 1 for run)")
    sw.add_argument("--out", type=Path, default=None, help="sweep folder (default sweeps/<scenario>-<timestamp>/); the same folder resumes")
    sw.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE", dest="overrides", help="a fixed override for every run (repeatable)")
    sw.add_argument("--duration", type=procutil.positive_float, default=None, help="world seconds per run (default: the scenario's)")
    sw.add_argument("--seed", type=int, default=None, help="seed of repeat 0 (default: the scenario's); repeat r uses seed + r")
    sw.add_argument(
        "--thresholds",
        default=None,
        metavar="ATT,POS",
        help="convergence thresholds on the mean attitude error |R̃|_I and position error in m (default 0.01,0.1)",
    )
    sw.add_argument("--timeout", type=procutil.positive_float, default=None, help="seconds before a run is killed and recorded as failed")
    sw.add_argument("--keep-recordings", action="store_true", help="keep each run's recording.mcap (deleted by default; summaries and CSVs stay)")

    b = sub.add_parser(
        "basin",
        help="Monte-Carlo check of a tree scheme's global claim: N uniform initial attitudes on sim",
        description="Draws N initial conditions (draw 0: the scenario's own start; then every R_i(0) uniform on SO(3) "
        "for the Chapter 5 laws, Q_i(0) too for the velocity-free one, every R̂_i(0) for the §4 observers), runs each "
        "on sim and reports the fraction that synchronizes (max_k |R̄_k|_I below the threshold from some time on) and "
        "the settle times.  Writes basin.csv, basin.json, basin.png; the same command with the same --out resumes.",
    )
    b.add_argument("topology", help="scenario TOML file (a Chapter 5 law or a §4 observer)")
    b.add_argument("--draws", type=procutil.positive_int, default=101, help="draws including the scenario's own start (default 101)")
    b.add_argument("--seed", type=int, default=1, help="seed of the draws (default 1)")
    b.add_argument("--duration", type=procutil.positive_float, default=None, help="horizon, world seconds (default: the scenario's)")
    b.add_argument("--threshold", type=procutil.positive_float, default=0.01, help="max_k |R̄_k|_I that counts as synchronized (default 0.01)")
    b.add_argument("--jobs", type=procutil.positive_int, default=None, help="draws at a time (default: the number of cores)")
    b.add_argument(
        "--near",
        type=procutil.positive_float,
        default=None,
        metavar="EPS",
        help="instead of uniform draws, turn the scenario's own start by EPS rad about a uniform axis "
        "(shows an almost-global law's slow escape from the undesired set)",
    )
    b.add_argument("--out", type=Path, default=None, help="folder (default basins/<scenario>-<timestamp>/); the same folder resumes")

    bc = sub.add_parser(
        "basin-compare",
        help="compare basin folders: a Markdown table and one figure",
        description="Reads the basin.csv and basin_def.json of each folder written by zswarm basin and prints a Markdown "
        "table (fraction synchronized with its 95 % interval, settle-time quantiles, jumps); writes one figure of the "
        "settle-time distributions, and of settle time against ε for folders made with --near.",
    )
    bc.add_argument("dirs", nargs="+", type=Path, help="folders written by zswarm basin")
    bc.add_argument("--out", type=Path, default=Path("basin-compare.png"), help="the figure (default basin-compare.png)")

    ro = sub.add_parser("router", help="run a Zenoh router for processes started by hand")
    procutil.add_zenoh_args(ro, default_mode="router")
    ro.add_argument("--exit-after-run", metavar="RUN_ID", default=None, help="exit once the recorder of this run has come and gone (compose: the run ends by itself)")
    ro.add_argument(
        "--run-id",
        default="default",
        help="with --secure: the run whose keys the access control is for (default: default); each process with a certificate in DIR may put only its own",
    )

    ce = sub.add_parser(
        "certs",
        help="make a CA and a certificate per process of a scenario, for processes started by hand with --secure DIR",
        description="Writes ca.pem, router.pem, world.pem, recorder.pem and agent-<i>.pem (each with its .key, mode 0600) "
        "into DIR: EC P-256, valid for localhost and 127.0.0.1 (and --host names) for a week.  Then: zswarm router --secure DIR "
        "--run-id R --listen tls/HOST:PORT, and every other process with --secure DIR --connect tls/HOST:PORT.",
    )
    ce.add_argument("dir", type=Path, help="folder for the certificates (created; existing files of the same names are replaced)")
    ce.add_argument("topology", help="scenario TOML file (its agents get a certificate each)")
    ce.add_argument("--host", action="append", default=[], metavar="NAME|IP", help="another name or address the router is reached at (repeatable)")

    co = sub.add_parser(
        "compose",
        help="write a docker-compose file for a scenario: a router, the recorder, the world and one container per agent",
        description="Writes a compose file (to stdout or -o FILE) that runs TOPOLOGY with one container per process on "
        "internal bridge networks.  The scenario's folder is mounted at /scenario, results go to "
        "${ZSWARM_RESULTS:-./runs}/<scenario>/ on the host.  `docker compose up` returns when the run is over.",
    )
    co.add_argument("topology", help="scenario TOML file")
    co.add_argument("-o", "--output", type=Path, default=None, help="the compose file (default: stdout); relative paths in it are from its folder")
    co.add_argument("--image", default="zswarm:latest", help="image of every service (default zswarm:latest)")
    co.add_argument("--build-context", type=Path, default=None, help="folder with zswarm's Dockerfile to build the image from (default: this zswarm's source tree, if it has one)")
    co.add_argument("--no-build", action="store_true", help="no build section: the image must exist (docker build -t IMAGE .)")
    co.add_argument("--base", default=None, help="base image build argument (the Dockerfile's default: python:3.11-slim)")
    co.add_argument("--network", choices=("flat", "routed"), default="flat", help="flat: one network; routed: agents behind a second router on their own network")
    co.add_argument("--run-id", default="compose", help="run id (default compose)")
    co.add_argument("--results", default="${ZSWARM_RESULTS:-./runs}", help="host folder for the results (default ${ZSWARM_RESULTS:-./runs})")
    co.add_argument("--duration", type=procutil.positive_float, default=None, help="world seconds (default: the scenario's)")
    co.add_argument("--time-scale", type=procutil.positive_float, default=1.0, help="world seconds per wall second (default 1)")
    co.add_argument("--seed", type=int, default=None, help="random seed (default: the scenario's)")
    co.add_argument("--live", type=int, default=None, metavar="PORT", help="serve the run on a Foxglove WebSocket server, published on 127.0.0.1:PORT")
    co.add_argument(
        "--set", action="append", default=[], metavar="FIELD=VALUE", dest="overrides", help="override a scenario field; the scenario as run is written beside the compose file"
    )

    rec = sub.add_parser("record", help="record a run (started by hand) into a results folder")
    rec.add_argument("topology", help="scenario TOML file")
    rec.add_argument("--out", type=Path, default=None, help="results folder (default runs/<scenario>-<timestamp>/)")
    rec.add_argument("--no-report", action="store_true", help="do not write summary/plots at the end (the recording stays as recording.raw.mcap, payloads as they came, until zswarm report transcodes it)")
    rec.add_argument("--live", type=procutil.host_port, default=None, metavar="HOST:PORT", help="also serve the channels on a Foxglove WebSocket server")
    procutil.add_run_args(rec)
    procutil.add_zenoh_args(rec)

    rp = sub.add_parser(
        "replay",
        help="play a results folder back: on a Foxglove WebSocket server (--live) or onto a Zenoh network as the original messages",
        description="Plays RESULTS/recording.mcap back at --speed times its pace.  With --live, serves every channel "
        "(the run's messages, /tf, /scene, /errors, ...) on a Foxglove WebSocket server; with --connect/--listen, "
        "publishes every message on its original key under --run-id (default: the recorded one), liveliness included, "
        "for zswarm record or your own subscribers.  Both at once work too.",
    )
    rp.add_argument("results", type=Path, help="results folder holding recording.mcap and scenario.toml")
    _live_arg(rp, "serve on a Foxglove WebSocket server")
    rp.add_argument("--speed", type=procutil.positive_float_or_inf, default=1.0, help="times the recording's pace (default 1; 'inf': as fast as possible)")
    rp.add_argument("--run-id", default=None, help="run id to publish under on Zenoh (default: the recorded run's)")
    rp.add_argument("--wait-for-recorder", action="store_true", help="on Zenoh: start once a zswarm recorder of --run-id is alive")
    rp.add_argument("--hold", action="store_true", help="with --live: keep serving after the end until Ctrl-C")
    procutil.add_zenoh_args(rp)  # an endpoint replays onto a Zenoh network

    rep = sub.add_parser("report", help="(re)compute summary.json, errors.csv and plots of a results folder")
    rep.add_argument("results", type=Path, help="results folder holding recording.mcap and scenario.toml")

    g = sub.add_parser(
        "generate",
        help="write an N-agent scenario of an algorithm family (graph, positions, motions, initial errors from a seed)",
        description="Writes a scenario that loads by construction: the family's algorithm, gains and world as in its paper's "
        "shipped scenario; the graph, positions, motions and initial estimation errors drawn from --seed.",
    )
    g.add_argument("family", nargs="?", help="algorithm family (--list shows them)")
    g.add_argument("-n", "--agents", type=int, default=None, help="number of agents")
    g.add_argument("--seed", type=int, default=1, help="seed of the draw, and the scenario's seed (default 1)")
    g.add_argument("--graph", default=None, help="graph shape (default: the family's first; --list shows them)")
    g.add_argument("--in-degree", type=int, default=3, help="leader-follower families: in-neighbours per follower (default 3)")
    g.add_argument("--max-angle", type=float, default=0.9, help="largest initial attitude error, a fraction of pi (default 0.9)")
    g.add_argument("--spread", type=float, default=3.0, help="RMS initial position error, m (default 3)")
    g.add_argument("--duration", type=procutil.positive_float, default=None, help="the scenario's duration, s (default: the family's)")
    g.add_argument("--name", default=None, help="scenario name (default gen-<family>-<n>-s<seed>)")
    g.add_argument("-o", "--output", type=Path, default=None, help="file to write (default: standard output)")
    g.add_argument("--list", action="store_true", help="list the families and their graph shapes")

    d = sub.add_parser(
        "design-hybrid",
        help="Prop. 4.2: u, Δ*, and the bounds on γ and δ for A and Ξ; checks Condition 4.1",
        description="Thesis Prop. 4.2 (§4.3.2.3): from the eigenvalues of A and the set Ξ, compute u, Δ*, "
        "the bounds γ < 4Δ*/π² and δ < (4Δ*/π² − γ) ξ_L²/2, and check Condition 4.1 at the undesired critical "
        "points.  Without --gamma/--delta, both are taken at 95 %% of their bounds (the thesis' choice).",
    )
    d.add_argument("--A", required=True, help="eigenvalues of a diagonal A, e.g. 5,8.57,12 (or 9 numbers, row-major)")
    d.add_argument("--xi", required=True, help="the set Ξ, e.g. 0.08pi or 0.5,0.9pi")
    d.add_argument("--gamma", default=None, help="γ to check (default: 0.95 of its bound)")
    d.add_argument("--delta", default=None, help="δ to check (default: 0.95 of its bound)")
    d.add_argument("--u", default=None, help="u to check against Prop. 4.2's (3 numbers)")
    d.add_argument("--json", action="store_true", help="print the design as JSON")
    return p


def main(argv: list[str] | None = None) -> int:
    procutil.die_with_parent()  # as a sweep's child: ends with the sweep
    args = build_parser().parse_args(argv)
    cmds = {"run": cmd_run, "sim": cmd_sim, "sweep": cmd_sweep, "basin": cmd_basin, "basin-compare": cmd_basin_compare, "router": cmd_router, "compose": cmd_compose, "record": cmd_record, "replay": cmd_replay, "report": cmd_report, "design-hybrid": cmd_design_hybrid, "generate": cmd_generate, "certs": cmd_certs}
    try:
        return cmds[args.cmd](args)
    except Exception as exc:
        problem = procutil.write_problem(exc)
        if problem is None:
            raise
        print(f"zswarm {args.cmd}: {one_line(problem)}", file=sys.stderr)
        return 1


def cmd_run(args: argparse.Namespace) -> int:
    from zswarm import launch

    sc = _load(args)
    _warn(sc)
    secure = None if args.secure is None else Path(args.secure) if args.secure else True
    return launch.run(args.topology, sc, args.out, args.duration, args.time_scale, args.seed, quiet=args.quiet, live=args.live, secure=secure)


def cmd_sim(args: argparse.Namespace) -> int:

    from zswarm import report
    from zswarm.launch import results_dir
    from zswarm.sim import LEAN_SKIP, simulate

    sc = _load(args)
    _warn(sc)
    duration = sc.duration if args.duration is None else args.duration
    seed = sc.seed if args.seed is None else args.seed
    out = results_dir(args.out, sc.name)
    (out / "scenario.toml").write_text(sc.text, encoding="utf-8")
    tty = sys.stderr.isatty()

    def progress(t: float) -> None:
        if tty:
            print(f"\rt = {t:6.1f} / {duration:g} s", end="", file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    kept: list[tuple[str, bytes, int]] = []
    times: dict[str, float] = {}
    recorded = simulate(sc, out, duration, seed, progress=None if args.quiet else progress, lean=args.lean, record=not args.no_recording, keep=kept, times=times)
    wall = time.perf_counter() - t0
    if tty and not args.quiet:
        print(file=sys.stderr)
    messages = recorded if isinstance(recorded, list) else (kept or None)
    summary = report.make_report(out, sc, "sim", duration, 0.0, seed, plots=not args.no_plots, messages=messages, not_recorded=LEAN_SKIP if args.lean else ())
    summary["wall_time_s"] = wall
    summary["wall_time_run_s"] = times["run_s"]
    summary["wall_time_recording_s"] = times["record_s"]
    summary["wall_time_report_s"] = time.perf_counter() - t0 - wall
    report.write_summary(out / "summary.json", summary)
    if not args.quiet:
        print(report.table(summary))
        print(
            f"simulated {duration:g} s in {times['run_s']:.1f} s of wall time ({duration / max(times['run_s'], 1e-9):.1f}x real time), "
            f"then the recording in {times['record_s']:.1f} s and the report in {summary['wall_time_report_s']:.1f} s; results: {out}"
        )
    return 0 if summary["completed"] else 1


def cmd_sweep(args: argparse.Namespace) -> int:
    import os
    import threading

    from zswarm import sweep
    from zswarm.launch import results_dir
    from zswarm.scenario import ScenarioError, parse_override

    thresholds = (0.01, 0.1)
    if args.thresholds is not None:
        parts = args.thresholds.split(",")
        if len(parts) != 2:
            procutil.fail_usage(f"--thresholds: give ATT,POS, e.g. 0.01,0.1 (got {args.thresholds!r})")
        a, p_ = (_number(x, "--thresholds") for x in parts)
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
    spec_path = out / "sweep.json"
    if spec_path.exists():
        old = json.loads(spec_path.read_text())
        diff = sorted(k for k in set(old) | set(spec) if k != "topology" and old.get(k) != spec.get(k))
        if diff:
            procutil.fail_usage(f"--out {out}: holds a different sweep (differs in: {', '.join(diff)}); use another --out to start a new one")
    else:
        spec_path.write_text(json.dumps(spec, indent=2) + "\n")
    n_jobs = args.jobs or ((os.cpu_count() or 1) if args.engine == "sim" else 1)
    timeout = args.timeout or (max(120.0, 10.0 * duration) if args.engine == "sim" else duration + 180.0)
    stop = threading.Event()
    procutil.stop_on_signals_into(stop)
    n_points = len(jobs) // args.repeats
    print(f"sweep of {sc.name}: {n_points} grid points x {args.repeats} repeats = {len(jobs)} runs on {args.engine}, {n_jobs} at a time; {out}", file=sys.stderr)
    t0 = time.monotonic()
    ok, _failed, interrupted = sweep.run_sweep(
        args.topology, sc, jobs, varies, out, args.engine, n_jobs, duration, thresholds, timeout, args.keep_recordings, stop.is_set
    )
    wall = time.monotonic() - t0
    rows = sweep.load_rows(out / "sweep.csv")
    if interrupted:
        print(f"interrupted: {len(rows)} of {len(jobs)} runs are in {out / 'sweep.csv'}; the same command resumes", file=sys.stderr)
        return 130
    plots = sweep.plot_sweep(out, rows, [v.field for v in varies], duration)
    n_failed = sum(1 for r in rows if r["status"] == "failed")
    print(f"{len(rows)} runs ({ok} run now in {wall:.0f} s, {n_failed} failed in all); {out / 'sweep.csv'}; plots: {', '.join(p.name for p in plots) or 'none'}")
    return 0 if n_failed == 0 else 1


def cmd_basin(args: argparse.Namespace) -> int:
    import os
    import threading

    from zswarm import basin
    from zswarm.launch import results_dir

    sc = procutil.load_or_exit(args.topology)
    try:
        basin.starts_of(sc)
    except ValueError as exc:
        procutil.fail_usage(f"{args.topology}: {exc}")
    duration = sc.duration if args.duration is None else args.duration
    out = args.out if args.out is not None else results_dir(None, sc.name, base=Path("basins"))
    out.mkdir(parents=True, exist_ok=True)
    spec = {"topology": str(args.topology), "scenario": sc.name, "seed": args.seed, "duration_s": duration, "threshold": args.threshold, "near": args.near}
    spec_path = out / "basin_def.json"
    if spec_path.exists():
        old = json.loads(spec_path.read_text())
        diff = sorted(k for k in spec if k != "topology" and old.get(k) != spec[k])
        if diff:
            procutil.fail_usage(f"--out {out}: holds a different basin check (differs in: {', '.join(diff)}); use another --out")
    else:
        spec_path.write_text(json.dumps(spec, indent=2) + "\n")
    stop = threading.Event()
    procutil.stop_on_signals_into(stop)
    jobs = args.jobs or (os.cpu_count() or 1)
    print(f"basin of {sc.name}: {args.draws} draws ({duration:g} s each) on sim, {jobs} at a time; {out}", file=sys.stderr)
    t0 = time.monotonic()
    rows, interrupted = basin.run_basin(
        str(args.topology), args.draws, args.seed, duration, args.threshold, out, jobs, stop.is_set, lambda m: print(m, file=sys.stderr, flush=True), args.near
    )
    if interrupted:
        print(f"interrupted: {len(rows)} of {args.draws} draws are in {out / 'basin.csv'}; the same command resumes", file=sys.stderr)
        return 130
    s = basin.write(out, sc.name, rows, args.threshold, duration, args.near)
    print(basin.table(sc.name, s))
    print(f"{len(rows)} draws in {out / 'basin.csv'} ({time.monotonic() - t0:.0f} s now); {out / 'basin.json'}, {out / 'basin.png'}")
    return 0 if not s["failed"] else 1


def cmd_basin_compare(args: argparse.Namespace) -> int:
    from zswarm import basin

    try:
        entries = basin.compare(args.dirs)
    except ValueError as exc:
        procutil.fail_usage(str(exc))
    print(basin.compare_table(entries))
    for line in basin.paired(entries):
        print(f"\n{line}")
    if args.out.parent != Path(""):
        args.out.parent.mkdir(parents=True, exist_ok=True)
    print(f"figure: {basin.plot_compare(entries, args.out)}", file=sys.stderr)
    return 0


def cmd_router(args: argparse.Namespace) -> int:
    from zswarm import secure as sec
    from zswarm.bus import ZenohBus

    if not args.listen and not args.config:
        procutil.fail_usage("router needs --listen ENDPOINT, e.g. --listen tcp/127.0.0.1:7447")
    acl = None
    if args.secure:
        run = keys.check_run_id(args.run_id)
        plain = [e for e in args.listen if not e.startswith("tls/")]
        if plain:
            procutil.fail_usage(f"router --secure listens on tls/ endpoints only (got {', '.join(plain)})")
        procs = sec.processes_in(Path(args.secure))
        if not procs:
            procutil.fail_usage(f"--secure {args.secure}: no process certificates there (zswarm certs DIR TOPOLOGY makes them)")
        acl = sec.acl(run, procs)
    log = procutil.setup_logging("router")
    with ZenohBus(procutil.zenoh_conf(args, sec.ROUTER, acl=acl)) as bus:
        if acl is not None:
            log.info("mutual TLS; run %r: %d processes may put their own keys (%s)", args.run_id, len(procs), ", ".join(sec.name_of(r, i) for r, i in procs))
        stop = procutil.stop_on_signals()
        log.info("zenoh %s listening on %s; Ctrl-C to stop", args.mode, ", ".join(args.listen) or "(config)")
        if args.exit_after_run:
            run = keys.check_run_id(args.exit_after_run)
            seen = threading.Event()

            def on_recorder(_key: str, alive: bool) -> None:
                if alive:
                    seen.set()
                elif seen.is_set():
                    log.info("the recorder of run %r is gone: exiting", run)
                    stop.set()

            bus.watch_alive(keys.alive(run, "recorder", 0), on_recorder)
        stop.wait()
    return 0


def cmd_certs(args: argparse.Namespace) -> int:
    from zswarm import secure as sec

    sc = procutil.load_or_exit(args.topology)
    names = sec.certificate_names(sc.ids)
    sec.make_certs(args.dir, names, hosts=args.host)
    print(f"{args.dir}: ca.pem, {sec.ROUTER}.pem, " + ", ".join(f"{n}.pem" for n in names) + " (and their .key)")
    return 0


def cmd_compose(args: argparse.Namespace) -> int:
    from zswarm import compose

    sc = _load(args)
    undone = [f.describe() for f in sc.faults if f.kind != "cut"]
    if undone:
        # A cut is the receivers' link emulation and happens in containers too; a kill, stop
        # or router fault needs a launcher, which compose does not have.
        print(f"zswarm compose: note: docker compose does not carry out these faults (zswarm run and sim do): {'; '.join(undone)}", file=sys.stderr)
    topology = Path(args.topology)
    if args.overrides:
        if args.output is None:
            procutil.fail_usage("--set needs -o FILE (the scenario as run is written beside it)")
        topology = args.output.with_name(args.output.stem + ".scenario.toml")
        topology.write_text(sc.text, encoding="utf-8")
    build = None
    if not args.no_build:
        build = args.build_context
        if build is None:
            src = Path(__file__).resolve().parent.parent
            build = src if (src / "Dockerfile").exists() else None
        elif not (build / "Dockerfile").exists():
            procutil.fail_usage(f"{build}: no Dockerfile there")
    text = compose.write(
        sc,
        topology,
        args.output,
        args.image,
        build,
        args.base,
        keys.check_run_id(args.run_id),
        args.results,
        args.network,
        args.duration,
        args.time_scale,
        args.seed,
        args.live,
        argv=sys.argv[2:],
    )
    _write_output(text, args.output, f"({len(sc.ids)} agents); run it with: docker compose -f {args.output} up")
    return 0


# The recorder gives back what a catch-up freed (procutil.trim_heap) every 30 s.  A trim took
# 20-80 ms here on a heap of 85 MiB churned, with the soak saturating both cores: <= 0.3 % of
# the recorder's time; meanwhile samples wait in the kernel's socket buffer and Zenoh's FIFO.
TRIM_EVERY_S = 30.0
FINAL_STATS_WAIT_S = 8.0  # the recorder's wait for the processes' final stats after the run's stop


def cmd_record(args: argparse.Namespace) -> int:
    from zswarm import report, wire
    from zswarm.bus import ZenohBus
    from zswarm.launch import results_dir
    from zswarm.record import RAW_SUFFIX, Recorder

    sc = procutil.load_or_exit(args.topology)
    conf = procutil.zenoh_conf(args, "recorder")
    log = procutil.setup_logging("recorder")
    run = keys.check_run_id(args.run_id)
    out = results_dir(args.out, sc.name)
    if not (out / "scenario.toml").exists():
        (out / "scenario.toml").write_text(sc.text)
    start: dict[str, object] = {}
    with ZenohBus(conf) as bus:
        stop = procutil.stop_on_signals()
        # Without a live view the recorder copies payloads as they come (recording.raw.mcap);
        # the report below (or zswarm report) transcodes them into recording.mcap.
        path = out / ("recording" + (RAW_SUFFIX if args.live is None else ".mcap"))
        rec = Recorder(bus, run, path, metadata={"engine": "run", "scenario": sc.name, "run": run}, scenario=sc, live=args.live, raw=args.live is None)

        def on_start(key: str, payload: bytes) -> None:
            if not start:
                try:
                    start.update(wire.decode_ctl(payload, "start"))
                except wire.MessageError:
                    pass

        bus.subscribe(keys.ctl(run, "start"), on_start)
        procutil.warm_up()
        bus.declare_token(keys.alive(run, "recorder", 0))
        log.info("recording run %r into %s", run, path)
        if args.live is not None:
            log.info("live view on ws://%s:%d (Foxglove or Lichtblick: open connection, Foxglove WebSocket)", args.live[0], rec.live_port)
        procs = [("world", 0), *(("agent", i) for i in sc.ids)]
        try:
            next_flush = time.monotonic() + 0.5
            next_trim = time.monotonic() + TRIM_EVERY_S
            while not stop.is_set() and not rec.stopped.is_set():
                stop.wait(0.01)
                rec.poll()
                if time.monotonic() >= next_flush:
                    rec.flush()
                    next_flush += 0.5
                if time.monotonic() >= next_trim:
                    procutil.trim_heap()  # what a catch-up freed goes back (procutil.trim_heap)
                    next_trim += TRIM_EVERY_S
            if rec.stopped.is_set() and not stop.is_set():
                # The run ended: wait for the final stats of every process still up.  A fixed
                # second was not always enough on a loaded machine (an agent behind its
                # schedule stops later), and a missed one reads as an agent that died.
                # Bounded: `zswarm run` kills a process that has not stopped 6 s after the world.
                end = time.monotonic() + FINAL_STATS_WAIT_S
                while not stop.is_set() and time.monotonic() < end and rec.awaiting_finals(procs):
                    stop.wait(0.01)
                    rec.poll()
                end = time.monotonic() + 0.2  # what is in flight from processes that went meanwhile
                while not stop.is_set() and time.monotonic() < end:
                    stop.wait(0.01)
                    rec.poll()
        finally:
            rec.close()  # takes what arrived since the last poll
            log.info("closed recording: %d messages", rec.count)
        if rec.stopped.is_set() and not stop.is_set() and (missing := rec.missing_finals(procs)):
            # The report will call them not alive at the end: say what was seen of them.
            log.warning(
                "no final stats from %s (token up at the end: %s)",
                ", ".join(f"{r} {i}" for r, i in missing),
                ", ".join(f"{r} {i}: {rec.alive.get(keys.alive(run, r, i))}" for r, i in missing),
            )
    if not args.no_report and start:
        summary = report.make_report(out, sc, "run", float(start["duration"]), float(start["time_scale"]), int(start["seed"]))  # type: ignore[arg-type]
        print(report.table(summary))
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    from zswarm import replay
    from zswarm.record import ensure_recording

    sc = procutil.load_or_exit(str(args.results / "scenario.toml")) if (args.results / "scenario.toml").exists() else None
    rec_path = ensure_recording(args.results, sc)
    if not rec_path.exists():
        procutil.fail_usage(f"{rec_path}: no recording there")
    zenoh_out = bool(args.connect or args.listen or args.config)
    if args.live is None and not zenoh_out:
        procutil.fail_usage("replay needs --live [HOST:PORT] or a Zenoh endpoint (--connect/--listen/--config)")
    log = procutil.setup_logging("replay")
    stop = procutil.stop_on_signals()
    run = None
    if zenoh_out:
        run = keys.check_run_id(args.run_id or replay.recorded_run_id(rec_path) or "default")
    bus = None
    try:
        if zenoh_out:
            from zswarm.bus import ZenohBus

            bus = ZenohBus(procutil.zenoh_conf(args))
            if args.wait_for_recorder:
                up = threading.Event()
                bus.watch_alive(keys.alive(run, "recorder", 0), lambda _k, alive: up.set() if alive else None)  # type: ignore[arg-type]
                log.info("waiting for a recorder of run %r", run)
                while not up.wait(0.2):
                    if stop.is_set():
                        return 130
        counts = replay.run_replay(args.results, sc, args.speed, args.live, bus, run, stop, hold=args.hold)
        log.info("replayed %d messages and %d liveliness events%s", counts["messages"], counts["alive_events"], f" onto run {run!r}" if run else "")
    finally:
        if bus is not None:
            time.sleep(0.5)  # let the last samples leave before the session closes
            bus.close()
    return 130 if stop.is_set() else 0


def cmd_report(args: argparse.Namespace) -> int:
    from zswarm import report, wire
    from zswarm.record import decode, ensure_recording, read

    sc = procutil.load_or_exit(str(args.results / "scenario.toml"))
    rec_path = ensure_recording(args.results, sc)
    if not rec_path.exists():
        procutil.fail_usage(f"{rec_path}: no recording there")
    start = None
    for topic, payload, _t in read(rec_path):
        if topic == "ctl/start":
            try:
                start = decode(payload, "start")
            except wire.MessageError:
                continue
            break
    prev = {}
    if (args.results / "summary.json").exists():
        prev = json.loads((args.results / "summary.json").read_text())
    engine = prev.get("engine", "run")
    duration = float(prev.get("duration_s", start["duration"] if start else sc.duration))
    scale = float(prev.get("time_scale", start["time_scale"] if start else 1.0))
    seed = int(prev.get("seed", start["seed"] if start else sc.seed))
    summary = report.make_report(args.results, sc, engine, duration, scale, seed, not_recorded=prev.get("recording", {}).get("not_recorded", ()))
    print(report.table(summary))
    return 0


def cmd_generate(args: argparse.Namespace) -> int:
    from zswarm import generate

    if args.list:
        for fam, what, graphs in generate.describe():
            print(f"{fam:<28} graphs: {', '.join(graphs):<22} {what}")
        return 0
    if args.family is None or args.agents is None:
        procutil.fail_usage("generate needs a FAMILY and -n N (zswarm generate --list shows the families)")
    try:
        text, sc = generate.generate(
            args.family,
            args.agents,
            args.seed,
            graph=args.graph,
            in_degree=args.in_degree,
            max_angle=args.max_angle,
            spread=args.spread,
            duration=args.duration,
            name=args.name,
        )
    except ValueError as exc:
        procutil.fail_usage(f"generate: {exc}")
    _write_output(text, args.output, f": {sc.name}, {len(sc.ids)} agents, {sc.duration:g} s")
    return 0


def _write_output(text: str, output: Path | None, what: str) -> None:
    """``text`` to standard output, or to ``output`` (its folder made) with "wrote FILE<what>" on stderr."""
    if output is None:
        sys.stdout.write(text)
        return
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(text, encoding="utf-8")
    print(f"wrote {output}{what}", file=sys.stderr)


def _warn(sc: object) -> None:
    for w in getattr(sc, "warnings", ()):
        print(f"{getattr(sc, 'path', '')}: note: {w}", file=sys.stderr)


def _number(s: str, flag: str) -> float:
    """A number or an expression such as ``0.08pi`` / ``0.08*pi`` / ``pi/2``."""
    import math
    import re

    from zswarm.expr import ExprError, parse

    text = s.strip()
    text = re.sub(r"^([0-9.eE+-]+)\s*pi$", r"\1*pi", text)
    try:
        x = float(parse(text)(0.0))
    except ExprError as exc:
        procutil.fail_usage(f"{flag}: {exc} (got {s!r})")
    if not math.isfinite(x):
        procutil.fail_usage(f"{flag}: must be finite (got {s!r})")
    return x


def cmd_design_hybrid(args: argparse.Namespace) -> int:
    import numpy as np

    from zswarm import hybrid

    vals = [_number(x, "--A") for x in args.A.split(",")]
    if len(vals) == 3:
        A = np.diag(vals)
    elif len(vals) == 9:
        A = np.array(vals).reshape(3, 3)
    else:
        procutil.fail_usage(f"--A: give 3 eigenvalues or 9 entries (got {len(vals)} numbers)")
    Xi = [_number(x, "--xi") for x in args.xi.split(",")]
    gamma = None if args.gamma is None else _number(args.gamma, "--gamma")
    delta = None if args.delta is None else _number(args.delta, "--delta")
    try:
        if args.u is not None:
            u = [_number(x, "--u") for x in args.u.split(",")]
            if len(u) != 3:
                procutil.fail_usage(f"--u: give 3 numbers (got {len(u)})")
            base = hybrid.design(A, Xi, gamma, delta)
            d = hybrid.check_parameters(A, np.array(u), base.gamma, base.delta, Xi)
        else:
            d = hybrid.design(A, Xi, gamma, delta)
    except hybrid.DesignError as exc:
        procutil.fail_usage(f"--{exc.field.lower()}: {exc.problem}")
    if args.json:
        print(json.dumps(d.as_dict(), indent=2))
        return 0
    lam = d.eigenvalues
    case_text = {1: "λ1 = λ2", 2: "λ2 ≥ λ1λ3/(λ3−λ1)", 3: "λ1 < λ2 < λ1λ3/(λ3−λ1)"}[d.case]
    print(
        f"A: eigenvalues λ = {lam[0]:g}, {lam[1]:g}, {lam[2]:g}; Prop. 4.2 case {d.case} ({case_text}; λ1λ3/(λ3−λ1) = {lam[0] * lam[2] / (lam[2] - lam[0]):.6g})"
    )
    print(f"u       = [{', '.join(f'{x:.4f}' for x in d.u)}]   (α = [{', '.join(f'{a:.4f}' for a in d.alpha)}] on the eigenvectors of A)")
    print(f"Δ*      = {d.Delta_star:.6g}")
    print(f"γ       = {d.gamma:.6g}   (bound: γ < 4Δ*/π² = {d.gamma_max:.6g})")
    print(f"δ       = {d.delta:.6g}   (bound: 0 < δ < (4Δ*/π² − γ) ξ_L²/2 = {d.delta_max:.6g}, ξ_L = {max(abs(x) for x in Xi):.6g})")
    print(f"Ξ       = {{{', '.join(f'{x:.6g}' for x in Xi)}}}")
    gaps = ", ".join(f"{g:.4g}" for g in d.gaps)
    print(f"Condition 4.1: U(R̄,0) − min_Ξ U(R̄,ξ) at R̄ = Ra(π, q_β), β = 1,2,3: {gaps}  (> δ: {'holds' if d.condition_holds else 'FAILS'})")
    print(
        "Condition 5.1 (the velocity-free law's (Q̃_i, ζ_i), §5.4) is the same condition on the same potential (4.23): "
        f"with δ_Q̃ = {d.delta:.6g} and Π = Ξ it {'holds' if d.condition_holds else 'FAILS'} (Remark 5.2); "
        "[algorithm.params] delta_Q, Pi are checked against these bounds too"
    )
    return 0 if d.condition_holds else 1


if __name__ == "__main__":
    sys.exit(main())
