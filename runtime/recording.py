"""Reading MCAP recordings (also truncated or damaged ones: what is readable, then one line
saying where it breaks) and inspecting them; the format is runtime.recording_format's, the
writer runtime.recording_writer."""

from __future__ import annotations

import heapq
import io
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.records import Channel, Chunk, Footer, Metadata, Schema
from mcap.records import Header as McapHeader
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader
from mcap.writer import MCAP0_MAGIC

from beyond_self.core.errors import InputError
from beyond_self.runtime.mcap_chunk import chunk_records
from beyond_self.runtime.recording_format import JSON, META_FORM, META_TYPE, META_VIEW
from beyond_self.schemas.base import Message
from beyond_self.schemas.codec import (
    RECORDING_JSON_FORM,
    REGISTRY,
    encode,
    from_recording_json,
    wire_encoding,
)


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
                        inner = chunk_records(record)
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
