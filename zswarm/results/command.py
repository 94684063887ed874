"""``zswarm report``, the command (zswarm.cli dispatches here)."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import Any

from zswarm.transport import procutil
from zswarm.util import files


def report(args: argparse.Namespace) -> int:
    """``zswarm report DIR``: the report made again from the folder's recording; exit 0 when the
    run completed, 1 when not (as ``zswarm run`` exits), 2 for a file that is not a recording."""
    from zswarm import results
    from zswarm.recording.mcap_io import decode, ensure_recording, read
    from zswarm.recording.mcap_read import NotMcap
    from zswarm.report.decoded import NoTruth
    from zswarm.transport import wire

    sc = procutil.load_or_exit(str(args.results / "scenario.toml"))
    try:
        rec_path = ensure_recording(args.results, sc)
        if not rec_path.exists():
            procutil.fail_usage(f"{rec_path}: no recording there")
        start = None
        for topic, payload, _t in read(rec_path, []):  # its losses are the report's to tell
            if topic == "ctl/start":
                try:
                    start = decode(payload, "start")
                except wire.MessageError:
                    continue
                break
    except NotMcap as exc:
        procutil.fail_usage(str(exc))
    prev: dict[str, Any] = {}
    if (args.results / "summary.json").exists():
        try:
            prev = files.read_json_object(args.results / "summary.json")
        except ValueError as exc:
            print(f"warning: {args.results / 'summary.json'}: not a summary ({exc}); made again from the recording", file=sys.stderr)
    known, remade = run_parameters(args.results, prev, start)
    engine = known["engine"]
    duration, scale, seed = known["duration_s"], known["time_scale"], known["seed"]
    # What only the launcher knew (its children's exit codes, an interruption, their CPU) is
    # kept: the report's verdict is then the run's (exit 1 where `zswarm run` exited 1).
    kept = {k: prev[k] for k in ("exit_codes", "interrupted", "cpu", "fault_actions") if k in prev}
    codes = kept.get("exit_codes") if isinstance(kept.get("exit_codes"), dict) else None
    remade = {**(prev.get("remade") if isinstance(prev.get("remade"), dict) else {}), **remade}
    if remade:  # where each parameter of the run was found (summary.json lost or not one)
        kept["remade"] = remade
    try:
        summary = results.make_report(
            args.results, sc, engine, duration, scale, seed, exit_codes=codes, not_recorded=prev.get("recording", {}).get("not_recorded", ()), keep=kept
        )
    except NoTruth as exc:  # no summary to make: the run's verdict is said, in one line
        lost: list = []
        list(read(rec_path, lost))
        print(f"{sc.name}: NOT COMPLETED: {exc}" + "".join(f"; {x.text()}" for x in lost))
        return 1
    print(results.table(summary))
    for line in summary.get("recording", {}).get("damaged", []):
        print(line, file=sys.stderr)
    return 0 if summary["completed"] else 1


# The world's log line of its start (world/__main__.py): what a run's launcher gave it.
_WORLD_START = re.compile(r"start: epoch [-0-9.e+]+, time scale ([-0-9.e+]+), duration ([-0-9.e+]+) s")


def run_parameters(folder: Path, prev: dict[str, Any], start: Any) -> tuple[dict[str, Any], dict[str, str]]:
    """The engine, duration, time scale and seed the folder's run was made with, each from the
    first source that knows it: the earlier summary.json, the recording's start message, the
    recording's metadata (written before its first chunk: ``zswarm sim`` puts all four there,
    the recorder its engine), the launcher's files (processes.json, which only ``zswarm run``
    writes; the world's log line of its start).  What none of them tells is "unknown" (the
    engine) or None, never the scenario's or a default: a lost summary of a ``sim`` folder read
    ``engine=run``, and one with its start message damaged the scenario's 40 s for the run's 3 s.
    Returns the values and, for those not from summary.json, where each was found."""
    from zswarm.recording.mcap_read import metadata

    rec = folder / "recording.mcap"
    meta = metadata(rec) if rec.exists() else {}
    world_log = folder / "logs" / "world.log"
    m = _WORLD_START.search(world_log.read_text(errors="replace")) if world_log.exists() else None
    logged = {"time_scale": m.group(1), "duration_s": m.group(2)} if m else {}
    found: dict[str, Any] = {}
    where: dict[str, str] = {}
    kinds = {"engine": str, "duration_s": float, "time_scale": float, "seed": int}
    sources: dict[str, list[tuple[str, Any]]] = {
        "engine": [("recording metadata", meta.get("engine")), ("processes.json (zswarm run's)", "run" if (folder / "processes.json").exists() else None)],
        "duration_s": [("recording ctl/start", start["duration"] if start else None), ("recording metadata", meta.get("duration")), ("logs/world.log", logged.get("duration_s"))],
        "time_scale": [("recording ctl/start", start["time_scale"] if start else None), ("recording metadata", meta.get("time_scale")), ("logs/world.log", logged.get("time_scale"))],
        "seed": [("recording ctl/start", start["seed"] if start else None), ("recording metadata", meta.get("seed"))],
    }
    for key, kind in kinds.items():
        for source, value in [("summary.json", prev.get(key)), *sources[key]]:
            try:
                found[key] = kind(value) if value is not None else None
            except (TypeError, ValueError):
                found[key] = None  # a foreign or damaged entry: not evidence
            if found[key] is not None and (key != "engine" or found[key] != "unknown"):
                if source != "summary.json":
                    where[key] = source
                break
        else:
            found[key] = "unknown" if key == "engine" else None
            where[key] = "unknown: " + ", ".join(s for s, _ in sources[key]) + " do not say"
    return found, where
