"""One progress style for every long command (sim, sweep, basin): on a terminal a single line
redrawn in place, ``[#########---------] 12/40 runs, 1 failed, 0:05 elapsed, ~0:10 left``; in a
log or a pipe, plain lines (each message, and the bar's text at most every ``every_s`` seconds
and at the end), so a log holds no carriage returns."""

from __future__ import annotations

import math
import sys
import time
from typing import Any, TextIO

WIDTH = 30  # characters of the bar
REDRAW_S = 0.1  # a terminal's line at most this often


def hms(s: float) -> str:
    """``m:ss`` (``?`` when unknown)."""
    if not math.isfinite(s):
        return "?"
    n = round(s)
    return f"{n // 60}:{n % 60:02d}"


class Progress:
    """Progress toward ``total`` (in ``unit``: "runs", "draws", "s of world time"), of which
    ``already`` were done before this command (a resume): the time left is estimated from this
    command's own pace."""

    def __init__(self, total: float, unit: str, already: float = 0, stream: TextIO | Any = None, every_s: float = 30.0) -> None:
        self.total, self.unit, self.done, self.start = total, unit, already, already
        self.stream = sys.stderr if stream is None else stream
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.every_s = every_s
        self.t0 = time.monotonic()
        self.extra = ""
        self._drawn = 0.0
        self._plain = self.t0
        self._on_line = False

    def text(self) -> str:
        el = time.monotonic() - self.t0
        new = self.done - self.start
        eta = el / new * (self.total - self.done) if new > 0 else math.nan
        fill = int(WIDTH * min(1.0, self.done / self.total)) if self.total else WIDTH
        count = f"{self.done:g}/{self.total:g}" if isinstance(self.done, int) or float(self.done).is_integer() else f"{self.done:.1f}/{self.total:g}"
        return f"[{'#' * fill}{'-' * (WIDTH - fill)}] {count} {self.unit}{', ' + self.extra if self.extra else ''}, {hms(el)} elapsed" + (f", ~{hms(eta)} left" if new > 0 and self.done < self.total else "")

    def update(self, done: float, extra: str | None = None, note: str | None = None) -> None:
        """Now ``done`` of the total (``extra``: more to say on the line, e.g. "1 failed");
        ``note``: a message of its own (a finished run), printed as a line either way."""
        self.done = done
        if extra is not None:
            self.extra = extra
        now = time.monotonic()
        if note is not None:
            self.line(note)
        if self.tty:
            if now - self._drawn >= REDRAW_S or done >= self.total:
                self._draw()
        elif note is None and (now - self._plain >= self.every_s or done >= self.total):
            self._plain = now
            print(self.text(), file=self.stream, flush=True)

    def line(self, text: str) -> None:
        """A message on a line of its own (on a terminal above the bar, which is redrawn)."""
        if self.tty and self._on_line:
            print("\r\x1b[K" + text, file=self.stream, flush=True)
            self._draw()
        else:
            print(text if self.tty else f"{text}  [{self.text()}]", file=self.stream, flush=True)

    def _draw(self) -> None:
        self._drawn = time.monotonic()
        self._on_line = True
        print("\r\x1b[K" + self.text(), end="", file=self.stream, flush=True)

    def close(self) -> None:
        """End the terminal's line (the next output starts on its own)."""
        if self.tty and self._on_line:
            print(file=self.stream, flush=True)
            self._on_line = False
