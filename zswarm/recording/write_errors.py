"""What the Foxglove SDK could not write: its per-message write errors counted (not printed),
and the OS's words for an I/O error in its text (:mod:`zswarm.recording.mcap_io`'s writers
raise RecordingError with them)."""

from __future__ import annotations

import logging
from pathlib import Path


class _WriteErrors(logging.Filter):
    """The Foxglove SDK logs each message it could not write (``error logging message:
    McapError(Io(Os { code: 28, ... }))`` on the ``foxglove.log_sink_set`` logger) and goes
    on: a full disk printed 19 000 such lines before a traceback.  Counted and kept here
    (the first), not printed; the writers check :attr:`count` and raise RecordingError."""

    def __init__(self) -> None:
        super().__init__()
        self.count = 0
        self.first = ""

    def filter(self, record: logging.LogRecord) -> bool:
        msg = record.getMessage()
        if not msg.startswith("error logging message"):
            return True
        if not self.first:
            self.first = msg
        self.count += 1
        return False


WRITE_ERRORS = _WriteErrors()
logging.getLogger("foxglove.log_sink_set").addFilter(WRITE_ERRORS)


def io_problem(text: str, path: Path | None = None) -> str:
    """The OS's words for an I/O error in the SDK's text (``os error 28`` / ``code: 28``); a
    text without the OS's number ("I/O error from writing", from a flush) is told by the
    state of ``path``'s file system: full or read-only."""
    import errno
    import os
    import re

    m = re.search(r"(?:os error |code: )(\d+)", text)
    if m:
        return os.strerror(int(m.group(1)))
    if path is not None:
        try:
            st = os.statvfs(Path(path).parent)
        except OSError:
            return text
        if st.f_flag & os.ST_RDONLY:
            return os.strerror(errno.EROFS)
        if st.f_bavail * st.f_frsize < (1 << 20):
            return f"{os.strerror(errno.ENOSPC)} ({st.f_bavail * st.f_frsize} bytes free)"
    return text
