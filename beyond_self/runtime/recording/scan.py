"""Walking an MCAP file record by record, past whatever is damaged.

A damaged chunk costs only itself: one that does not decompress or fails its CRC is counted as
lost (its header's time span says what it held) and the walk goes on with the next record. A
record whose header is damaged (an impossible opcode or length) is skipped to the next chunk,
found from an intact summary's chunk index, else as the next bytes that parse as a chunk whose
CRC holds. A truncated file is read up to where it ends. Channels and schemas come from the
summary too, so messages after a damaged chunk that defined their channel are still read.
Everything lost is tallied in a `runtime.recording.damage.Losses`.
"""

from __future__ import annotations

import io
import mmap
import struct
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Message,
    Metadata,
    Schema,
    Statistics,
)
from mcap.writer import MCAP0_MAGIC

from beyond_self.runtime.recording.damage import Losses
from beyond_self.runtime.recording.mcap_chunk import chunk_records

_HEAD = struct.Struct("<BQ")  # opcode, body length
_CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, compression length
_FOOTER_BYTES = _HEAD.size + 20
_COMPRESSIONS = (b"", b"zstd", b"lz4")
_READERS: dict[int, Any] = {
    Opcode.HEADER: Header,
    Opcode.SCHEMA: Schema,
    Opcode.CHANNEL: Channel,
    Opcode.MESSAGE: Message,
    Opcode.METADATA: Metadata,
    Opcode.STATISTICS: Statistics,
    Opcode.CHUNK_INDEX: ChunkIndex,
    Opcode.DATA_END: DataEnd,
    Opcode.FOOTER: Footer,
}
_KNOWN = {int(op) for op in Opcode}
DataEndReached = DataEnd  # the walk yields it: the data section is complete


@contextmanager
def mapped(path: Path) -> Iterator[bytes | mmap.mmap]:
    """The file's bytes, mapped (an empty file has nothing to map)."""
    with open(path, "rb") as f:
        size = f.seek(0, io.SEEK_END)
        if size == 0:
            yield b""
            return
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
            yield data


def _parse(opcode: int, body: bytes) -> Any:
    reader = _READERS.get(opcode)
    if reader is None:
        return None  # indexes, attachments...: nothing a reader of messages needs
    stream = ReadDataStream(io.BytesIO(body))
    if opcode == Opcode.MESSAGE:
        return Message.read(stream, len(body))
    return reader.read(stream)


class Walk:
    """One pass over `data` (a whole MCAP file), tallying what it cannot read in `losses`."""

    def __init__(self, data: bytes | mmap.mmap, losses: Losses) -> None:
        self.data = data
        self.size = len(data)
        self.losses = losses
        self.chunk_starts: list[int] = []  # from the summary's chunk index, when there is one
        self.summary: list[Any] = []  # schemas, channels, statistics of an intact summary
        self.chunks = 0  # chunks read
        self.readable = 0  # bytes up to the end of the last record read
        self.complete = False  # the data section ended and the footer is there
        self.footer = False

    # -- the summary, read first from the end -----------------------------------------------

    def read_summary(self) -> None:
        """Schemas, channels, statistics and chunk offsets from the summary section, if the
        footer and the summary are intact (a truncated file has neither: nothing is taken)."""
        data, size = self.data, self.size
        end = size - len(MCAP0_MAGIC)
        at = end - _FOOTER_BYTES
        if at < len(MCAP0_MAGIC) or data[end:size] != MCAP0_MAGIC:
            return
        opcode, length = _HEAD.unpack_from(data, at)
        if opcode != Opcode.FOOTER or length != 20:
            return
        footer = _parse(opcode, bytes(data[at + _HEAD.size : end]))
        self.footer = True
        start = footer.summary_start
        if not len(MCAP0_MAGIC) <= start < at:
            return
        records: list[Any] = []
        try:
            pos = start
            while pos < at:
                opcode, length = _HEAD.unpack_from(data, pos)
                body_end = pos + _HEAD.size + length
                if opcode not in _KNOWN or body_end > at:
                    return
                record = _parse(opcode, bytes(data[pos + _HEAD.size : body_end]))
                if record is not None:
                    records.append(record)
                pos = body_end
        except Exception:  # a damaged summary: read the data section without it
            return
        self.summary = [r for r in records if isinstance(r, Schema | Channel | Statistics)]
        self.chunk_starts = sorted(
            r.chunk_start_offset for r in records if isinstance(r, ChunkIndex)
        )
        for r in records:
            if isinstance(r, Statistics):
                self.losses.expected = r.message_count

    # -- the data section --------------------------------------------------------------------

    def records(self) -> Iterator[Any]:
        """Every readable record of the data section, chunks broken up, in file order; the
        DataEnd record once the data section is complete."""
        data, size, losses = self.data, self.size, self.losses
        pos = len(MCAP0_MAGIC)
        self.readable = pos
        while True:
            if pos + _HEAD.size > size:
                losses.cut(
                    pos, "ends inside a record header" if pos < size else "ends between records"
                )
                return
            opcode, length = _HEAD.unpack_from(data, pos)
            body_end = pos + _HEAD.size + length
            if opcode not in _KNOWN or body_end > size:
                nxt = self.next_chunk(pos + 1)
                if nxt is None:
                    losses.cut(pos, self._cut_inside(pos, opcode))
                    return
                losses.skipped(
                    pos,
                    nxt,
                    f"unknown record type {opcode}"
                    if opcode not in _KNOWN
                    else f"record length {length} runs past the next chunk",
                )
                pos = nxt
                continue
            body = bytes(data[pos + _HEAD.size : body_end])
            if opcode == Opcode.CHUNK:
                inner = self._chunk(pos, body)
                if inner is None:  # lost; its length may be damaged too: find the next one
                    nxt = self.next_chunk(pos + 1)
                    pos = body_end if nxt is None else nxt
                    continue
                yield from inner
                # a damaged length that still fits would skip intact chunks: go on where the
                # chunk's own contents end (a writer never pads a chunk)
                pos = min(body_end, pos + _HEAD.size + self._chunk_length(body))
                self.readable = pos
                continue
            else:
                try:
                    record = _parse(opcode, body)
                except Exception as exc:
                    nxt = self.next_chunk(pos + 1)
                    if nxt is None:
                        losses.cut(pos, f"{type(exc).__name__}: {exc}")
                        return
                    losses.skipped(pos, nxt, f"{type(exc).__name__}: {exc}")
                    pos = nxt
                    continue
                if isinstance(record, Footer) or (isinstance(record, DataEnd) and self.footer):
                    self.complete = True
                if record is not None:
                    yield record
                if isinstance(record, DataEnd | Footer):
                    self.readable = size
                    return
            pos = body_end
            self.readable = pos

    @staticmethod
    def _chunk_length(body: bytes) -> int:
        """Bytes a chunk's fields take (its header, compression name and records)."""
        (clen,) = struct.unpack_from("<I", body, _CHUNK_HEAD.size - 4)
        (records,) = struct.unpack_from("<Q", body, _CHUNK_HEAD.size + clen)
        return int(_CHUNK_HEAD.size + clen + 8 + records)

    def _cut_inside(self, pos: int, opcode: int) -> str:
        """Why the file ends at `pos`, and from when on a cut chunk's messages are missing."""
        if opcode not in _KNOWN:
            return f"unknown record type {opcode}"
        head = pos + _HEAD.size
        if head <= self.size:
            (length,) = struct.unpack_from("<Q", self.data, pos + 1)
            if length > 4 * 2**30:  # more than a writer makes (mcap's own limit): damage
                return f"a record of {length} bytes, past any limit, runs past the end"
        if opcode == Opcode.CHUNK and head + _CHUNK_HEAD.size <= self.size:
            start, end, *_ = _CHUNK_HEAD.unpack_from(self.data, head)
            if start <= end:
                return f"inside a chunk of messages from {self.losses.at(start)} on"
        return "ends inside a record"

    def _chunk(self, pos: int, body: bytes) -> list[Any] | None:
        """The chunk's records, or None (counted as lost) when it cannot be read."""
        span = None
        try:
            chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
            if chunk.message_start_time <= chunk.message_end_time:
                span = (chunk.message_start_time, chunk.message_end_time)
                if self.losses.first_stamp is None:  # times in the line count from here
                    self.losses.first_stamp = chunk.message_start_time
            inner = chunk_records(chunk)
        except Exception as exc:
            self.losses.chunk(pos, span, f"{type(exc).__name__}: {exc}")
            return None
        self.chunks += 1
        return inner

    def next_chunk(self, start: int) -> int | None:
        """Offset of the first intact chunk at or after `start`: from the summary's index if
        there is one, else the first bytes from `start` on that parse as a chunk whose CRC
        holds."""
        if self.chunk_starts:
            return next((c for c in self.chunk_starts if c >= start), None)
        data = self.data
        at = start
        while (at := data.find(bytes([Opcode.CHUNK]), at)) >= 0:
            if self._is_chunk(at):
                return at
            at += 1
        return None

    def _is_chunk(self, at: int) -> bool:
        data, size = self.data, self.size
        head_end = at + _HEAD.size + _CHUNK_HEAD.size
        if head_end > size:
            return False
        _, length = _HEAD.unpack_from(data, at)
        body_end = at + _HEAD.size + length
        if body_end > size:
            return False
        start, end, _, _, clen = _CHUNK_HEAD.unpack_from(data, at + _HEAD.size)
        if start > end or clen > 4 or bytes(data[head_end : head_end + clen]) not in _COMPRESSIONS:
            return False
        records_at = head_end + clen
        if records_at + 8 > body_end:
            return False
        (records_length,) = struct.unpack_from("<Q", data, records_at)
        if records_at + 8 + records_length != body_end:
            return False
        try:
            chunk_records(
                Chunk.read(ReadDataStream(io.BytesIO(bytes(data[at + _HEAD.size : body_end]))))
            )
        except Exception:
            return False
        return True
