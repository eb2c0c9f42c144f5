"""The one replay engine: send timed messages at their stamp-derived times.

`Player` is shared by `beyond replay` (through `replay()`) and the ingest service, so speed,
pause, pacing and stop mean the same on both paths. Each pass sends its cues in order, the n-th
at `(at_n - at_0) / rate` after the pass began (None: as fast as possible), `at` being the
message's own stamp: timing follows the data. With a pacer it never runs more than a window of
stream time ahead of the slowest consumer (runtime.recording.pacing), so even an as-fast-as-possible
replay
is complete and deterministic; with `ticks` it publishes the stream's time (runtime.clock). What a
message becomes on the wire is the caller's `send`; `replay()` uses reliable publishers.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.delivery import STATUS
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.clock import ClockTicks
from beyond_self.runtime.recording.damage import Losses
from beyond_self.runtime.recording.pacing import Pacer
from beyond_self.runtime.recording.reader import RecordedMessage, decoded, read_recording
from beyond_self.runtime.recording.replay_control import ReplayControl, check_rate
from beyond_self.schemas.base import Header, Message
from beyond_self.schemas.codec import encode_into, shift_stamps, wire_encoding
from beyond_self.schemas.keys import STREAMS, Keys, split_key, with_robot
from beyond_self.schemas.messages import StreamClock, Time

log = logging.getLogger("beyond.replay")
M = TypeVar("M", bound=Message)
YIELD_EVERY = 32  # messages sent without sleeping before the event loop gets a turn


@dataclass
class ReplayStats:
    messages: int = 0
    passes: int = 0
    span_s: float = 0.0  # recording time covered (per pass)
    wall_s: float = 0.0
    damaged: str = ""
    held_back_s: float = 0.0  # waiting for the slowest paced consumer

    @property
    def speed(self) -> float:
        """Recording seconds per wall second (over all passes)."""
        return (self.span_s * self.passes) / self.wall_s if self.wall_s > 0 else float("inf")


@dataclass(slots=True, frozen=True)
class Cue:
    """One message to send: when (`at`, ns on the recording's clock), where (`key`, after any
    rename: consumers report progress per key) and the stamp they will report handling."""

    at: int
    key: str
    stamp: int
    message: Message | None  # decoded once; None: a sample not ours, sent as recorded
    recorded: RecordedMessage | None = None

    def ours(self) -> Message:
        """The message; InputError if the sample is not a beyond message."""
        if self.message is not None:
            return self.message
        if self.recorded is not None:
            return self.recorded.message()  # raises, naming the channel
        raise InputError(f"cue on {self.key} carries no message")

    def shifted(self, offset: int) -> Cue:
        """This cue `offset` ns later, its message restamped (a sample not ours is sent as
        recorded: only its time moves)."""
        if offset == 0:
            return self
        message = None if self.message is None else restamped(self.message, offset)
        return Cue(self.at + offset, self.key, self.stamp + offset, message, self.recorded)


def restamped(message: M, offset: int) -> M:
    """`message` moved `offset` ns later: every stamp it holds (schemas.codec.shift_stamps) and
    a camera frame's `timestamp` (which must equal its header stamp)."""
    if isinstance(getattr(message, "timestamp", None), Time):
        return shift_stamps(message, offset, timestamp=Time.from_ns(message.header.stamp + offset))
    return shift_stamps(message, offset)


def recorded_cues(
    items: Iterable[RecordedMessage],
    rename: Callable[[str], str | None] | None = None,
    losses: Losses | None = None,
) -> Iterator[Cue]:
    """Cues for recorded messages, ours decoded once (the stamp to pace on and the message to
    send come from the same decoding). rename: the key to send a recorded key on, None to skip.
    A message that does not decode, or whose stamp does not move forward on its key, is
    dropped and counted in `losses` (runtime.recording.reader.decoded): it is not the end of the
    source."""
    for item, message in decoded(items, losses if losses is not None else Losses("")):
        key = item.key if rename is None else rename(item.key)
        if key is None:
            continue
        stamp = item.publish_time if message is None else message.header.stamp
        yield Cue(item.publish_time, key, stamp, message, item)


LOOP_GAP_S = 1.0  # between one pass of a looped source and the next


def looped(
    passes: Callable[[], Iterable[Cue]],
    *,
    loop: bool,
    span: tuple[int, int] | None = None,
    resume_at: int | None = None,
) -> Iterator[Cue]:
    """The cues of one pass (`passes()` makes them), or with `loop` pass after pass for ever,
    each restamped `span` (first and last stamp of a pass) plus LOOP_GAP_S later than the one
    before: stamps keep increasing, so consumers take every pass (the same stamps again would
    be refused as going backwards) and a looped source plays for ever. `resume_at`: start with
    the pass that holds this (restamped) stamp, where a restarted source's consumers are."""
    period = None if span is None else span[1] - span[0] + round(LOOP_GAP_S * 1e9)
    index = 0
    if loop and resume_at is not None and span is not None and period:
        index = max(0, (resume_at - span[0]) // period)
    while True:
        sent = 0
        first = last = None
        for cue in passes():
            first = cue.at if first is None else first
            last = cue.at
            yield cue.shifted(index * period) if period else cue
            sent += 1
        if not loop or sent == 0:
            return
        if period is None:  # a source whose span was not known before its first pass
            assert first is not None and last is not None
            period = last - first + round(LOOP_GAP_S * 1e9)
        index += 1


class Player:
    """Sends cues through a caller's `send` at their times scaled by `rate`, held by `control`,
    never ahead of `pacer`'s consumers (started and stopped by the caller), until `stop`;
    `ticks` hears the stream's time before each cue is sent, and its last at the end."""

    def __init__(
        self,
        *,
        rate: float | None = 1.0,
        pacer: Pacer | None = None,
        control: ReplayControl | None = None,
        stop: asyncio.Event | None = None,
        ticks: ClockTicks | None = None,
    ) -> None:
        self.rate = check_rate(rate)
        self.pacer = pacer
        self.control = control
        self.stop = stop
        self.ticks = ticks
        self.stats = ReplayStats()
        self._began: float | None = None

    @property
    def stopped(self) -> bool:
        return self.stop is not None and self.stop.is_set()

    async def play(self, cues: Iterable[Cue], send: Callable[[Cue], None]) -> int:
        """One pass over `cues` (timed from its first); returns how many were sent."""
        loop = asyncio.get_running_loop()
        stats, pacer = self.stats, self.pacer
        if self._began is None:
            self._began = loop.time()
        pass_start = loop.time()
        t0: int | None = None
        last = 0
        sent = 0
        for cue in cues:
            if self.stopped:
                break
            if t0 is None:
                t0 = cue.at
            last = cue.at
            delay = 0.0
            if self.rate is not None:
                delay = pass_start + (cue.at - t0) / 1e9 / self.rate - loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
            elif stats.messages % YIELD_EVERY == 0:
                await asyncio.sleep(0)  # let the loop breathe (health, progress, signals)
            if self.control is not None:
                pass_start += await self.control.gate()
            if pacer is not None:
                await pacer.before(cue.key, cue.stamp)
            if self.ticks is not None:
                self.ticks.at(cue.at)
            send(cue)
            if pacer is not None:
                pacer.after(cue.key, cue.stamp)
            sent += 1
            stats.messages += 1
        stats.passes += 1
        if t0 is not None:
            stats.span_s = max(stats.span_s, (last - t0) / 1e9)
            if self.ticks is not None:
                self.ticks.last(last)
        stats.wall_s = loop.time() - self._began
        if pacer is not None:
            stats.held_back_s = pacer.waited_s
        return sent


async def replay(
    bus: Bus,
    path: str | Path,
    *,
    rate: float | None = 1.0,
    loop: bool = False,
    topics: Iterable[str] | None = None,
    start: float | None = None,
    end: float | None = None,
    robot: str | None = None,
    on_message: Callable[[RecordedMessage], None] | None = None,
    stop: asyncio.Event | None = None,
    pace_for: Iterable[str] = (),
    remap: Callable[[str], str] | None = None,
    control: ReplayControl | None = None,
) -> ReplayStats:
    """Publish `path` on `bus` as recorded (`beyond replay`). rate: 2.0 = twice as fast, None =
    as fast as possible. robot: publish under this robot name instead of the recorded one. With
    `loop`, repeat, each pass restamped after the last (`looped`), until `stop` is set (or
    forever). pace_for: services (by name) never to outrun. remap: renames each key as
    published (runtime.recording.replay_control); control: pause/step (the schedule shifts by the
    time
    held). A damaged file replays what is readable and says what was lost in `damaged`."""
    check_rate(rate)
    if start is not None and end is not None and end < start:
        raise InputError(f"--end {end} is before --start {start}")
    topic_list = list(topics) if topics else None

    def rename(key: str) -> str:
        key = with_robot(key, robot) if robot else key
        return remap(key) if remap is not None else key

    clocks = StreamClocks(bus)

    def replayed(key: str) -> str | None:  # the recorded stream clock: ours replaces it
        split = split_key(key)
        if split is not None and split[1] == STREAMS["clock"][0]:
            return None
        key = rename(key)
        clocks.replaying(key)
        return key

    from beyond_self.runtime.recording.reader import scan_recording

    info = scan_recording(path)  # its channels and span; each message is decoded as it is sent
    pacer: Pacer | None = None
    if pace_for:
        pacer = Pacer(bus, pace_for, [rename(c.topic) for c in info.channels])
        await pacer.start()
    player = Player(rate=rate, pacer=pacer, control=control, stop=stop, ticks=clocks.ticks)
    stats = player.stats
    publishers: dict[tuple[str, str], Any] = {}
    buffer = bytearray()
    losses = Losses(str(path))

    def send(cue: Cue) -> None:
        item = cue.recorded
        assert item is not None
        if cue.message is not None and item.cls is not None:
            # = item.wire(), encoded into one reused buffer (Zenoh copies it in `put`):
            # a fresh 230 kB block per camera frame costs more than the encoding.
            encoding = wire_encoding(item.cls)
            encode_into(cue.message, buffer)
            payload: bytes | bytearray = buffer
        else:
            payload, encoding = item.data, item.encoding
        pub = publishers.get((cue.key, encoding))
        if pub is None:
            pub = publishers[(cue.key, encoding)] = bus.raw_publisher(cue.key, encoding)
        pub.put(payload)
        if on_message is not None:
            on_message(item)

    passes = 0

    def one_pass() -> Iterator[Cue]:
        nonlocal passes
        passes += 1  # every pass finds the same damage: the first one says it
        tally = losses if passes == 1 else Losses(str(path))
        items = read_recording(path, topics=topic_list, start=start, end=end, losses=tally)
        return recorded_cues(items, replayed, tally)

    span = None if info.start is None or info.end is None else (info.start, info.end)
    try:
        await player.play(looped(one_pass, loop=loop, span=span), send)
        stats.passes, stats.span_s = passes, info.duration_s
    finally:
        if pacer is not None:
            pacer.stop()
        for pub in publishers.values():
            pub.undeclare()
        clocks.close()
    if losses.any:
        stats.damaged = losses.line()
    return stats


class StreamClocks:
    """`beyond replay`'s stream clock (runtime.clock), on `beyond/<robot>/clock` of every robot
    it has replayed a key of so far."""

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self.ticks = ClockTicks(self._publish)
        self._publishers: dict[str, Any] = {}
        self._seq = 0

    def replaying(self, key: str) -> None:
        split = split_key(key)
        if split is not None and split[0] not in self._publishers:
            clock = Keys(split[0]).clock
            self._publishers[split[0]] = self.bus.publisher(clock, StreamClock, STATUS)

    def _publish(self, stamp: int) -> None:
        header = Header(version=StreamClock.VERSION, source="replay", seq=self._seq, stamp=stamp)
        for pub in self._publishers.values():
            pub.put(StreamClock(header=header))
        self._seq += 1

    def close(self) -> None:
        for pub in self._publishers.values():
            pub.close()
