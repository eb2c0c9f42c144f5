"""Writing bus messages into MCAP recordings, in the format of runtime.recording.format."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import IO, Any, NamedTuple

from mcap.writer import CompressionType, IndexType, Writer

from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.format import (
    JSON,
    JSONSCHEMA,
    META_FORM,
    META_TYPE,
    META_VERSION,
    META_VIEW,
)
from beyond_self.schemas.base import Message
from beyond_self.schemas.codec import (
    RECORDING_JSON_FORM,
    SchemaError,
    decode,
    recording_json_schema_bytes,
    to_recording_json,
    type_from_encoding,
)
from beyond_self.schemas.keys import type_for_key

DEFAULT_CHUNK_SIZE = 256 * 1024
COMPRESSIONS = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}


def _library() -> str:
    def v(pkg: str) -> str:
        try:
            return version(pkg)
        except PackageNotFoundError:
            return "?"

    return f"beyond-self {v('beyond-self')}; mcap-python {v('mcap')}"


class _Pending(NamedTuple):
    log_time: int
    publish_time: int
    channel: int
    data: bytes
    seq: int


class _DirectFile:
    """Write-through file for mcap's Writer: every write is a complete system call."""

    def __init__(self, raw: Any) -> None:
        self._raw = raw

    def write(self, data: bytes | memoryview) -> int:
        view = memoryview(data)
        while view:
            written = self._raw.write(view)
            view = view[written:]
        return len(data)

    def tell(self) -> int:
        return int(self._raw.tell())

    def flush(self) -> None:
        pass

    def close(self) -> None:
        os.fsync(self._raw.fileno())
        self._raw.close()


class RecordingWriter:
    """Writes bus messages into an MCAP file (or any binary stream).

    flush_interval: close the open chunk at least this often (seconds of wall time) so a crash
    loses at most that much; None (the default) closes chunks only when full, which keeps the
    output byte-for-byte deterministic for a deterministic input.
    foxglove_views: also store each message's Foxglove views (runtime.foxglove.views: skeleton
    scene, object annotations, plottable beliefs, description log lines) on their own channels,
    marked `beyond.view` so that replay and the readers here skip them."""

    def __init__(
        self,
        target: str | Path | IO[bytes],
        *,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        compression: str = "zstd",
        flush_interval: float | None = None,
        metadata: dict[str, str] | None = None,
        foxglove_views: bool = False,
    ) -> None:
        if compression not in COMPRESSIONS:
            raise InputError(
                f"unknown compression {compression!r}; valid: {', '.join(COMPRESSIONS)}"
            )
        if isinstance(target, str | Path):
            # Unbuffered: each closed chunk reaches the OS at once and survives a SIGKILL.
            # Wrapped, because mcap-python would put a raw file behind its own buffer.
            raw = open(target, "wb", buffering=0)  # noqa: SIM115
            self._file: _DirectFile | None = _DirectFile(raw)
            stream: Any = self._file
        else:
            self._file, stream = None, target
        indexes = IndexType.CHUNK | IndexType.MESSAGE
        if metadata:
            indexes |= IndexType.METADATA
        self._writer = Writer(
            stream,
            chunk_size=chunk_size,
            compression=COMPRESSIONS[compression],
            index_types=indexes,
            enable_data_crcs=True,
        )
        self._writer.start(profile="", library=_library())
        if metadata:
            self._writer.add_metadata("beyond", dict(sorted(metadata.items())))
        self._schemas: dict[type[Message], int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._flush_interval = flush_interval
        self._last_flush = time.monotonic()
        # a live recording's messages wait here to be written in log-time order, chunk by chunk
        # (outputs copy their input's stamp and arrive after newer inputs)
        self._pending: list[_Pending] = []
        self._aging: list[_Pending] = []  # came before the last flush: written at the next
        self._stamp_offset: int | None = None  # last stamp minus its receive time
        self._last_on: dict[str, int] = {}  # last log time per channel
        self._logged: dict[int, int] = {}  # last log time written per MCAP channel id
        self._held: list[tuple[str, int, Callable[[int], None]]] = []  # before any stamp
        self._views: dict[str, int] = {}  # view topic -> channel id
        self._with_views = foxglove_views
        self.count = 0
        self.malformed = 0
        self._closed = False

    def _schema_id(self, cls: type[Message]) -> int:
        sid = self._schemas.get(cls)
        if sid is None:
            sid = self._schemas[cls] = self._writer.register_schema(
                name=cls.schema_name(),
                encoding=JSONSCHEMA,
                data=recording_json_schema_bytes(cls),
            )
        return sid

    def _channel_id(self, key: str, cls: type[Message] | None, encoding: str) -> int:
        name = cls.type_name() if cls is not None else encoding
        cid = self._channels.get((key, name))
        if cid is None:
            if cls is not None:
                cid = self._writer.register_channel(
                    topic=key,
                    message_encoding=JSON,
                    schema_id=self._schema_id(cls),
                    metadata={
                        META_TYPE: cls.type_name(),
                        META_VERSION: str(cls.VERSION),
                        META_FORM: str(RECORDING_JSON_FORM),
                    },
                )
            else:
                cid = self._writer.register_channel(
                    topic=key, message_encoding=encoding or "application/octet-stream", schema_id=0
                )
            self._channels[(key, name)] = cid
        return cid

    def write(self, key: str, message: Message, *, log_time: int | None = None) -> None:
        """Store a message; log_time defaults to its stamp (deterministic recordings), and the
        publish time is the stamp, or log_time for an unstamped message."""
        stamp = message.header.stamp
        log = log_time if log_time is not None else stamp
        self._add(
            self._channel_id(key, type(message), JSON),
            log,
            stamp or log,
            to_recording_json(message),
            message.header.seq,
        )
        if self._with_views:
            self._write_views(key, message, log)

    def _write_views(self, key: str, message: Message, log_time: int) -> None:
        from beyond_self.runtime.foxglove.views import VIEWS_OF, encode_view, root_of

        root = root_of(key)
        if root is None:
            return
        for view in VIEWS_OF.get(type(message), ()):
            topic = view.topic(root)
            cid = self._views.get(topic)
            if cid is None:
                sid = self._writer.register_schema(
                    name=view.schema_name, encoding=JSONSCHEMA, data=view.schema()
                )
                cid = self._views[topic] = self._writer.register_channel(
                    topic=topic,
                    message_encoding=JSON,
                    schema_id=sid,
                    metadata={META_VIEW: view.name},
                )
            self._add(cid, log_time, log_time, encode_view(view, message), message.header.seq)

    def write_wire(self, key: str, payload: bytes, encoding: str, received: int) -> Message | None:
        """Store a sample as it came off the wire at `received` (ns). Ours (by encoding or key)
        are decoded and stored as JSON at their stamp; a malformed one raises SchemaError.
        Others, and ours stamped 0 (a service on a replay's clock before the stream started),
        at their receive time moved onto the stamps' clock, never before the last message of
        their channel; before any stamp has come they wait for the first and are logged at it,
        so a recording of a replay starts with the stream (runtime.clock)."""
        cls = type_from_encoding(encoding) or type_for_key(key)
        if cls is None:
            self._unstamped(key, received, lambda at: self.write_raw(key, payload, encoding, at))
            return None
        try:
            message = decode(payload, cls, key)
        except SchemaError:
            self.malformed += 1
            raise
        stamp = message.header.stamp
        if not stamp:
            self._unstamped(key, received, lambda at: self.write(key, message, log_time=at))
            return message
        self._stamp_offset = stamp - received
        self.write(key, message)
        self._last_on[key] = max(self._last_on.get(key, stamp), stamp)
        held, self._held = self._held, []
        for held_key, _, store in held:
            self._last_on[held_key] = max(self._last_on.get(held_key, stamp), stamp)
            store(stamp)
        return message

    def _unstamped(self, key: str, received: int, store: Callable[[int], None]) -> None:
        """Store a message without a stamp of its own (`store(log_time)`), now or once the
        stamps' clock is known."""
        if self._stamp_offset is None:
            self._held.append((key, received, store))
            return
        at = max(received + self._stamp_offset, self._last_on.get(key, 0))
        self._last_on[key] = at
        store(at)

    def write_raw(self, key: str, payload: bytes, encoding: str, log_time: int) -> None:
        """Store a sample that is not ours as it came, schemaless, under its encoding."""
        self._add(self._channel_id(key, None, encoding), log_time, log_time, payload, 0)

    def _add(self, channel: int, log_time: int, publish_time: int, data: bytes, seq: int) -> None:
        record = _Pending(log_time, publish_time, channel, data, seq & 0xFFFFFFFF)
        self.count += 1
        if self._flush_interval is None:
            self._put(record)
            return
        self._pending.append(record)
        if time.monotonic() - self._last_flush >= self._flush_interval:
            self.flush()

    def _put(self, record: _Pending) -> None:
        # a channel's log times never step back (ROS and Foxglove players assume it): a message
        # stamped before the last one written on its channel, later than the flushes wait for
        # (flush), is logged at that last time, its publish time and contents its own
        log_time = max(record.log_time, self._logged.get(record.channel, record.log_time))
        self._logged[record.channel] = log_time
        self._writer.add_message(
            channel_id=record.channel,
            log_time=log_time,
            publish_time=record.publish_time,
            data=record.data,
            sequence=record.seq,
        )

    def flush(self, *, last: bool = False) -> None:
        """Write what waits, in log-time order, and close the open chunk now, so it is on disk
        even if this process is killed. What came since the previous flush waits for the next
        one (`last`: not), unless it goes before something written now: an output that comes
        after newer inputs (a gesture's final belief, stamped at its end) is written in its
        place if it comes within a flush interval, so log times hold its stamp and never step
        back; at most two intervals of messages wait."""
        self._last_flush = time.monotonic()
        waiting = sorted(self._aging + self._pending, key=lambda r: r.log_time)  # stable
        if last:
            ready, self._aging = waiting, []
        else:
            cut = max((r.log_time for r in self._aging), default=None)
            ready = [r for r in waiting if cut is not None and r.log_time <= cut]
            self._aging = [r for r in waiting if cut is None or r.log_time > cut]
        self._pending = []
        # in the log times the records will be written at (a late one at its channel's last),
        # so a chunk's messages never step back across channels either (`mcap doctor` checks)
        ready.sort(key=lambda r: max(r.log_time, self._logged.get(r.channel, r.log_time)))
        for record in ready:
            self._put(record)
        if ready:
            # mcap-python has no public "close this chunk" call; its private one is stable
            # across 1.x. Without it only size-full chunks would be written before finish().
            finalize = getattr(self._writer, "_Writer__finalize_chunk", None)
            if finalize is not None:
                finalize()

    def maybe_flush(self) -> None:
        """Flush if the interval has passed (call when idle)."""
        if (
            self._flush_interval is not None
            and (self._pending or self._aging)
            and time.monotonic() - self._last_flush >= self._flush_interval
        ):
            self.flush()

    def close(self) -> None:
        """Write the summary and footer (a file without them is still readable here)."""
        if self._closed:
            return
        self._closed = True
        held, self._held = self._held, []
        for _, received, store in held:  # no stamp ever came: the wall clock is the only one
            store(received)
        self.flush(last=True)
        self._writer.finish()  # type: ignore[no-untyped-call]  # mcap leaves it unannotated
        if self._file is not None:
            self._file.close()

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
