"""Play a recording onto the bus, in stamp order, with its original timing scaled.

`replay()` is the library form (tests and services call it in-process); `beyond replay` wraps it.
Messages go out on reliable publishers (Zenoh blocks rather than drops when its queue is full),
and with `pace_for` the replay never runs more than a window of recording time ahead of the
slowest of those services (runtime.pacing), so an as-fast-as-possible replay into a pipeline is
complete and deterministic.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from core.errors import InputError
from runtime.bus import Bus
from runtime.pacing import Pacer
from runtime.recording import RecordedMessage, RecordingInfo, read_recording
from runtime.replay_control import ReplayControl
from schemas.codec import encode_into, wire_encoding
from schemas.keys import with_robot

log = logging.getLogger("beyond.replay")


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
    """Publish `path` on `bus`. rate: 2.0 = twice as fast, None = as fast as possible.
    robot: publish under this robot name instead of the recorded one. With `loop`, repeat until
    `stop` is set (or forever). pace_for: services (by name) never to outrun. remap: renames
    each key as published (runtime.replay_control); control: pause/step (the schedule shifts by
    the time held)."""
    if rate is not None and rate <= 0:
        raise InputError(f"replay rate {rate} must be positive (or as fast as possible)")
    if start is not None and end is not None and end < start:
        raise InputError(f"--end {end} is before --start {start}")
    event_loop = asyncio.get_running_loop()
    publishers: dict[tuple[str, str], Any] = {}
    stats = ReplayStats()
    buffer = bytearray()
    topic_list = list(topics) if topics else None
    pacer: Pacer | None = None
    if pace_for:
        from runtime.recording import inspect_recording

        recorded = [c.topic for c in inspect_recording(path).channels]
        keys = [with_robot(k, robot) if robot else k for k in recorded]
        pacer = Pacer(bus, pace_for, [remap(k) for k in keys] if remap else keys)
        await pacer.start()
    began = event_loop.time()

    def damaged(info: RecordingInfo) -> None:
        if not stats.damaged:
            stats.damaged = info.damage()
            log.warning("replaying the readable part: %s", stats.damaged)

    while True:
        t0: int | None = None
        last = 0
        pass_start = event_loop.time()
        count_before = stats.messages
        for item in read_recording(
            path, topics=topic_list, start=start, end=end, on_damage=damaged
        ):
            if stop is not None and stop.is_set():
                break
            if t0 is None:
                t0 = item.publish_time
            last = item.publish_time
            if rate is not None:
                delay = pass_start + (item.publish_time - t0) / 1e9 / rate - event_loop.time()
                if delay > 0:
                    await asyncio.sleep(delay)
            elif stats.messages % 64 == 0:
                await asyncio.sleep(0)  # let the loop breathe
            if control is not None:
                pass_start += await control.gate()
            key = with_robot(item.key, robot) if robot else item.key
            if remap is not None:
                key = remap(key)
            stamp = item.publish_time
            if pacer is not None:
                if item.cls is not None:
                    stamp = item.message().header.stamp
                await pacer.before(key, stamp)
            if item.cls is not None:
                # = item.wire(), encoded into one reused buffer (Zenoh copies it in `put`):
                # a fresh 230 kB block per camera frame costs more than the encoding.
                encoding = wire_encoding(item.cls)
                encode_into(item.message(), buffer)
                payload: bytes | bytearray = buffer
            else:
                payload, encoding = item.wire()
            pub = publishers.get((key, encoding))
            if pub is None:
                pub = publishers[(key, encoding)] = bus.raw_publisher(key, encoding)
            pub.put(payload)
            if pacer is not None:
                pacer.after(key, stamp)
            stats.messages += 1
            if on_message is not None:
                on_message(item)
        stats.passes += 1
        if t0 is not None:
            stats.span_s = max(stats.span_s, (last - t0) / 1e9)
        if not loop or (stop is not None and stop.is_set()) or stats.messages == count_before:
            break
    stats.wall_s = event_loop.time() - began
    if pacer is not None:
        pacer.stop()
        stats.held_back_s = pacer.waited_s
    for pub in publishers.values():
        pub.undeclare()
    return stats
