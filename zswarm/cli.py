"""The ``zswarm`` command: builds the parser and hands each subcommand to the run function of its
module (``zswarm.engines.sim.command``, ``zswarm.studies.sweep_command.command``, ...); run, router, report and certs are
small enough to stay here."""

from __future__ import annotations

import argparse
import json
import sys
import threading
from pathlib import Path
from typing import Any

from zswarm.families import contract as family
from zswarm.transport import keys, procutil
from zswarm.transport.probe import add_args as probe_args
from zswarm.util.quoting import one_line


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
    p.add_argument(
        "--allow-long",
        action="store_true",
        help="run even when the run's estimated CPU time (from its world steps and agent ticks) is over a day; without it such a run is refused with one line naming the estimate (exit 2)",
    )


def _rerun_arg(p: argparse.ArgumentParser, what: str) -> None:
    """``--rerun [URL]``: stream to a Rerun viewer, at its default address without a value."""
    url = procutil.RERUN_DEFAULT
    p.add_argument("--rerun", nargs="?", const=url, default=None, metavar="URL", help=f"{what} (default {url}, where 'rerun' listens; needs zswarm[rerun])")


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


# Every subcommand's --help ends with examples and its exit codes (issue 48).  1 is what each
# command means by a failure; 2, 130 and 143 mean the same everywhere (EXIT_USAGE; SIGINT and
# SIGTERM, 128 + the signal's number: procutil.interrupted_code).
T32 = "topologies/thesis-3.2-fixed8.toml"
T56 = "topologies/thesis-5.6-hybrid7.toml"
EXAMPLES: dict[str, tuple[tuple[str, ...], str]] = {
    "run": ((f"zswarm run {T32} --duration 20", f"zswarm run {T32} --set links.delay_ms=50 --live"), "the run did not complete (a process died or the recording is cut short)"),
    "sim": ((f"zswarm sim {T32} --duration 40", f"zswarm sim {T32} --fault kill,agent=5,at=10"), "the run did not complete"),
    "sweep": ((f"zswarm sweep {T32} --vary links.delay_ms=0,50,100 --repeats 3 --duration 20",), "a run of the sweep failed (the others are in sweep.csv)"),
    "basin": ((f"zswarm basin {T56} --draws 1000 --duration 20",), "a draw failed (the others are in basin.csv)"),
    "basin-compare": (("zswarm basin-compare basins/a basins/b",), "a file could not be written"),
    "router": (("zswarm router --listen tcp/127.0.0.1:7447",), "a file could not be written"),
    "certs": ((f"zswarm certs certs/ {T32} --host 127.0.0.1",), "a file could not be written"),
    "compose": ((f"zswarm compose {T32} -o compose.yml",), "a file could not be written"),
    "record": ((f"zswarm record {T32} --connect tcp/127.0.0.1:7447 --run-id demo",), "a results file could not be written"),
    "replay": (("zswarm replay runs/thesis-3.2-fixed8 --live",), "a file could not be read or written"),
    "view": (("zswarm view runs/thesis-3.2-fixed8", "zswarm view runs/thesis-3.2-fixed8 --save run.rrd"), "the viewer failed, or the recording is damaged (what could be read is shown; a line names each loss)"),
    "report": (("zswarm report runs/thesis-3.2-fixed8",), "the run did not complete (as zswarm run says: its summary's problems), the recording is damaged, or a results file could not be written"),
    "info": (("zswarm info runs/thesis-3.2-fixed8", "zswarm info runs/thesis-3.2-fixed8/recording.mcap --json"), "the path could not be read"),
    "runs": (("zswarm runs", "zswarm runs results/ --json"), "the directory could not be read"),
    "echo": (("zswarm echo est/3 --results runs/thesis-3.2-fixed8", "zswarm echo 'edge/*/3' --connect tcp/127.0.0.1:7447 --run-id demo --count 5"), "the Zenoh session failed"),
    "hz": (("zswarm hz 'sense/*' --results runs/thesis-3.2-fixed8", "zswarm hz '**' --connect tcp/127.0.0.1:7447 --run-id demo --duration 10"), "the Zenoh session failed"),
    "generate": (("zswarm generate --list", "zswarm generate bearing-fixed -n 8 --seed 3 -o my.toml"), "a file could not be written"),
}


def _epilog(examples: tuple[str, ...], failure: str) -> str:
    lines = ["examples:", *(f"  {e}" for e in examples), "", "exit codes:", "  0    done", f"  1    {failure}", "  2    bad arguments or a bad scenario file (one line on stderr: file: field: problem)", "  130  interrupted (Ctrl-C, SIGINT)", "  143  stopped by SIGTERM (kill, docker stop)"]
    return "\n".join(lines)


class _Formatter(argparse.HelpFormatter):
    """Descriptions wrapped as argparse wraps them; an epilog of several lines kept as written."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        return text if "\n" in text else super()._fill_text(text, width, indent)


def _explain(sub: Any) -> None:
    """Examples and exit codes at the end of every subcommand's --help (a family's command: its
    own examples, or its --help)."""
    own = family.commands()
    for name, parser in sub.choices.items():
        if name in EXAMPLES:
            examples, failure = EXAMPLES[name]
        else:
            examples, failure = own[name].examples or (f"zswarm {name} --help",), "the command failed"
        parser.epilog = _epilog(examples, failure)
        parser.formatter_class = _Formatter


def _version() -> str:
    """The installed distribution's version (pyproject.toml's, when installed from this checkout)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("zswarm")
    except PackageNotFoundError:  # run from a checkout that is not installed
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    p = procutil.ArgumentParser(prog="zswarm", description="Multi-agent distributed estimation over Zenoh: one process per agent.")
    p.add_argument("--version", action="version", version=f"zswarm {_version()}", help="print zswarm's version and exit")
    sub = p.add_subparsers(dest="cmd", required=True, metavar="COMMAND")

    r = sub.add_parser(
        "run",
        help="run a scenario over real processes (router, world, agents, recorder)",
        description="Opens a Zenoh router in this process on a free localhost port and starts the recorder, the world and "
        "one process per agent; "
        "the world starts the run once every process is up, and the recorder writes RESULTS/recording.mcap.  At the end "
        "the report is written (summary.json, errors.csv, plots) and its table printed.",
    )
    _common_run_args(r)
    r.add_argument("--time-scale", type=procutil.positive_float, default=1.0, help="world seconds per wall second (default 1)")
    r.add_argument("--quiet", action="store_true", help="no progress output")
    r.add_argument("--no-plots", action="store_true", help="skip the PNG plots (as zswarm sim --no-plots; zswarm report RESULTS draws them later)")
    _live_arg(r, "serve the recording's channels on a Foxglove WebSocket server while the run goes on (open it in Foxglove or Lichtblick)")
    _rerun_arg(r, "stream the run to a Rerun viewer while it goes on (the recorder does it, off the agents' loops)")
    r.add_argument(
        "--secure",
        nargs="?",
        const="",
        default=None,
        metavar="DIR",
        help="mutual TLS and access control: certificates made for the run in DIR (default: the results folder's secure/); each process may publish only its own keys",
    )

    s = sub.add_parser(
        "sim",
        help="run the same world and agents in one process on a virtual clock",
        description="Hosts the same World and AgentNode objects as zswarm run in one process, stepping each on its own "
        "clock in world time as fast as the machine allows (link delays, jitter, loss and faults emulated as in a run); "
        "writes the same results folder.",
    )
    _common_run_args(s)
    s.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    s.add_argument("--lean", action="store_true", help="leave sensor and edge messages out of the recording (§3.2: 61 %% of the size)")
    s.add_argument("--quiet", action="store_true", help="print nothing but errors")
    s.add_argument("--no-recording", action="store_true", help="write no recording.mcap (the report is made from memory; zswarm sweep uses this)")
    _rerun_arg(s, "stream the run to a Rerun viewer as it is simulated")

    sw = sub.add_parser(
        "sweep",
        help="run a scenario over a grid of field values (repeated with different seeds) and plot the results",
        description="Runs every combination of the --vary values, --repeats times each (seed, seed+1, ...), "
        "on the batched engine, on sim in --jobs worker processes (each run its own zswarm sim process with "
        "--keep-recordings), or each its own zswarm run process; writes sweep.csv (a row per run) and plots.  Interrupted and "
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
    sw.add_argument(
        "--engine",
        choices=("auto", "batched", "sim", "run"),
        default="auto",
        help="batched: the runs that share a schedule (differing in seeds, noise variances, starts) stepped together on arrays, the same rows as sim; "
        "sim: each run a zswarm sim; run: real processes over Zenoh; auto (default): batched where it applies (the §3, §4.5 and §5.6 schemes on one clock, no faults but link cuts; see the README for the links), else sim, saying why",
    )
    sw.add_argument("--chunk", type=procutil.positive_int, default=None, help="runs stepped together per task of the batched engine (default: shared out among the jobs, at most 1000)")
    sw.add_argument("--jobs", type=procutil.positive_int, default=None, help="runs (or batches) at a time (default: the number of cores for sim and batched, 1 for run)")
    sw.add_argument("--out", type=Path, default=None, help="sweep folder (default sweeps/<scenario>-<timestamp>/); the same folder resumes")
    sw.add_argument("--cluster", default=None, metavar="ADDRESS", help="run the runs (engines auto, batched, sim) on the Dask distributed cluster whose scheduler is at ADDRESS (tcp://host:port)")
    sw.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE", dest="overrides", help="a fixed override for every run (repeatable)")
    sw.add_argument("--duration", type=procutil.positive_float, default=None, help="world seconds per run (default: the scenario's)")
    sw.add_argument("--seed", type=int, default=None, help="seed of repeat 0 (default: the scenario's); repeat r uses seed + r")
    sw.add_argument(
        "--thresholds",
        default=None,
        metavar="ATT,POS",
        help="convergence thresholds on the mean attitude error |R̃|_I and position error in m (default 0.01,0.1)",
    )
    sw.add_argument("--timeout", type=procutil.positive_float, default=None, help="seconds before a run (on sim or run) is stopped and recorded as failed: a run process killed, or on sim the worker processes, whose other runs start again (not the batched engine's runs, nor a cluster's)")
    sw.add_argument("--keep-recordings", action="store_true", help="keep each run's recording.mcap (deleted by default; summaries and CSVs stay)")
    sw.add_argument("--no-plots", action="store_true", help="write no figures (sweep.csv only; figures an earlier run left in --out are removed, as they would not show this sweep.csv)")

    b = sub.add_parser(
        "basin",
        help="Monte-Carlo check of a scheme's global claim: N random starts, on the batched engine or sim",
        description="Draws N initial conditions (draw 0: the scenario's own start; then what its experiment family "
        "randomises uniformly on SO(3): every R_i(0) for the Chapter 5 laws, Q_i(0) too for the velocity-free one, every "
        "R̂_i(0) for the §4 observers), runs them on the batched engine (or sim) and reports the fraction whose family "
        "measure (max_k |R̄_k|_I for those) stays below the threshold from some time on, and the settle times.  Writes "
        "basin.csv, basin.json, basin.png (not with --no-plots); the same command with the same --out resumes.",
    )
    b.add_argument("topology", help="scenario TOML file (of an experiment family with a basin check: a Chapter 5 law, a §4 observer)")
    b.add_argument("--draws", type=procutil.positive_int, default=101, help="draws including the scenario's own start (default 101)")
    b.add_argument("--seed", type=int, default=1, help="seed of the draws (default 1)")
    b.add_argument("--duration", type=procutil.positive_float, default=None, help="horizon, world seconds (default: the scenario's)")
    b.add_argument("--threshold", type=procutil.positive_float, default=0.01, help="the family's measure below which a draw has settled (\"synchronized\": max_k |R̄_k|_I; default 0.01)")
    b.add_argument("--jobs", type=procutil.positive_int, default=None, help="draws at a time (default: the number of cores)")
    b.add_argument(
        "--near",
        type=procutil.positive_float,
        default=None,
        metavar="EPS",
        help="instead of uniform draws, turn the scenario's own start by EPS rad about a uniform axis "
        "(shows an almost-global law's slow escape from the undesired set)",
    )
    b.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        dest="overrides",
        help="override a scenario field for every draw (repeatable), e.g. links.commands.delay_ms=2; with random links (loss, bursts, jitter) "
        "draw d runs with seed scenario.seed + d, its own losses and delays",
    )
    b.add_argument("--out", type=Path, default=None, help="folder (default basins/<scenario>-<timestamp>/); the same folder resumes")
    b.add_argument(
        "--engine",
        choices=("auto", "batched", "sim"),
        default="auto",
        help="batched: the draws stepped together on arrays (the same algorithm modules; draw by draw the same numbers as sim); "
        "sim: each draw on zswarm sim; auto (default): batched where the scenario allows it (one clock without jitter, drift or offset on the sensor grid; every link model and link cut, each draw its own losses and delays as sim draws them; no faults but link cuts; sensor jitter, loss or cuts on a prescribed truth go to sim, where they run as fast), else sim, saying why",
    )
    b.add_argument("--chunk", type=procutil.positive_int, default=None, help="draws stepped together per task of the batched engine (default: the draws shared out among the jobs, at most 1000)")
    b.add_argument("--cluster", default=None, metavar="ADDRESS", help="run the draws on the Dask distributed cluster whose scheduler is at ADDRESS (tcp://host:port) instead of local processes")
    b.add_argument("--no-plots", action="store_true", help="write no basin.png (basin.csv and basin.json only; a basin.png an earlier run left in --out is removed)")

    bc = sub.add_parser(
        "basin-compare",
        help="compare basin folders: a Markdown table and one figure",
        description="Reads the basin.csv and basin_def.json of each folder written by zswarm basin and prints a Markdown "
        "table (fraction synchronized with its 95 % interval, settle-time quantiles, jumps); writes one figure of the "
        "settle-time distributions, and of settle time against ε for folders made with --near.",
    )
    bc.add_argument("dirs", nargs="+", type=Path, help="folders written by zswarm basin")
    bc.add_argument("--out", type=Path, default=Path("basin-compare.png"), help="the figure (default basin-compare.png)")

    ro = sub.add_parser(
        "router",
        help="run a Zenoh router for processes started by hand",
        description="Runs a Zenoh router on the --listen endpoints until Ctrl-C (or, with --exit-after-run, until the "
        "recorder of that run has come and gone), for a world, agents and a recorder started by hand or by compose.  "
        "With --secure DIR: mutual TLS on tls/ endpoints, each process allowed to put only its own keys.",
    )
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
    co.add_argument("--build-context", type=Path, default=None, help="folder with zswarm's Dockerfile to build the image from (default: this zswarm's source checkout, if it is one)")
    co.add_argument("--no-build", action="store_true", help="no build section: the image must exist (docker build -t IMAGE .)")
    co.add_argument("--base", default=None, help="base image build argument (the Dockerfile's default: python:3.11-slim)")
    co.add_argument("--network", choices=("flat", "routed"), default="flat", help="flat: one network; routed: agents behind a second router on their own network")
    co.add_argument("--run-id", default="compose", help="run id (default compose)")
    co.add_argument("--results", default="${ZSWARM_RESULTS:-./runs}", help="host folder for the results (default ${ZSWARM_RESULTS:-./runs})")
    co.add_argument("--duration", type=procutil.positive_float, default=None, help="world seconds (default: the scenario's)")
    co.add_argument("--time-scale", type=procutil.positive_float, default=1.0, help="world seconds per wall second (default 1)")
    co.add_argument("--seed", type=int, default=None, help="random seed (default: the scenario's)")
    _live_arg(co, "serve the run on a Foxglove WebSocket server in the recorder's container, published on the host at HOST:PORT")
    co.add_argument(
        "--set", action="append", default=[], metavar="FIELD=VALUE", dest="overrides", help="override a scenario field; the scenario as run is written beside the compose file"
    )

    rec = sub.add_parser(
        "record",
        help="record a run (started by hand) into a results folder",
        description="Subscribes to every key of the run (--run-id) and writes the payloads as they come to "
        "RESULTS/recording.raw.mcap; when the world stops the run, transcodes it into recording.mcap and writes the "
        "report (unless --no-report).",
    )
    rec.add_argument("topology", help="scenario TOML file")
    rec.add_argument("--out", type=Path, default=None, help="results folder (default runs/<scenario>-<timestamp>/)")
    rec.add_argument("--no-report", action="store_true", help="do not write summary/plots at the end (the recording stays as recording.raw.mcap, payloads as they came, until zswarm report transcodes it)")
    _live_arg(rec, "also serve the channels on a Foxglove WebSocket server")
    _rerun_arg(rec, "also stream the run to a Rerun viewer")
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

    vw = sub.add_parser(
        "view",
        help="open a results folder in Rerun: bodies true and estimated in 3-D, errors, hybrid variables, jumps, links, commands, faults",
        description="Reads RESULTS/recording.mcap into a Rerun recording (timelines world_time and log_time): every agent's "
        "true and estimated frame, the graph's edges, the per-agent and per-edge errors, ξ and ζ and their jumps, the link "
        "counters, the commands and the scenario's fault windows.  Opens it in Rerun's viewer; --save writes the .rrd file "
        "instead; --web serves Rerun's web viewer (no browser is opened).",
    )
    vw.add_argument("run_dir", type=Path, help="results folder holding recording.mcap (and scenario.toml)")
    vw.add_argument("--save", type=Path, default=None, metavar="FILE.rrd", help="write the Rerun recording to FILE.rrd and exit")
    vw.add_argument("--web", nargs="?", const="127.0.0.1:9090", default=None, metavar="HOST:PORT", help="serve the web viewer on HOST:PORT (default 127.0.0.1:9090) until Ctrl-C")

    rep = sub.add_parser(
        "report",
        help="(re)compute summary.json, errors.csv and plots of a results folder",
        description="Reads RESULTS/recording.mcap (or transcodes recording.raw.mcap first) with RESULTS/scenario.toml, "
        "writes summary.json, errors.csv, the experiment family's files and plots, and prints the table.  Recordings of "
        "earlier wire versions are read too.",
    )
    rep.add_argument("results", type=Path, help="results folder holding recording.mcap and scenario.toml")

    inf = sub.add_parser(
        "info",
        help="what a results folder or a recording holds: scenario, engine, status, each channel's count, rate and span, the links",
        description="Prints what RESULTS/summary.json says of the run (scenario, engine, duration, seed, completed or why "
        "not, whether it kept up, what the recording lacks) and, from the MCAP recording, every channel's message count, "
        "rate and first and last log time (s from the recording's first message), then each link's counters.  PATH may "
        "also be a recording file (.mcap) alone.  Nothing is recomputed (zswarm report does that).",
    )
    inf.add_argument("path", type=Path, help="a results folder, or a recording (.mcap)")
    inf.add_argument("--json", action="store_true", help="print the same as one JSON object")

    rns = sub.add_parser(
        "runs",
        help="list the results folders under a directory: when, engine, duration, status, scenario",
        description="One line per results folder directly under DIR (default runs/, where run and sim write), oldest "
        "first: when its summary was written, run or sweep or basin, the engine, the duration, its status (completed, "
        "NOT COMPLETED, interrupted, no summary yet) and the scenario.",
    )
    rns.add_argument("dir", type=Path, nargs="?", default=Path("runs"), help="the directory to list (default runs/)")
    rns.add_argument("--json", action="store_true", help="print the same as a JSON list")

    ec = sub.add_parser(
        "echo",
        help="print the messages of a live run's key, decoded, one JSON line each",
        description="Joins a live run's Zenoh network (a zswarm run through --results DIR, or processes started by hand "
        "through --connect and --run-id) and prints each message on STREAM as a JSON line {\"key\", \"message\"}, "
        "decoded and checked as every receiver checks it; a payload that does not decode is named on stderr and dropped.  "
        "Under --secure it uses the run's recorder certificate.",
    )
    probe_args(ec)
    ec.add_argument("--count", type=int, default=None, metavar="N", help="stop after N messages")

    hz = sub.add_parser(
        "hz",
        help="the rate and gaps of each key of a live run, every second",
        description="Joins a live run's Zenoh network as echo does and prints, every --window seconds, each key's message "
        "count, rate (1 / mean gap) and mean, shortest and longest gap between arrivals, and the payloads that did not decode.",
    )
    probe_args(hz)
    hz.add_argument("--window", type=procutil.positive_float, default=1.0, metavar="S", help="seconds per report (default 1)")
    hz.add_argument("--json", action="store_true", help="one JSON object per window")

    g = sub.add_parser(
        "generate",
        help="write an N-agent scenario of an experiment family's recipe (graph, positions, motions, initial errors from a seed)",
        description="Writes a scenario that loads by construction: the recipe's algorithm, gains and world as in its paper's "
        "shipped scenario; the graph, positions, motions and initial estimation errors drawn from --seed.  The recipes "
        "are the experiment families' (zswarm.families.contract.Recipe), a user's registered families' too.",
    )
    g.add_argument("family", nargs="?", metavar="RECIPE", help="the recipe (--list shows them)")
    g.add_argument("-n", "--agents", type=int, default=None, help="number of agents")
    g.add_argument("--seed", type=int, default=1, help="seed of the draw, and the scenario's seed (default 1)")
    g.add_argument("--graph", default=None, help="graph shape (default: the recipe's first; --list shows them)")
    g.add_argument("--in-degree", type=int, default=3, help="recipes with leaders and followers: in-neighbours per follower (default 3)")
    g.add_argument("--max-angle", type=float, default=0.9, help="largest initial attitude error, a fraction of pi (default 0.9)")
    g.add_argument("--spread", type=float, default=3.0, help="RMS initial position error, m (default 3)")
    g.add_argument("--duration", type=procutil.positive_float, default=None, help="the scenario's duration, s (default: the family's)")
    g.add_argument("--name", default=None, help="scenario name (default gen-<family>-<n>-s<seed>)")
    g.add_argument("-o", "--output", type=Path, default=None, help="file to write (default: standard output)")
    g.add_argument("--list", action="store_true", help="list the recipes and their graph shapes")

    # The experiment families' own commands (zswarm.families.contract.Command), e.g. design-hybrid.
    for c in family.commands().values():
        c.arguments(sub.add_parser(c.name, help=c.help, description=c.description))
    _explain(sub)
    return p


def _lazy(module: str, name: str) -> Any:
    """The run function ``name`` of the module ``module``, imported when its command runs."""

    def run(args: argparse.Namespace) -> int:
        import importlib

        return int(getattr(importlib.import_module(module), name)(args))

    return run


def main(argv: list[str] | None = None) -> int:
    procutil.die_with_parent()  # as a sweep's child: ends with the sweep
    args = build_parser().parse_args(argv)
    cmds = {
        "run": cmd_run,
        "sim": _lazy("zswarm.engines.sim", "command"),
        "sweep": _lazy("zswarm.studies.sweep_command", "command"),
        "basin": _lazy("zswarm.studies.basin", "command"),
        "basin-compare": _lazy("zswarm.studies.basin_compare", "compare_command"),
        "router": cmd_router,
        "compose": _lazy("zswarm.engines.compose", "command"),
        "record": _lazy("zswarm.engines.recorder", "command"),
        "replay": _lazy("zswarm.engines.replay", "command"),
        "view": _lazy("zswarm.recording.rerun_view", "command"),
        "report": _lazy("zswarm.results.command", "report"),
        "generate": _lazy("zswarm.studies.generate", "command"),
        "certs": cmd_certs,
        "info": cmd_info,
        "runs": cmd_runs,
        "echo": _lazy("zswarm.transport.probe", "echo"),
        "hz": _lazy("zswarm.transport.probe", "hz"),
    }
    run = cmds.get(args.cmd) or family.commands()[args.cmd].run
    try:
        return run(args)
    except KeyboardInterrupt:  # Ctrl-C where the command does not stop on it by itself (sim writes what it simulated first)
        print(f"zswarm {args.cmd}: interrupted", file=sys.stderr)
        return procutil.interrupted_code()  # 130, or 143 for a SIGTERM the command caught
    except BrokenPipeError:  # its output piped into `head`, which has read enough: not a failure
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # the interpreter's final flush goes nowhere
        return 0
    except Exception as exc:
        problem = procutil.write_problem(exc)
        if problem is None:
            raise
        print(f"zswarm {args.cmd}: {one_line(problem)}", file=sys.stderr)
        return 1


def cmd_run(args: argparse.Namespace) -> int:
    from zswarm.engines import cost, launch

    sc = procutil.load_args(args)
    cost.refuse_if_too_long(sc, args.topology, args.duration, args.allow_long)  # before anything is printed or started
    procutil.warn_notes(sc)
    procutil.check_faults_in_run(sc, sc.duration if args.duration is None else args.duration, args.duration is not None)
    secure = None if args.secure is None else Path(args.secure) if args.secure else True
    return launch.run(args.topology, sc, args.out, args.duration, args.time_scale, args.seed, quiet=args.quiet, live=args.live, secure=secure, rerun=args.rerun, plots=not args.no_plots)


def cmd_router(args: argparse.Namespace) -> int:
    from zswarm.transport import secure as sec
    from zswarm.transport.bus import ZenohBus

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
    from zswarm.transport import secure as sec

    sc = procutil.load_or_exit(args.topology)
    names = sec.certificate_names(sc.ids)
    sec.make_certs(args.dir, names, hosts=args.host)
    print(f"{args.dir}: ca.pem, {sec.ROUTER}.pem, " + ", ".join(f"{n}.pem" for n in names) + " (and their .key)")
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    from zswarm.results import catalog

    try:
        d = catalog.info(args.path)
    except catalog.NotOurs as exc:
        procutil.fail_usage(str(exc))
    print(json.dumps(d, indent=1) if args.json else catalog.format_info(d))
    return 0


def cmd_runs(args: argparse.Namespace) -> int:
    from zswarm.results import catalog

    if not args.dir.is_dir():
        procutil.fail_usage(f"{args.dir}: no such directory")
    rows = catalog.runs(args.dir)
    print(json.dumps(rows, indent=1) if args.json else catalog.format_runs(rows) if rows else f"{args.dir}: no results folders")
    return 0


if __name__ == "__main__":
    sys.exit(main())
