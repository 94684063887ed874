"""What is in a results folder or a recording, without recomputing anything: ``zswarm info``
(the ``ros2 bag info`` of zswarm) and ``zswarm runs`` (the results folders under a directory).

:func:`info` reads ``summary.json`` as the report wrote it (scenario, engine, duration, whether
the run completed and why not, whether it kept up, the links' counters) and scans the MCAP
recording's messages for each channel's count, rate and span (log times: when the recorder
took each message).  A recording file alone gives its own part.  Nothing is decoded beyond
the MCAP records, so a 40 s run of 8 agents (240 000 messages) takes about a second.
"""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path
from typing import Any

from zswarm.transport import keys

RECORDINGS = ("recording.mcap", "recording.raw.mcap")
_WALL_CLOCK_NS = 10**17  # log times after 1973: a wall clock's, not world time


class NotOurs(ValueError):
    """A path that is neither a results folder nor an MCAP recording."""


def recording_info(path: Path) -> dict[str, Any]:
    """A recording's size, metadata, message count, span and, per channel, its count, rate
    (messages over the span between its first and last, per second) and its first and last
    log time relative to the recording's first message.  A file cut short (no summary) is
    read up to its last complete chunk and says so."""
    from mcap.records import Channel, Message, Metadata
    from mcap.stream_reader import StreamReader

    first: dict[str, int] = {}
    last: dict[str, int] = {}
    count: dict[str, int] = {}
    topics: dict[int, str] = {}
    metadata: dict[str, str] = {}
    cut_short = False
    with open(path, "rb") as f:
        try:  # one pass over the records in file order (chunks decompressed): channels, messages, metadata
            for record in StreamReader(f, record_size_limit=None).records:
                if isinstance(record, Message):
                    topic = topics.get(record.channel_id)
                    if topic is None:
                        continue  # a message before its channel: not a valid MCAP, not counted
                    t = record.log_time
                    if topic not in first:
                        first[topic] = t
                        count[topic] = 0
                    last[topic] = t
                    count[topic] += 1
                elif isinstance(record, Channel):
                    topics[record.id] = record.topic.removeprefix("/")
                elif isinstance(record, Metadata) and record.name == "zswarm":
                    metadata = dict(record.metadata)
        except Exception:  # noqa: BLE001 - a truncated or damaged tail ends what can be read
            cut_short = True
    t0 = min(first.values(), default=0)
    t1 = max(last.values(), default=0)
    channels = {}
    for topic in sorted(first, key=keys.natural):
        span = (last[topic] - first[topic]) / 1e9
        channels[topic] = {
            "count": count[topic],
            "rate_hz": (count[topic] - 1) / span if span > 0 else None,
            "first_s": (first[topic] - t0) / 1e9,
            "last_s": (last[topic] - t0) / 1e9,
        }
    return {
        "path": str(path),
        "bytes": path.stat().st_size,
        "metadata": metadata,
        "messages": sum(count.values()),
        # A real-time run's log times are the recorder's clock (Unix time); sim's are world time from 0.
        "start_utc": _utc(t0) if first and t0 > _WALL_CLOCK_NS else None,
        "span_s": (t1 - t0) / 1e9,
        "readable_to_end": not cut_short,
        "channels": channels,
    }


def _utc(t_ns: int) -> str:
    return dt.datetime.fromtimestamp(t_ns / 1e9, dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")


def _is_mcap(path: Path) -> bool:
    try:
        with open(path, "rb") as f:
            return f.read(8) == b"\x89MCAP0\r\n"
    except OSError:
        return False


def info(path: Path) -> dict[str, Any]:
    """What :func:`format_info` prints about ``path`` (a results folder or a recording), as data.
    Raises :class:`NotOurs` for anything else, OSError for what cannot be read."""
    if path.is_file():
        if not _is_mcap(path):
            raise NotOurs(f"{path}: not an MCAP recording (no MCAP magic) nor a results folder")
        return {"kind": "recording", "recording": recording_info(path)}
    if not path.is_dir():
        raise NotOurs(f"{path}: no such file or folder")
    summary_path = path / "summary.json"
    rec = next((path / r for r in RECORDINGS if (path / r).exists()), None)
    if not summary_path.exists() and rec is None and not (path / "scenario.toml").exists():
        raise NotOurs(f"{path}: not a results folder (no summary.json, scenario.toml or recording there)")
    out: dict[str, Any] = {"kind": "results", "path": str(path)}
    if summary_path.exists():
        try:
            out["summary"] = json.loads(summary_path.read_text())
        except ValueError as exc:
            out["summary_problem"] = f"{summary_path}: not JSON ({exc})"
    out["recording"] = recording_info(rec) if rec is not None else None
    return out


def _status(s: dict[str, Any]) -> str:
    if s.get("interrupted"):
        return "interrupted"
    return "completed" if s.get("completed") else "NOT COMPLETED"


def format_info(d: dict[str, Any]) -> str:
    """The lines ``zswarm info`` prints."""
    lines: list[str] = []
    if d["kind"] == "results":
        lines.append(f"results:    {d['path']}")
        s = d.get("summary")
        if s is None:
            lines.append(f"summary:    {d.get('summary_problem', 'none (the run is going on, or was killed before its report: zswarm report FOLDER)')}")
        else:
            lines.append(f"scenario:   {s.get('scenario')} ({s.get('algorithm')}, family {s.get('report_family')})")
            scale = s.get("time_scale")
            pace = "as fast as it computes" if not scale else f"at time scale {_g(scale)}"
            lines.append(f"engine:     {s.get('engine')}, {_g(s.get('duration_s'))} s of world time {pace}, seed {s.get('seed')}")
            lines.append(f"status:     {_status(s)}")
            for p in s.get("problems") or []:
                lines.append(f"  problem:  {p}")
            ov = s.get("overload") or {}
            if ov and (s.get("engine") == "run" or ov.get("overloaded")):  # sim and batched keep no real time
                worst = max((ov.get("agents_missed_pct") or {}).values(), default=0.0)
                kept = "OVERLOADED: " + "; ".join(ov.get("reasons", [])) if ov.get("overloaded") else f"kept up (worst agent missed {worst:g} % of its ticks, the world skipped {ov.get('world_skipped_pct', 0):g} % of its samples)"
                lines.append(f"timing:     {kept}")
            r = s.get("recording") or {}
            if r:
                missing = r.get("missing_total", 0)
                lines.append(f"recorded:   {r.get('recorded')} of {r.get('published')} published messages" + (f" ({missing} missing)" if missing else "") + (", cut short" if r.get("cut_short") else ""))
    rec = d.get("recording")
    if rec is None:
        lines.append("recording:  none")
    else:
        md = rec["metadata"]
        since = f"from {rec['start_utc']}" if rec["start_utc"] else "of world time"
        lines.append(f"recording:  {rec['path']} ({rec['bytes'] / 1e6:.1f} MB, {rec['messages']} messages over {rec['span_s']:.2f} s {since})")
        if md:
            lines.append("            " + ", ".join(f"{k} {md[k]}" for k in ("scenario", "engine", "run") if k in md))
        if not rec["readable_to_end"]:
            lines.append("            DAMAGED or cut short: read up to its last complete chunk")
        lines.append("")
        lines.append(f"  {'channel':<22} {'count':>8} {'rate Hz':>9} {'first s':>9} {'last s':>9}")
        for topic, c in rec["channels"].items():
            rate = f"{c['rate_hz']:.2f}" if c["rate_hz"] is not None else "-"
            lines.append(f"  {topic:<22} {c['count']:>8} {rate:>9} {c['first_s']:>9.3f} {c['last_s']:>9.3f}")
    s = d.get("summary") or {}
    if s.get("links"):
        lines.append("")
        lines.append(f"  {'link':<12} {'sent':>8} {'delivered':>10} {'dropped':>8} {'reordered':>9} {'p50 ms':>8} {'p99 ms':>8}")
        for link in sorted(s["links"], key=keys.natural):
            c = s["links"][link]
            p50, p99 = (_ms(c.get(f"latency_{q}_ms")) for q in ("p50", "p99"))
            sent = f"{'>=' if c.get('sent_is_lower_bound') else ''}{c.get('sent', 0)}"  # a killed sender's last counts were not recorded
            lines.append(f"  {link:<12} {sent:>8} {c.get('delivered', 0):>10} {c.get('dropped', 0):>8} {c.get('reordered', 0):>9} {p50:>8} {p99:>8}")
    return "\n".join(lines)


def _g(x: Any) -> str:
    """A number as ``:g`` writes it; anything else (a summary from elsewhere) as it is."""
    return format(x, "g") if isinstance(x, int | float) else str(x)


def _ms(x: Any) -> str:
    return f"{x:.2f}" if isinstance(x, int | float) else "-"


def runs(root: Path) -> list[dict[str, Any]]:
    """The results folders directly under ``root`` (each with a summary.json, a scenario.toml or
    a recording; a sweep's or a basin's folder too), oldest first: name, what, scenario,
    engine, status, duration and when its newest file was written."""
    out = []
    for p in sorted(root.iterdir()) if root.is_dir() else []:
        if not p.is_dir():
            continue
        files = {f.name for f in p.iterdir()}
        row: dict[str, Any] = {"path": str(p), "name": p.name}
        if "sweep.csv" in files or "basin.csv" in files:
            what = "sweep" if "sweep.csv" in files else "basin"
            csv = p / f"{what}.csv"
            rows = max(0, sum(1 for line in csv.read_text(errors="replace").splitlines() if line.strip()) - 1)
            row.update(what=what, scenario=_scenario_name(p), engine=None, status=f"{rows} rows", duration_s=None, written=csv.stat().st_mtime)
        elif "summary.json" in files:
            try:
                s = json.loads((p / "summary.json").read_text())
            except ValueError:
                row.update(what="run", scenario=_scenario_name(p), engine=None, status="summary.json unreadable", duration_s=None, written=(p / "summary.json").stat().st_mtime)
            else:
                row.update(what="run", scenario=s.get("scenario"), engine=s.get("engine"), status=_status(s), duration_s=s.get("duration_s"), written=(p / "summary.json").stat().st_mtime)
        elif files & {"scenario.toml", *RECORDINGS}:
            newest = max((p / f).stat().st_mtime for f in files & {"scenario.toml", *RECORDINGS})
            row.update(what="run", scenario=_scenario_name(p), engine=None, status="no summary (running, or stopped before its report)", duration_s=None, written=newest)
        else:
            continue
        out.append(row)
    out.sort(key=lambda r: r["written"])
    return out


def _scenario_name(folder: Path) -> str | None:
    """The ``[scenario] name`` of the folder's scenario.toml, read as text (a broken file: None)."""
    import tomllib

    try:
        return str(tomllib.loads((folder / "scenario.toml").read_text())["scenario"]["name"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def format_runs(rows: list[dict[str, Any]]) -> str:
    lines = [f"{'written (UTC)':<20} {'what':<5} {'engine':<7} {'duration':>8}  {'status':<16} {'scenario':<28} folder"]
    for r in rows:
        when = dt.datetime.fromtimestamp(r["written"], dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S")
        dur = f"{r['duration_s']:g} s" if isinstance(r["duration_s"], int | float) else "-"
        lines.append(f"{when:<20} {r['what']:<5} {r['engine'] or '-':<7} {dur:>8}  {r['status']:<16} {r['scenario'] or '-':<28} {r['path']}")
    return "\n".join(lines)
