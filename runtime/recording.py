"""MCAP recordings: write, read (also truncated files), inspect.

Format decisions (see runtime/README.md):
- Channel topic = the Zenoh key. Our messages are stored with message encoding "json" and a
  "jsonschema" schema (the msgspec schema, `$ref`s inlined), both well-known MCAP encodings, so
  any MCAP tool decodes them without this project; msgpack, the wire encoding, is converted on
  the way in and back on replay (`RecordedMessage.wire()`), losslessly (floats round-trip
  exactly, bytes as base64, stamps as Foxglove `Time` {sec, nsec} so that a JavaScript reader,
  whose numbers are doubles, keeps them exact). Each channel names its JSON form in its
  metadata (`beyond.json_form`, see `schemas.codec.RECORDING_JSON_FORM`); a channel without it
  is form 1 (stamps as integers), read as before. Camera frames are stored under Foxglove's
  schema names `foxglove.RawImage` / `foxglove.CompressedImage`, whose fields they carry, so
  Foxglove shows them. Samples on keys that are not ours are stored as they came, schemaless,
  with their Zenoh encoding as the message encoding.
- log_time = publish_time = the header stamp (the data's time), so a viewer's timeline, the
  message's own stamp and the camera `timestamp` agree. A sample without a stamp (0: a
  service whose recording clock has not started yet) or not ours is logged at its receive
  time moved onto the stamps' clock (by the offset of the last stamped sample), never at 0.
  Replay follows publish_time.
- No attachment index and, without metadata, no metadata index: an empty index group with a
  summary offset pointing at it is an error to `mcap doctor`. The data-section CRC is written.
- Chunked and compressed (zstd); the file is written unbuffered and the open chunk is closed at
  least every `flush_interval` s, so a killed recorder leaves every closed chunk readable.
  The reader here reads sequentially and stops cleanly at the first damaged record.
- Deterministic: the same messages written through `RecordingWriter` give the same bytes (no
  wall-clock time is stored unless the caller adds it as metadata).
"""

from __future__ import annotations

import heapq
import io
import os
import struct
import time
import zlib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import IO, Any

from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Footer, Metadata, Schema
from mcap.records import Header as McapHeader
from mcap.records import Message as McapMessage
from mcap.stream_reader import CRCValidationError, StreamReader
from mcap.writer import MCAP0_MAGIC, CompressionType, IndexType, Writer

from core.errors import InputError
from schemas.base import Message
from schemas.codec import (
    RECORDING_JSON_FORM,
    REGISTRY,
    SchemaError,
    decode,
    encode,
    from_recording_json,
    recording_json_schema_bytes,
    to_recording_json,
    type_from_encoding,
    wire_encoding,
)
from schemas.keys import type_for_key

JSON = "json"
JSONSCHEMA = "jsonschema"
META_TYPE = "beyond.type"
META_VERSION = "beyond.version"
META_FORM = "beyond.json_form"
META_VIEW = "beyond.view"  # a derived Foxglove view channel (not replayed)
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
    foxglove_views: also store each message's Foxglove views (runtime.foxglove_views: skeleton
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
        self._unflushed = 0
        self._stamp_offset = 0  # last stamp minus its receive time: the stamps' clock
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
        from runtime.foxglove_views import VIEWS_OF, encode_view, root_of

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
        are decoded and stored as JSON at their stamp; a malformed one raises SchemaError;
        others are stored raw at their receive time on the stamps' clock."""
        cls = type_from_encoding(encoding) or type_for_key(key)
        if cls is None:
            self.write_raw(key, payload, encoding, received + self._stamp_offset)
            return None
        try:
            message = decode(payload, cls, key)
        except SchemaError:
            self.malformed += 1
            raise
        stamp = message.header.stamp
        if stamp:
            self._stamp_offset = stamp - received
        self.write(key, message, log_time=stamp or received + self._stamp_offset)
        return message

    def write_raw(self, key: str, payload: bytes, encoding: str, log_time: int) -> None:
        """Store a sample that is not ours as it came, schemaless, under its encoding."""
        self._add(self._channel_id(key, None, encoding), log_time, log_time, payload, 0)

    def _add(self, channel: int, log_time: int, publish_time: int, data: bytes, seq: int) -> None:
        self._writer.add_message(
            channel_id=channel,
            log_time=log_time,
            publish_time=publish_time,
            data=data,
            sequence=seq & 0xFFFFFFFF,
        )
        self.count += 1
        self._unflushed += 1
        if self._flush_interval is not None:
            now = time.monotonic()
            if now - self._last_flush >= self._flush_interval:
                self.flush()

    def flush(self) -> None:
        """Close the open chunk now so it is on disk even if this process is killed."""
        self._last_flush = time.monotonic()
        if self._unflushed:
            # mcap-python has no public "close this chunk" call; its private one is stable
            # across 1.x. Without it only size-full chunks would be written before finish().
            finalize = getattr(self._writer, "_Writer__finalize_chunk", None)
            if finalize is not None:
                finalize()
            self._unflushed = 0

    def maybe_flush(self) -> None:
        """Flush if the interval has passed (call when idle)."""
        if (
            self._flush_interval is not None
            and self._unflushed
            and time.monotonic() - self._last_flush >= self._flush_interval
        ):
            self.flush()

    def close(self) -> None:
        """Write the summary and footer (a file without them is still readable here)."""
        if self._closed:
            return
        self._closed = True
        self._writer.finish()  # type: ignore[no-untyped-call]  # mcap leaves it unannotated
        if self._file is not None:
            self._file.close()

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(slots=True, frozen=True)
class RecordedMessage:
    key: str
    log_time: int
    publish_time: int
    encoding: str  # MCAP message encoding of `data`
    cls: type[Message] | None
    data: bytes
    form: int = RECORDING_JSON_FORM  # JSON form of `data` (schemas.codec), 1 in older files

    def message(self) -> Message:
        """The decoded message (strict); InputError if the channel is not one of ours."""
        if self.cls is None:
            raise InputError(f"channel {self.key} ({self.encoding}) is not a beyond message")
        return from_recording_json(self.data, self.cls, self.key, self.form)

    def wire(self) -> tuple[bytes, str]:
        """(payload, Zenoh encoding) to publish this message as the original sender did."""
        if self.cls is None:
            return self.data, self.encoding
        return encode(self.message()), wire_encoding(self.cls)


@dataclass
class ChannelInfo:
    topic: str
    message_encoding: str
    schema_name: str
    schema_encoding: str
    count: int = 0
    first_stamp: int | None = None
    last_stamp: int | None = None


@dataclass
class RecordingInfo:
    path: str
    size: int
    channels: list[ChannelInfo] = field(default_factory=list)
    messages: int = 0
    chunks: int = 0
    start: int | None = None  # publish_time range
    end: int | None = None
    complete: bool = False  # summary and footer present (the writer finished)
    readable_bytes: int = 0  # bytes up to the end of the last record read intact
    error: str = ""
    library: str = ""
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return 0.0 if self.start is None or self.end is None else (self.end - self.start) / 1e9

    def damage(self) -> str:
        """One line saying what is wrong and what is readable."""
        return (
            f"{self.path} is truncated or corrupt at byte {self.readable_bytes} of {self.size} "
            f"({self.error}); readable: {self.messages} messages in {self.chunks} complete "
            f"chunks, {self.duration_s:.3f} s"
        )


class _Scanner:
    """Sequential pass over an MCAP file that stops at the first damaged record."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(f"recording {self.path} does not exist")
        self.info = RecordingInfo(path=str(self.path), size=self.path.stat().st_size)
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.types: dict[int, type[Message] | None] = {}
        self.forms: dict[int, int] = {}
        self.views: set[int] = set()

    def messages(self) -> Iterator[tuple[Channel, McapMessage]]:
        info = self.info
        with open(self.path, "rb") as raw:
            f = io.BufferedReader(raw, buffer_size=1 << 20)
            reader = StreamReader(f, emit_chunks=True, validate_crcs=True)
            try:
                for record in reader.records:
                    if isinstance(record, Chunk):
                        inner = _chunk_records(record)
                        info.chunks += 1
                        info.readable_bytes = f.tell()
                        for rec in inner:
                            yield from self._handle(rec)
                        continue
                    yield from self._handle(record)
                    info.readable_bytes = f.tell()
                    if isinstance(record, Footer):
                        info.complete = True
            except Exception as exc:  # any damage: stop, keep what was read
                info.error = _describe(exc, f.tell(), info.size)
                info.complete = False
        if info.complete:
            info.readable_bytes = info.size

    def _handle(self, record: Any) -> Iterator[tuple[Channel, McapMessage]]:
        info = self.info
        if isinstance(record, McapMessage):
            channel = self.channels.get(record.channel_id)
            if channel is None:
                raise InputError(f"message on unknown channel {record.channel_id}")
            # counted here, so every reader's damage report says what it read (not 0)
            t = record.publish_time
            info.messages += 1
            info.start = t if info.start is None else min(info.start, t)
            info.end = t if info.end is None else max(info.end, t)
            yield channel, record
        elif isinstance(record, Schema):
            self.schemas[record.id] = record
        elif isinstance(record, Channel):
            if record.id not in self.channels:
                self.channels[record.id] = record
                schema = self.schemas.get(record.schema_id)
                cls = None
                type_name = record.metadata.get(META_TYPE)
                if record.message_encoding == JSON and type_name in REGISTRY:
                    cls = REGISTRY[type_name]
                self.types[record.id] = cls
                if META_VIEW in record.metadata:
                    self.views.add(record.id)
                form = record.metadata.get(META_FORM, "1")
                self.forms[record.id] = int(form) if form.isdigit() else -1
                info.channels.append(
                    ChannelInfo(
                        topic=record.topic,
                        message_encoding=record.message_encoding,
                        schema_name=schema.name if schema else "",
                        schema_encoding=schema.encoding if schema else "",
                    )
                )
        elif isinstance(record, McapHeader):
            info.library = record.library
        elif isinstance(record, Metadata):
            info.metadata[record.name] = dict(record.metadata)


_RECORD_HEAD = struct.Struct("<BQ")  # opcode, body length
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time


def _chunk_data(chunk: Chunk) -> bytes:
    """The chunk's records, decompressed and checked against its CRC."""
    if chunk.compression == "zstd":
        import zstandard

        data: bytes = zstandard.decompress(chunk.data, chunk.uncompressed_size)
    elif chunk.compression == "lz4":
        import lz4.frame  # type: ignore[import-untyped]

        data = lz4.frame.decompress(chunk.data)
    elif chunk.compression == "":
        data = bytes(chunk.data)
    else:
        raise InputError(f"unsupported chunk compression {chunk.compression!r}")
    if chunk.uncompressed_crc != 0 and zlib.crc32(data) != chunk.uncompressed_crc:
        raise CRCValidationError(
            expected=chunk.uncompressed_crc, actual=zlib.crc32(data), record=chunk
        )
    return data


def _chunk_records(chunk: Chunk) -> list[Any]:
    """Schema, channel and message records of a chunk (what mcap's `breakup_chunk` returns),
    with messages parsed straight from the buffer: mcap's general stream reader spends more
    time per camera frame than the CRC check."""
    data = _chunk_data(chunk)
    records: list[Any] = []
    pos, end = 0, len(data)
    while pos < end:
        if end - pos < _RECORD_HEAD.size:
            raise EndOfFile()
        opcode, length = _RECORD_HEAD.unpack_from(data, pos)
        start = pos + _RECORD_HEAD.size
        pos = start + length
        if pos > end:
            raise EndOfFile()
        if opcode == Opcode.MESSAGE:
            if length < _MESSAGE_HEAD.size:
                raise EndOfFile()
            channel_id, sequence, log_time, publish_time = _MESSAGE_HEAD.unpack_from(data, start)
            records.append(
                McapMessage(
                    channel_id=channel_id,
                    sequence=sequence,
                    log_time=log_time,
                    publish_time=publish_time,
                    data=data[start + _MESSAGE_HEAD.size : pos],
                )
            )
        elif opcode in (Opcode.CHANNEL, Opcode.SCHEMA):
            stream = ReadDataStream(io.BytesIO(data[start:pos]))
            records.append((Channel if opcode == Opcode.CHANNEL else Schema).read(stream))
    return records


def _describe(exc: Exception, at: int, size: int) -> str:
    name = type(exc).__name__
    text = " ".join(str(exc).split())
    if at >= size:
        return f"ends inside a record ({name}{': ' + text if text else ''})"
    return f"{name}{': ' + text if text else ''}"


def require_mcap(path: str | Path) -> Path:
    """`path` is a readable MCAP file with a readable message (or undamaged and empty), else an
    InputError.

    A cheap check (it reads up to the first message) before a command joins the bus or starts
    its work: a file that is no recording, or damaged before its first message, is refused
    first, on one line, rather than after a warning that 0 messages are readable (damage later
    in the file is reported by the readers, with what they read)."""
    p = Path(path)
    try:
        with open(p, "rb") as f:
            head = f.read(len(MCAP0_MAGIC))
    except FileNotFoundError:
        raise InputError(f"recording {p} does not exist") from None
    except IsADirectoryError:
        raise InputError(f"recording {p} is a folder; valid: an MCAP file") from None
    except OSError as exc:
        raise InputError(f"cannot read recording {p}: {exc.strerror}") from None
    if head != MCAP0_MAGIC:
        raise InputError(f"{p} is not an MCAP recording (it does not start with the MCAP magic)")
    scanner = _Scanner(p)
    for _ in scanner.messages():  # stops at the first message: a chunk read at most
        return p
    if scanner.info.error:
        raise InputError(f"nothing readable: {scanner.info.damage()}")
    return p


def inspect_recording(path: str | Path) -> RecordingInfo:
    """Channels, schemas, counts and time range; never raises for damage (see `.error`)."""
    scanner = _Scanner(path)
    by_id: dict[int, ChannelInfo] = {}
    for channel, msg in scanner.messages():
        ci = by_id.get(channel.id)
        if ci is None:
            ci = by_id[channel.id] = next(
                c
                for c in scanner.info.channels
                if c.topic == channel.topic and c.message_encoding == channel.message_encoding
            )
        ci.count += 1
        t = msg.publish_time
        ci.first_stamp = t if ci.first_stamp is None else min(ci.first_stamp, t)
        ci.last_stamp = t if ci.last_stamp is None else max(ci.last_stamp, t)
    return scanner.info


def _matcher(patterns: Iterable[str] | None) -> Callable[[str], bool]:
    if not patterns:
        return lambda _key: True
    import zenoh

    exprs = [zenoh.KeyExpr.autocanonize(p) for p in patterns]
    cache: dict[str, bool] = {}

    def match(key: str) -> bool:
        hit = cache.get(key)
        if hit is None:
            hit = cache[key] = any(e.intersects(zenoh.KeyExpr(key)) for e in exprs)
        return hit

    return match


def read_recording(
    path: str | Path,
    *,
    topics: Iterable[str] | None = None,
    start: float | None = None,
    end: float | None = None,
    reorder_window: float = 2.0,
    on_damage: Callable[[RecordingInfo], None] | None = None,
) -> Iterator[RecordedMessage]:
    """Messages in stamp (publish_time) order. `topics`: key expressions to keep; `start`/`end`:
    seconds from the first stamp of the recording. Files are read in one sequential pass;
    out-of-order stamps are sorted within `reorder_window` s of receive time. A damaged file
    yields what is readable, then calls `on_damage(info)` (default: raise InputError)."""
    scanner = _Scanner(path)
    keep = _matcher(topics)
    window = int(reorder_window * 1e9)
    heap: list[tuple[int, int, RecordedMessage]] = []
    t0: int | None = None

    def admit(item: RecordedMessage) -> bool:
        nonlocal t0
        if t0 is None:
            t0 = item.publish_time
        rel = (item.publish_time - t0) / 1e9
        if start is not None and rel < start:
            return False
        if end is not None and rel > end:
            return False
        return keep(item.key)

    for counter, (channel, msg) in enumerate(scanner.messages()):
        if channel.id in scanner.views:
            continue  # derived for viewers; the messages it came from are replayed
        item = RecordedMessage(
            key=channel.topic,
            log_time=msg.log_time,
            publish_time=msg.publish_time,
            encoding=channel.message_encoding,
            cls=scanner.types.get(channel.id),
            data=msg.data,
            form=scanner.forms.get(channel.id, 1),
        )
        heapq.heappush(heap, (item.publish_time, counter, item))
        while heap and heap[0][0] <= msg.log_time - window:
            ready = heapq.heappop(heap)[2]
            if admit(ready):
                yield ready
    while heap:
        ready = heapq.heappop(heap)[2]
        if admit(ready):
            yield ready
    if scanner.info.error:
        if on_damage is None:
            raise InputError(scanner.info.damage())
        on_damage(scanner.info)
