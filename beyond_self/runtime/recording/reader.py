"""Reading MCAP recordings and inspecting them; the format is runtime.recording.format's, the
writer runtime.recording.writer. Damaged files are read past their damage
(runtime.recording.scan), and what could not be played is said in one line
(runtime.recording.damage): the one policy of every command that reads a recording."""

from __future__ import annotations

import heapq
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.records import Channel, Metadata, Schema, Statistics
from mcap.records import Header as McapHeader
from mcap.records import Message as McapMessage
from mcap.writer import MCAP0_MAGIC

from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.damage import Losses
from beyond_self.runtime.recording.format import JSON, JSONSCHEMA, META_FORM, META_TYPE, META_VIEW
from beyond_self.runtime.recording.scan import Walk, mapped
from beyond_self.runtime.ros2.bag import Pair, Ros2Channels, bag_file, bag_size, rosbag_records
from beyond_self.schemas.base import Message
from beyond_self.schemas.codec import (
    RECORDING_JSON_FORM,
    REGISTRY,
    encode,
    from_recording_json,
    wire_encoding,
)
from beyond_self.schemas.keys import forward_only


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
    library: str = ""
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    losses: Losses = field(default_factory=lambda: Losses(""))
    ros2_topics: list[ChannelInfo] = field(default_factory=list)  # a bag's own topics, as read
    ros2_read_as: dict[str, str] = field(default_factory=dict)  # its topic -> stream ("": none)
    notes: list[str] = field(default_factory=list)  # what a command says after its output

    @property
    def duration_s(self) -> float:
        return 0.0 if self.start is None or self.end is None else (self.end - self.start) / 1e9

    @property
    def error(self) -> str:
        """The damage in one line ("" for an intact file)."""
        return self.losses.line() if self.losses.any else ""

    def damage(self) -> str:
        """One line saying what was lost and what is readable (runtime.recording.damage)."""
        return self.losses.line()


class _Scanner:
    """One pass over an MCAP file, past damaged chunks (runtime.recording.scan), keeping the
    schemas and channels it meets and counting what it reads."""

    def __init__(
        self,
        path: str | Path,
        losses: Losses | None = None,
        ros2_roles: Mapping[str, str] | None = None,
    ) -> None:
        self.path = bag_file(Path(path))
        self.bag = self.path.is_dir()  # a bag folder rosbags reads (runtime.ros2.bag)
        if not self.bag and not self.path.is_file():
            raise InputError(f"recording {self.path} does not exist")
        size = bag_size(self.path) if self.bag else self.path.stat().st_size
        self.info = RecordingInfo(path=str(self.path), size=size)
        if losses is not None:
            losses.path, losses.size = str(self.path), size
            self.info.losses = losses
        else:
            self.info.losses = Losses(str(self.path), size)
        self.counts: dict[int, ChannelInfo] = {}
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.types: dict[int, type[Message] | None] = {}
        self.forms: dict[int, int] = {}
        self.views: set[int] = set()
        self.ros2 = Ros2Channels(dict(ros2_roles or {}))  # a rosbag2 bag's channels, as ours
        self.ros2_counts: dict[str, ChannelInfo] = {}  # a bag's topic -> what was read of it

    def messages(self) -> Iterator[tuple[Channel, McapMessage]]:
        try:
            if self.bag:
                for record in rosbag_records(self.path):
                    yield from self._handle(record)
                yield from self._read_as_ours(self.ros2.flush())
                self.info.complete = True
            else:
                yield from self._mcap_messages()
        finally:
            self.ros2.close()
            self.info.ros2_topics = list(self.ros2_counts.values())
            if self.ros2_counts:
                note, routes = self.ros2.note(), self.ros2.plan.routes
                self.info.notes = [note] if note else []
                self.info.ros2_read_as = {
                    t: routes[t][1] if t in routes else "" for t in self.ros2_counts
                }

    def _mcap_messages(self) -> Iterator[tuple[Channel, McapMessage]]:
        info = self.info
        with mapped(self.path) as data:
            walk = Walk(data, info.losses)
            require_magic(self.path, data)
            walk.read_summary()
            for record in walk.summary:
                yield from self._handle(record)
            for record in walk.records():
                yield from self._handle(record)
            yield from self._read_as_ours(self.ros2.flush())
            info.chunks = walk.chunks
            info.complete = walk.complete
            info.readable_bytes = walk.readable

    def _handle(self, record: Any) -> Iterator[tuple[Channel, McapMessage]]:
        info = self.info
        if isinstance(record, McapMessage):
            channel = self.channels.get(record.channel_id)
            t = record.publish_time
            info.losses.read += 1
            if info.losses.first_stamp is None:
                info.losses.first_stamp = t
            if channel is None:
                info.losses.drop(
                    "on a channel no readable record defines",
                    f"channel {record.channel_id} at {info.losses.at(t)}",
                )
                return
            if record.channel_id in self.ros2.routes:  # a rosbag2 bag's, read as ours
                self._count_ros2(record)
                try:
                    yield from self._read_as_ours(self.ros2.convert(record))
                except InputError as exc:  # dropped and counted as any undecodable message
                    where = f"{self.ros2.routes[record.channel_id][0]} at {info.losses.at(t)}"
                    info.losses.drop(UNDECODABLE, f"{where}: {exc}")
            elif channel.id in self.counts:  # else a rosbag2 topic no stream of ours reads
                yield from self._count(channel, record)
        elif isinstance(record, Statistics):
            if record.message_count and info.losses.first_stamp is None:
                info.losses.first_stamp = record.message_start_time
        elif isinstance(record, Schema):
            self.schemas[record.id] = record
        elif isinstance(record, Channel) and record.id not in self.channels:
            schema = self.schemas.get(record.schema_id)
            if self.ros2.route(record, schema):
                self.channels[record.id] = record
                self.ros2_counts.setdefault(record.topic, ChannelInfo(
                    record.topic, record.message_encoding, schema.name if schema else "",
                    schema.encoding if schema else ""))  # fmt: skip
            else:  # ours, or not ROS 2's
                self._handle_channel(record, schema)
        elif isinstance(record, McapHeader):
            info.library = record.library
        elif isinstance(record, Metadata) and record.name != ROSBAG2_METADATA:
            info.metadata[record.name] = dict(record.metadata)

    def _count_ros2(self, record: McapMessage) -> None:
        """Count a sample of a bag's own topic (`inspect` lists them)."""
        counts = self.ros2_counts[self.ros2.routes[record.channel_id][0]]
        counts.count += 1
        t = record.log_time
        counts.first_stamp = t if counts.first_stamp is None else min(counts.first_stamp, t)
        counts.last_stamp = t if counts.last_stamp is None else max(counts.last_stamp, t)

    def _handle_channel(self, record: Channel, schema: Schema | None) -> None:
        info = self.info
        self.channels[record.id] = record
        cls = None
        type_name = record.metadata.get(META_TYPE)
        if record.message_encoding == JSON and type_name in REGISTRY:
            cls = REGISTRY[type_name]
        self.types[record.id] = cls
        if META_VIEW in record.metadata:
            self.views.add(record.id)
        form = record.metadata.get(META_FORM, "1")
        self.forms[record.id] = int(form) if form.isdigit() else -1
        counts = ChannelInfo(
            topic=record.topic,
            message_encoding=record.message_encoding,
            schema_name=schema.name if schema else (cls.schema_name() if cls else ""),
            schema_encoding=schema.encoding if schema else (JSONSCHEMA if cls else ""),
        )
        same = [c for c in info.channels if (c.topic, c.message_encoding) == (
            counts.topic, counts.message_encoding)]  # fmt: skip
        if same:  # one topic in one encoding is one channel to a reader
            counts = same[0]
        else:
            info.channels.append(counts)
        self.counts[record.id] = counts

    def _count(self, channel: Channel, record: McapMessage) -> Iterator[Pair]:
        """Count a message read on one of our channels (every reader's damage report says what
        it read, not 0), and yield it."""
        info, t = self.info, record.publish_time
        info.messages += 1
        info.start = t if info.start is None else min(info.start, t)
        info.end = t if info.end is None else max(info.end, t)
        ci = self.counts[channel.id]
        ci.count += 1
        ci.first_stamp = t if ci.first_stamp is None else min(ci.first_stamp, t)
        ci.last_stamp = t if ci.last_stamp is None else max(ci.last_stamp, t)
        yield channel, record

    def _read_as_ours(self, pairs: Iterable[Pair]) -> Iterator[Pair]:
        for channel, message in pairs:
            if channel.id not in self.channels:
                self._handle_channel(channel, None)
            yield from self._count(channel, message)


def require_magic(path: Path, head: bytes | Any) -> None:
    """InputError unless `head` (a file's first bytes) starts an MCAP recording: the one line
    every command says about an empty file or one that is no recording."""
    if len(head) == 0:
        raise InputError(f"{path} is empty; valid: an MCAP recording")
    if head[: len(MCAP0_MAGIC)] != MCAP0_MAGIC:
        raise InputError(f"{path} is not an MCAP recording (it does not start with the MCAP magic)")


def require_mcap(path: str | Path, ros2_roles: Mapping[str, str] | None = None) -> Path:
    """`path` is an MCAP file with a readable message (or undamaged and empty), else an
    InputError.

    A cheap check (it reads up to the first message) before a command joins the bus or starts
    its work: a file that is no recording, or has nothing readable, is refused first, on one
    line (damage after the first readable message is reported by the readers, with what they
    read)."""
    p = Path(path)
    try:
        p = bag_file(p)
        if p.is_dir():  # a bag rosbags reads: its first message, or its one line
            for _ in _Scanner(p, ros2_roles=ros2_roles).messages():
                break
            return p
        with open(p, "rb") as f:
            head = f.read(len(MCAP0_MAGIC))
    except FileNotFoundError:
        raise InputError(f"recording {p} does not exist") from None
    except IsADirectoryError:
        raise InputError(f"recording {p} is a folder; valid: an MCAP file or a bag") from None
    except OSError as exc:
        raise InputError(f"cannot read recording {p}: {exc.strerror}") from None
    require_magic(p, head)
    scanner = _Scanner(p, ros2_roles=ros2_roles)
    for _ in scanner.messages():  # stops at the first message: a chunk or two read at most
        return p
    if scanner.info.losses.any:
        raise InputError(f"nothing readable: {scanner.info.damage()}")
    return p


def inspect_recording(
    path: str | Path, ros2_roles: Mapping[str, str] | None = None
) -> RecordingInfo:
    """Channels, schemas, counts and time range, and what is lost (`.losses`): every message
    is read and decoded, so a message that would be dropped when played is counted here too.
    Never raises for damage (see `.error`); InputError for a file that is no recording.
    `ros2_roles`: a bag's topics mapped by hand (runtime.ros2.topics.parse_roles)."""
    scanner = _Scanner(path, ros2_roles=ros2_roles)
    for _ in decoded(_sorted(scanner, views=True), scanner.info.losses):
        pass
    return scanner.info


def scan_recording(path: str | Path, ros2_roles: Mapping[str, str] | None = None) -> RecordingInfo:
    """Channels, counts, time range and metadata, as `inspect_recording` finds them, from one
    pass over the file's records that decodes no message: what a player needs before it plays
    (it decodes each message as it sends it, and counts what it drops then). `.losses` holds
    only the file's own damage. InputError for a file that is no recording."""
    scanner = _Scanner(path, ros2_roles=ros2_roles)
    for _ in scanner.messages():
        pass
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


ROSBAG2_METADATA = "rosbag2"  # a bag's metadata.yaml, copied into its MCAP file: shown as topics
NOT_AFTER = "stamp not after the previous one on its key"
UNDECODABLE = "does not decode, or a value out of range"


def _sorted(
    scanner: _Scanner, *, reorder_window: float = 2.0, views: bool = False
) -> Iterator[RecordedMessage]:
    """Every readable message in publish_time order (sorted within `reorder_window` s of log
    time), a sensor frame whose publish_time is not after the previous one on its key dropped and
    counted (runtime.recording.damage: what no consumer could take; schemas.keys.forward_only)."""
    losses = scanner.info.losses
    window = int(reorder_window * 1e9)
    heap: list[tuple[int, int, RecordedMessage]] = []
    last: dict[str, int] = {}

    def in_order(item: RecordedMessage) -> bool:
        if not forward_only(item.key):
            return True
        previous = last.get(item.key)
        if previous is not None and item.publish_time <= previous:
            losses.drop(NOT_AFTER, f"{item.key} at {losses.at(item.publish_time)}")
            return False
        last[item.key] = item.publish_time
        return True

    for counter, (channel, msg) in enumerate(scanner.messages()):
        if channel.id in scanner.views and not views:
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
            if in_order(ready):
                yield ready
    while heap:
        ready = heapq.heappop(heap)[2]
        if in_order(ready):
            yield ready


def decoded(
    items: Iterable[RecordedMessage], losses: Losses
) -> Iterator[tuple[RecordedMessage, Message | None]]:
    """Each item with its decoded message (None: a sample not ours, kept raw). One that does
    not decode, or holds a value out of its bounds (a NaN joint), or a sensor frame whose header
    stamp is not after the previous one on its key, is dropped and counted in `losses`: one bad
    frame is not the end of the source."""
    last: dict[str, int] = {}
    for item in items:
        if item.cls is None:
            yield item, None
            continue
        try:
            message = item.message()
        except InputError as exc:
            losses.drop(UNDECODABLE, f"{item.key} at {losses.at(item.publish_time)}: {exc}")
            continue
        stamp, previous = message.header.stamp, last.get(item.key)
        if previous is not None and stamp <= previous and forward_only(item.key):
            losses.drop(NOT_AFTER, f"{item.key} at {losses.at(item.publish_time)}")
            continue
        last[item.key] = stamp
        yield item, message


def read_recording(
    path: str | Path,
    *,
    topics: Iterable[str] | None = None,
    start: float | None = None,
    end: float | None = None,
    reorder_window: float = 2.0,
    on_damage: Callable[[RecordingInfo], None] | None = None,
    losses: Losses | None = None,
    ros2_roles: Mapping[str, str] | None = None,
) -> Iterator[RecordedMessage]:
    """Messages in stamp (publish_time) order. `topics`: key expressions to keep; `start`/`end`:
    seconds from the first stamp of the recording. Files are read in one sequential pass;
    out-of-order stamps are sorted within `reorder_window` s of log time. A damaged file yields
    everything readable (runtime.recording.scan), then calls `on_damage(info)` (default: raise
    InputError with the one line). With `losses`, what was lost is tallied there instead and
    left to the caller to report (after `decoded` has added what it drops). `ros2_roles`: a
    bag's topics mapped by hand (runtime.ros2.topics.parse_roles)."""
    scanner = _Scanner(path, losses, ros2_roles)
    keep = _matcher(topics)
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

    for item in _sorted(scanner, reorder_window=reorder_window):
        if admit(item):
            yield item
    if losses is None and scanner.info.losses.any:
        if on_damage is None:
            raise InputError(scanner.info.damage())
        on_damage(scanner.info)
