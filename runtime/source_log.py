"""The source's flight recorder: what a live ingest publishes, kept on its machine, bounded.

A consumer restarted mid-gesture rebuilds its state from a snapshot and the sensor messages
since the snapshot's input position. A live sensor cannot send them again, and a publisher's
cache dies with the ingest, so the ingest first writes each message it publishes to this log:
MCAP files (`beyond replay` plays one) in the service's state folder, a new file every
`segment_bytes`, the oldest deleted while the log holds more than `max_bytes` (bounded by bytes,
never by the distance between stamps). A restarted ingest plays again from the log what a
consumer's successor needs (`since`). A chunk is closed every `flush_s`, so a SIGKILL loses at
most that much of the log's tail (the messages themselves were published).
"""

from __future__ import annotations

import contextlib
import os
import struct
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.records import Channel
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader

from beyond_self.core.errors import InputError
from beyond_self.runtime.publisher import Publisher
from beyond_self.runtime.recording_writer import RecordingWriter
from beyond_self.schemas.codec import wire_encoding

DEFAULT_MAX_MB = 256.0
SEGMENTS = 8  # files the log is cut into: the oldest is deleted whole
FLUSH_S = 0.1


def state_dir(robot: str, service: str) -> Path | None:
    """The state folder of `service` of `robot` on this machine, under $BEYOND_STATE_DIR (None
    when it is not set: the service keeps no state on disk)."""
    base = os.environ.get("BEYOND_STATE_DIR")
    return Path(base) / robot / service if base else None


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
        self.written = 0  # bytes appended to the open segment
        self.count = 0
        existing = self.segments()
        self._next = int(existing[-1].stem) + 1 if existing else 0
        self._writer: RecordingWriter | None = None
        self._by_key: dict[str, Publisher[Any]] = {}

    def segments(self) -> list[Path]:
        return sorted(self.folder.glob("*.mcap"), key=lambda p: int(p.stem))

    def append(self, key: str, stamp: int, payload: bytes, encoding: str) -> None:
        if self._writer is None or self.written >= self.segment_bytes:
            self._rotate()
        assert self._writer is not None
        self._writer.write_raw(key, payload, encoding, stamp)
        self.written += len(payload)
        self.count += 1
        self._writer.maybe_flush()

    def _rotate(self) -> None:
        if self._writer is not None:
            self._writer.close()
        path = self.folder / f"{self._next:08d}.mcap"
        self._next += 1
        self._writer = RecordingWriter(path, compression="none", flush_interval=self.flush_s)
        self.written = 0
        segments = self.segments()
        while len(segments) > 1 and sum(p.stat().st_size for p in segments) > self.max_bytes:
            segments.pop(0).unlink(missing_ok=True)

    def record(self, *publishers: Iterable[Publisher[Any]] | Publisher[Any]) -> None:
        """Write every message `publishers` put into this log first."""
        for group in publishers:
            for pub in [group] if isinstance(group, Publisher) else group:
                encoding = wire_encoding(pub.cls)
                self._by_key[pub.key] = pub

                def tap(key: str, stamp: int, payload: bytes, encoding: str = encoding) -> None:
                    self.append(key, stamp, payload, encoding)

                pub.tap = tap

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
        if self._writer is not None:
            self._writer.flush()

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None

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
