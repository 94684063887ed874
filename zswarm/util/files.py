"""Results files written whole or not at all.

A full disk or a dying process must not leave a 0-byte ``summary.json`` or half a CSV that
reads as a result: each file is written beside its place (``NAME.part``) and renamed over it
once complete (a rename within a folder is atomic); on any failure the part is removed and
the error goes on to the caller, which names the path and the problem in one line
(``zswarm.transport.procutil.write_problem``, printed by ``zswarm.cli.main``).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any


@contextmanager
def whole(path: Path) -> Iterator[Path]:
    """Yield the temporary path to write; on success it replaces ``path``."""
    tmp = path.with_name(path.name + ".part")
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text(path: Path, text: str) -> None:
    """``path.write_text(text)``, whole or not at all (and on disk: fsync before the rename)."""
    with whole(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())


def write_bytes(path: Path, data: bytes) -> None:
    """``path.write_bytes(data)``, whole or not at all."""
    with whole(path) as tmp, open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def save_png(fig: object, path: Path) -> None:
    """A matplotlib figure as a PNG at ``path``, whole or not at all."""
    with whole(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")  # type: ignore[attr-defined]


def read_json_object(path: Path) -> dict[str, Any]:
    """The JSON object in ``path``; ValueError naming the problem when the file holds none
    (not UTF-8, not JSON, or JSON of another shape)."""
    import json

    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        raise ValueError(str(exc)) from None
    if not isinstance(obj, dict):
        raise ValueError("not a JSON object")
    return obj


class RecordingError(Exception):
    """A recording that cannot be read or written as a whole (message names the file)."""


def hold(folder: Path, what: str, stop: Callable[[], bool]) -> int | None:
    """An exclusive lock on ``folder`` (``folder/.lock``, flock) for a command that appends to
    its results, as an open descriptor to keep (and to hand to the children that write into
    the folder, so the lock outlives a ``kill -9`` of the command until they have gone too).
    Waits while another holds it, saying so once; None when ``stop`` came first."""
    import fcntl
    import sys
    import time

    fd = os.open(folder / ".lock", os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    told = False
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return fd
        except BlockingIOError:
            if not told:
                print(f"{folder}: in use by another {what}, or by the runs of one that was killed; waiting for them to end", file=sys.stderr, flush=True)
                told = True
            if stop():
                os.close(fd)
                return None
            time.sleep(0.1)
