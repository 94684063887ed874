"""Append-only CSV results (``sweep.csv``, ``basin.csv``) whose every row is whole or known torn.

A sweep or a basin study appends a row as each run ends (written, flushed, fsynced) and a
resume runs what has no row yet.  A ``kill -9`` or a power cut mid-write leaves a prefix of
the last row; read as CSV, that prefix is a row with its first columns (``status`` "ok" among
them) and the rest missing or cut (``edge_dropped`` 138 where the run had 1382) — taken as
done, it would never run again and its numbers would go into the plots.

A row here is whole when its line ends with the newline the writer put last and it has
exactly the header's number of cells; cells never hold a newline (:func:`cell`).  Anything
else (a cut line, a line of NULs or garbage a broken disk left, a line with too few or too
many cells) is torn: it is left out of what is read, and :func:`open_append` rewrites the
file without it (whole or not at all, :mod:`zswarm.util.files`) before appending, so its run
is done again and the file holds each finished run once.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from zswarm.util import files


@dataclass
class Table:
    """What a results CSV holds: its header (None: no whole header line), its whole rows (in
    file order, each with its line number), and the line numbers of the torn ones."""

    header: list[str] | None
    rows: list[dict[str, str]] = field(default_factory=list)
    lines: list[int] = field(default_factory=list)
    torn: list[int] = field(default_factory=list)
    whole: bytes = b""  # the header and the whole rows, byte for byte as written


def _cells(line: bytes) -> list[str] | None:
    try:
        got = list(csv.reader(io.StringIO(line.decode("utf-8"), newline="")))
    except (UnicodeDecodeError, csv.Error):
        return None
    return got[0] if len(got) == 1 else None


def read(path: Path) -> Table:
    """The table at ``path`` (an absent file: no header, no rows)."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return Table(None)
    lines = data.split(b"\n")
    # lines[-1] follows the last newline: empty when the file ends whole, else a cut line.
    ended, tail = lines[:-1], lines[-1]
    t = Table(None)
    if not ended or _cells(ended[0]) is None:
        t.torn = list(range(1, len(lines) + 1)) if data else []
        return t
    t.header = _cells(ended[0])
    keep = [ended[0]]
    n = len(t.header or [])
    for i, line in enumerate(ended[1:], start=2):
        if not line.strip():
            continue
        cells = _cells(line)
        if cells is None or len(cells) != n:
            t.torn.append(i)
            continue
        t.rows.append(dict(zip(t.header or [], cells, strict=True)))
        t.lines.append(i)
        keep.append(line)
    if tail:
        t.torn.append(len(lines))
    t.whole = b"\n".join(keep) + b"\n"
    return t


def open_append(path: Path, header: Sequence[str]) -> tuple[Any, csv.DictWriter[str], Table]:
    """``path`` open to append rows, and what it held.  A new file (or one without a whole
    header line) gets ``header``; an existing one keeps its own (a folder begun by an older
    zswarm) and loses its torn lines first, so the runs they were cut from run again."""
    t = read(path)
    if t.header is None:
        t = Table(list(header), torn=t.torn)
        files.write_text(path, _line(list(header)))
    elif t.torn:
        files.write_bytes(path, t.whole)
    f = open(path, "a", newline="", encoding="utf-8")  # noqa: SIM115 - the caller closes it
    return f, csv.DictWriter(f, fieldnames=t.header or list(header), extrasaction="ignore"), t


def append(f: Any, w: csv.DictWriter[str], *rows: dict[str, Any]) -> None:
    """Rows, on disk before this returns (a run whose row is here is never run again); one
    fsync for them all (a chunk of a thousand draws: not a thousand fsyncs)."""
    for row in rows:
        w.writerow({k: cell(v) for k, v in row.items()})
    f.flush()
    os.fsync(f.fileno())


def cell(v: Any) -> Any:
    """A CSV cell as the results files write it: floats to 6 significant digits, None empty,
    text on one line (a row is one line: see the module's docstring)."""
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, str):
        return " ".join(v.splitlines()) if ("\n" in v or "\r" in v) else v
    return v


def _line(cells: list[str]) -> str:
    buf = io.StringIO(newline="")
    csv.writer(buf).writerow(cells)
    return buf.getvalue()


def torn_text(path: Path, torn: Sequence[int]) -> str:
    """One line naming what was dropped, e.g. ``sweep.csv: line 6: a torn row (a write cut
    short); its run is done again``."""
    where = f"line {torn[0]}" if len(torn) == 1 else f"lines {', '.join(map(str, torn[:5]))}{' ...' if len(torn) > 5 else ''}"
    what = "a torn row (a write cut short)" if len(torn) == 1 else f"{len(torn)} torn rows (writes cut short)"
    return f"{path}: {where}: {what} dropped; its run is done again" if len(torn) == 1 else f"{path}: {where}: {what} dropped; their runs are done again"
