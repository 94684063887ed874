"""Reading an MCAP recording past damage: what precedes it, and what follows where the file's
chunk indexes allow, with a line naming each loss.

``mcap``'s readers stop at the first damaged byte with the exception of whatever layer met it
(a ``zstandard`` ``ZstdError`` for a chunk whose end a bad sector changed, a ``struct.error``
for a cut record) and, in the whole-file (log-time) mode, yield nothing at all.  A recording is
an experiment's only copy of what was sent: :func:`records` reads record by record, checks each
chunk's CRC (the writers fill it in), skips a chunk it cannot read and goes on with the next
record, and when a record's framing itself is damaged it jumps to the next chunk the summary's
chunk index names (a file that ended whole has one; a file cut short ends there).  Each loss
goes into ``lost`` as a :class:`Lost`, whose :meth:`Lost.text` is one line ``file: where: what``.
"""

from __future__ import annotations

import io
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from mcap.records import Channel, Chunk, ChunkIndex, DataEnd, Footer, Message, Opcode, ReadDataStream, Schema, Statistics
from mcap.stream_reader import breakup_chunk

from zswarm.util.files import RecordingError

MAGIC = b"\x89MCAP0\r\n"
_HEAD = struct.Struct("<BQ")
# The largest record this reader loads (a chunk is 4 MiB, a message at most wire.MAX_PAYLOAD):
# a damaged length field above it is damage, not a record to allocate.
MAX_RECORD = 256 << 20
_KNOWN = {int(o) for o in Opcode}


class NotMcap(RecordingError):
    """A file that is not an MCAP recording at all (exit 2: not ours)."""


@dataclass
class Lost:
    """One loss: where in the file (byte offset), what was found there, and what it cost."""

    path: Path
    offset: int
    what: str
    cost: str

    def text(self) -> str:
        where = f"byte {self.offset}: " if self.offset >= 0 else ""
        return f"{self.path}: {where}{self.what}{'; ' if self.offset >= 0 else ': '}{self.cost}"


@dataclass
class _Summary:
    chunk_starts: list[int]
    channels: dict[int, Channel]
    messages: int | None
    t0: int | None


def _summary(f: IO[bytes], size: int) -> _Summary | None:
    """The summary section of a file that ended whole (its footer and chunk indexes), else None."""
    from mcap.reader import SeekingReader

    try:
        f.seek(0)
        s = SeekingReader(f, validate_crcs=False).get_summary()
    except Exception:  # noqa: BLE001 - a file cut short (or its end damaged) has none
        return None
    if s is None:
        return None
    starts = sorted(ci.chunk_start_offset for ci in s.chunk_indexes if isinstance(ci, ChunkIndex) and 8 <= ci.chunk_start_offset < size)
    stats = s.statistics if isinstance(s.statistics, Statistics) else None
    return _Summary(starts, dict(s.channels), stats.message_count if stats else None, stats.message_start_time if stats else None)


def _parse(opcode: int, body: bytes) -> Any:
    stream = ReadDataStream(io.BytesIO(body))
    if opcode == Opcode.MESSAGE:
        return Message.read(stream, len(body))
    if opcode == Opcode.CHUNK:
        return Chunk.read(stream)
    if opcode == Opcode.CHANNEL:
        return Channel.read(stream)
    if opcode == Opcode.SCHEMA:
        return Schema.read(stream)
    if opcode == Opcode.DATA_END:
        return DataEnd.read(stream)
    if opcode == Opcode.FOOTER:
        return Footer.read(stream)
    return None  # the rest (header, indexes, metadata, statistics ...) carry no message


def _span(t0: int | None, a: int, b: int) -> str:
    if t0 is None or not (0 <= a - t0 < 10**15 and 0 <= b - t0 < 10**15):
        return ""
    return f" (logged {(a - t0) / 1e9:.2f}-{(b - t0) / 1e9:.2f} s into the recording)"


def records(path: str | Path, lost: list[Lost]) -> Iterator[tuple[Channel, Message]]:
    """Every readable message of ``path`` with its channel, in file order; each loss appended
    to ``lost``.  :class:`NotMcap` when the file does not begin as an MCAP file.  A file that
    ends before its magic does (empty, or a prefix of it: a writer killed before its first
    flush, which the recorder makes every 0.5 s) holds nothing and says so."""
    path = Path(path)
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        head = f.read(8)
        if head != MAGIC:
            if MAGIC.startswith(head):
                lost.append(Lost(path, len(head), "the file ends before its first record (cut short: a writer killed before its first flush, or a full disk)", "nothing of it was written"))
                return
            raise NotMcap(f"{path}: byte 0: not an MCAP recording (no MCAP magic)")
        summary = _summary(f, size)
        channels: dict[int, Channel] = dict(summary.channels) if summary else {}
        t0 = summary.t0 if summary else None
        n = 0
        pos = 8
        while pos < size:
            f.seek(pos)
            head = f.read(_HEAD.size)
            opcode, length = _HEAD.unpack(head) if len(head) == _HEAD.size else (0, 0)
            end = pos + _HEAD.size + length
            framed = len(head) == _HEAD.size and opcode in _KNOWN and length <= MAX_RECORD and end <= size
            if not framed and summary is None and (len(head) < _HEAD.size or (end > size and opcode in _KNOWN)):
                lost.append(Lost(path, pos, "the file ends inside a record (cut short: a killed writer or a full disk)", "what followed was never written"))
                return
            try:
                if not framed:
                    raise ValueError(f"no record here (opcode 0x{opcode:02x}, length {length})")
                rec = _parse(opcode, f.read(length))
            except Exception as exc:  # noqa: BLE001 - damage of any kind: described, then skipped
                nxt = next((s for s in summary.chunk_starts if s > pos), None) if summary else None
                cost = f"read again from the next chunk at byte {nxt}" if nxt is not None else f"the rest of the file ({size - pos} bytes) is lost"
                lost.append(Lost(path, pos, f"damaged record ({_why(exc)})", cost))
                if nxt is None:
                    return
                pos = nxt
                continue
            pos = end
            if isinstance(rec, Chunk):
                if t0 is None:
                    t0 = rec.message_start_time
                try:
                    inner = breakup_chunk(rec, validate_crc=True)
                except Exception as exc:  # noqa: BLE001 - a chunk whose data is damaged: skipped whole
                    lost.append(Lost(path, end - length - _HEAD.size, f"damaged chunk ({_why(exc)})", "its messages" + _span(t0, rec.message_start_time, rec.message_end_time) + " are lost; read on after it"))
                    continue
            else:
                inner = [rec]
            for r in inner:
                if isinstance(r, Channel):
                    channels[r.id] = r
                elif isinstance(r, Message):
                    ch = channels.get(r.channel_id)
                    if ch is not None:
                        n += 1
                        yield ch, r
            if isinstance(rec, (DataEnd, Footer)):
                break
        if summary is not None and summary.messages is not None and lost and n < summary.messages:
            lost.append(Lost(path, -1, "in all", f"{summary.messages - n} of its {summary.messages} messages lost (the count in its statistics)"))


def metadata(path: str | Path, name: str = "zswarm") -> dict[str, str]:
    """The entries of the metadata records called ``name``, read in file order from the start
    up to the first damaged or cut record (the writers put theirs before the first chunk, so a
    file cut short or with a damaged chunk keeps them; ``mcap``'s reader finds them only through
    the summary of a file that ended whole).  Chunks are skipped, not read.  {} for a file that
    is not MCAP or has none."""
    from mcap.records import Metadata

    out: dict[str, str] = {}
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        if f.read(8) != MAGIC:
            return out
        pos = 8
        while pos + _HEAD.size <= size:
            f.seek(pos)
            opcode, length = _HEAD.unpack(f.read(_HEAD.size))
            end = pos + _HEAD.size + length
            if opcode not in _KNOWN or length > MAX_RECORD or end > size or opcode in (Opcode.DATA_END, Opcode.FOOTER):
                break
            if opcode == Opcode.METADATA:
                try:
                    m = Metadata.read(ReadDataStream(io.BytesIO(f.read(length))))
                except Exception:  # noqa: BLE001 - a damaged record ends what can be trusted
                    break
                if m.name == name:
                    out.update(m.metadata)
            pos = end
    return out


def _why(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return f"{type(exc).__name__}: {text}"[:160]
