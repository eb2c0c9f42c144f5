"""The source's flight recorder: what a live ingest publishes, kept on its machine, bounded.

A consumer restarted mid-gesture rebuilds its state from a snapshot and the sensor messages
since the snapshot's input position. A live sensor cannot send them again, and a publisher's
cache dies with the ingest, so the ingest first writes each message it publishes to this log:
MCAP files (`beyond replay` plays one) in the service's state folder, a new file every
`segment_bytes`, the oldest deleted while the log holds more than `max_bytes` (bounded by bytes,
never by the distance between stamps). A restarted ingest plays again from the log what a
consumer's successor needs (`since`). What is appended reaches the file every `flush_s` (or
MB), so a SIGKILL loses at most that much of the log's tail (the messages were published).
"""

from __future__ import annotations

import contextlib
import os
import struct
import time
from collections.abc import Iterable, Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.publisher import Publisher
from beyond_self.schemas.codec import wire_encoding

DEFAULT_MAX_MB = 256.0
SEGMENTS = 8  # files the log is cut into: the oldest is deleted whole
FLUSH_S = 0.1
FLUSH_BYTES = 1 << 20
_IOV = 512  # pieces per writev (the system's limit is 1024)


MAGIC = b"\x89MCAP0\r\n"
_MESSAGE = struct.Struct("<BQHIQQ")  # opcode, length, channel, sequence, log and publish time


def _string(text: str) -> bytes:
    data = text.encode()
    return struct.pack("<I", len(data)) + data


def _record(opcode: Opcode, content: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(content)) + content


class _Segment:
    """One log file: MCAP without chunks (a message is one record: its header packed, then the
    payload as it was published, not copied), gathered and handed every `flush_s` or MB to the
    log's writing thread (one `writev`), so the publisher pays little more than packing a
    header. Closed with a footer without a summary; a file cut short by
    a kill is read up to its last whole record."""

    def __init__(
        self, path: Path, flush_s: float, io: ThreadPoolExecutor, encodings: dict[str, str]
    ) -> None:
        self.path = path
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._io = io
        self._encodings = encodings  # key -> wire encoding
        self.total = 0  # payload bytes appended
        header = _record(Opcode.HEADER, _string("") + _string("beyond-self source log"))
        self._pieces: list[bytes] = [MAGIC, header]
        self._size = 0
        self._channels: dict[str, int] = {}
        self._flush_s = flush_s
        self._flushed = time.monotonic()
        self._seq = 0

    def append(self, key: str, stamp: int, payload: bytes) -> None:
        channel = self._channels.get(key)
        if channel is None:
            channel = self._channels[key] = len(self._channels) + 1
            encoding = self._encodings.get(key, "")
            content = struct.pack("<HH", channel, 0) + _string(key) + _string(encoding)
            self._pieces.append(_record(Opcode.CHANNEL, content + struct.pack("<I", 0)))
        self._seq += 1
        size = 22 + len(payload)  # channel, sequence, log and publish time, then the data
        self._pieces += (
            _MESSAGE.pack(Opcode.MESSAGE, size, channel, self._seq, stamp, stamp),
            payload,
        )
        self._size += size
        self.total += size
        if self._size >= FLUSH_BYTES or time.monotonic() - self._flushed >= self._flush_s:
            self.flush()

    def flush(self) -> None:
        self._flushed = time.monotonic()
        pieces, self._pieces, self._size = self._pieces, [], 0
        if pieces:
            self._io.submit(_write, self._fd, pieces)

    def close(self) -> None:
        self._pieces.append(_record(Opcode.DATA_END, struct.pack("<I", 0)))
        self._pieces += (_record(Opcode.FOOTER, struct.pack("<QQI", 0, 0, 0)), MAGIC)
        self.flush()
        self._io.submit(os.close, self._fd)


def _write(fd: int, pieces: list[bytes]) -> None:
    """On the log's own thread (the GIL is released while the kernel copies)."""
    for i in range(0, len(pieces), _IOV):
        batch = pieces[i : i + _IOV]
        done, total = os.writev(fd, batch), sum(map(len, batch))
        if done < total:  # a short write (a full disk, a signal): the rest, plainly
            os.write(fd, b"".join(batch)[done:])


class SourceLog:
    """Append-only, bounded: `append` what is published, `since` to play it again."""

    def __init__(self, folder: Path, max_bytes: int, flush_s: float = FLUSH_S) -> None:
        if max_bytes < SEGMENTS * 64 * 1024:
            raise InputError(
                f"a source log of {max_bytes} bytes; valid: at least {SEGMENTS * 64} KiB"
            )
        self.folder = folder / "log"
        self.folder.mkdir(parents=True, exist_ok=True)
        self.max_bytes = max_bytes
        self.segment_bytes = max_bytes // SEGMENTS
        self.flush_s = flush_s
        existing = self.segments()
        self._next = int(existing[-1].stem) + 1 if existing else 0
        self._writer: _Segment | None = None
        # each file's size as appended, not as written yet: the writing thread may lag behind
        self._sizes = {path: path.stat().st_size for path in existing}
        # one thread writes the files, in order: publishing does not wait for the kernel
        self._io = ThreadPoolExecutor(1, "source-log")
        self._by_key: dict[str, Publisher[Any]] = {}
        self._encodings: dict[str, str] = {}

    def segments(self) -> list[Path]:
        return sorted(self.folder.glob("*.mcap"), key=lambda p: int(p.stem))

    def append(self, key: str, stamp: int, payload: bytes, encoding: str = "") -> None:
        """Log `payload`, published on `key` stamped `stamp` (its encoding: the first time)."""
        if encoding:
            self._encodings.setdefault(key, encoding)
        writer = self._writer
        if writer is None or writer.total >= self.segment_bytes:
            writer = self._rotate()
        writer.append(key, stamp, payload)

    def _rotate(self) -> _Segment:
        if self._writer is not None:
            self._writer.close()
            self._sizes[self._writer.path] = self._writer.total
        path = self.folder / f"{self._next:08d}.mcap"
        self._next += 1
        writer = self._writer = _Segment(path, self.flush_s, self._io, self._encodings)
        self._sizes[path] = 0
        while len(self._sizes) > 1 and sum(self._sizes.values()) > self.max_bytes:
            oldest = min(self._sizes, key=lambda p: int(p.stem))
            del self._sizes[oldest]
            # on the writing thread, after what it still has to write there
            self._io.submit(oldest.unlink, True)
        return writer

    def record(self, *publishers: Iterable[Publisher[Any]] | Publisher[Any]) -> None:
        """Write every message `publishers` put into this log first."""
        for group in publishers:
            for pub in [group] if isinstance(group, Publisher) else group:
                self._encodings[pub.key] = wire_encoding(pub.cls)
                self._by_key[pub.key] = pub
                pub.tap = self.append

    def play_again(self, first: Mapping[str, int]) -> int:
        """Publish again (not logging it twice), from the recording publishers, what the log
        holds from `first` on (per key); how many messages."""
        count = 0
        for key, _stamp, payload, _encoding in self.since(first):
            pub = self._by_key.get(key)
            if pub is not None:
                pub.put_bytes(payload)
                count += 1
        return count

    def flush(self) -> None:
        """What was appended is in the files once this returns."""
        if self._writer is not None:
            self._writer.flush()
        self._io.submit(lambda: None).result()

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        self._io.shutdown(wait=True)
        self._io = ThreadPoolExecutor(1, "source-log")  # its thread starts if appended to again

    def since(self, first: Mapping[str, int]) -> Iterator[tuple[str, int, bytes, str]]:
        """(key, stamp, payload, encoding) of every message logged on a key of `first` stamped
        at or after its value, oldest file first; a file cut short by a kill gives what it
        holds."""
        for path in self.segments():
            yield from _read(path, first)


def _read(path: Path, first: Mapping[str, int]) -> Iterator[tuple[str, int, bytes, str]]:
    channels: dict[int, Channel] = {}
    with (
        contextlib.suppress(McapError, OSError, EOFError, ValueError, struct.error),
        path.open("rb") as f,
    ):
        for record in StreamReader(f, skip_magic=False, emit_chunks=False).records:
            if isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, McapMessage):
                channel = channels.get(record.channel_id)
                if channel is None:
                    continue
                at = first.get(channel.topic)
                if at is not None and record.log_time >= at:
                    yield channel.topic, record.log_time, record.data, channel.message_encoding
