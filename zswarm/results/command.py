"""``zswarm report``, the command (zswarm.cli dispatches here)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from zswarm.transport import procutil
from zswarm.util import files


def report(args: argparse.Namespace) -> int:
    """``zswarm report DIR``: the report made again from the folder's recording; exit 0 when the
    run completed, 1 when not (as ``zswarm run`` exits), 2 for a file that is not a recording."""
    from zswarm import results
    from zswarm.recording.mcap_io import decode, ensure_recording, read
    from zswarm.recording.mcap_read import NotMcap
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
    engine = prev.get("engine", "run")
    duration = float(prev.get("duration_s", start["duration"] if start else sc.duration))
    scale = float(prev.get("time_scale", start["time_scale"] if start else 1.0))
    seed = int(prev.get("seed", start["seed"] if start else sc.seed))
    # What only the launcher knew (its children's exit codes, an interruption, their CPU) is
    # kept: the report's verdict is then the run's (exit 1 where `zswarm run` exited 1).
    kept = {k: prev[k] for k in ("exit_codes", "interrupted", "cpu", "fault_actions") if k in prev}
    codes = kept.get("exit_codes") if isinstance(kept.get("exit_codes"), dict) else None
    summary = results.make_report(
        args.results, sc, engine, duration, scale, seed, exit_codes=codes, not_recorded=prev.get("recording", {}).get("not_recorded", ()), keep=kept
    )
    print(results.table(summary))
    for line in summary.get("recording", {}).get("damaged", []):
        print(line, file=sys.stderr)
    return 0 if summary["completed"] else 1
