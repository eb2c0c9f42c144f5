"""What a fleet workstation's `beyond up` counts: the gestures of the robots it serves.

Its own robot name (`--robot ws-1`) has no gestures; the robots `--robots`/`--standby` name do,
each on its own keys. The tally subscribes to their segments, descriptions and health and counts
per robot, by identity (a message received twice, from a cache, counts once): which gestures
started, which have a final description, which were cut (their frames lost), and the sensor
frames each robot's services dropped as stale.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from beyond_self.runtime.bus.delivery import FRAMES, RELIABLE
from beyond_self.runtime.bus.session import Bus
from beyond_self.schemas import Description, GestureSegment, ServiceHealth
from beyond_self.schemas.keys import for_robots, split_key

log = logging.getLogger("beyond.monitor")


@dataclass
class RobotCount:
    started: set[int] = field(default_factory=set)  # gestures started and not withdrawn
    described: set[int] = field(default_factory=set)  # with a final description
    cut: dict[int, str] = field(default_factory=dict)  # lost: why
    stale: dict[tuple[str, int], int] = field(default_factory=dict)  # (service, restarts)

    def on_segment(self, msg: GestureSegment) -> None:
        if msg.event == "start":
            self.started.add(msg.segment_id)
        elif msg.event == "cancel":
            self.started.discard(msg.segment_id)
            if msg.cut:
                self.cut[msg.segment_id] = msg.reason

    def on_description(self, msg: Description) -> None:
        if msg.final and msg.sentences:
            self.described.add(msg.segment_id)

    def on_health(self, msg: ServiceHealth) -> None:
        if msg.stale:
            instance = (msg.service, msg.restarts)
            self.stale[instance] = max(self.stale.get(instance, 0), msg.stale)

    @property
    def gestures(self) -> int:
        return len((self.started | self.described) - set(self.cut)) + len(self.cut)


class FleetTally:
    """Per robot of `patterns` (schemas.keys.robot_pattern's), what `RobotCount` keeps."""

    def __init__(self, bus: Bus, patterns: list[str]) -> None:
        self.bus, self.patterns = bus, patterns
        self.robots: dict[str, RobotCount] = {}
        self._tasks: list[asyncio.Task[None]] = []

    def start(self) -> None:
        keys = self.bus.keys
        streams: list[tuple[str, type[Any], Callable[[RobotCount, Any], None]]] = [
            (keys.gesture_segment, GestureSegment, RobotCount.on_segment),
            (keys.description, Description, RobotCount.on_description),
            (keys.health(), ServiceHealth, RobotCount.on_health),
        ]
        loop = asyncio.get_running_loop()
        for pattern in self.patterns:
            for key, cls, handler in streams:
                delivery = RELIABLE if cls is ServiceHealth else FRAMES
                sub = self.bus.subscribe(for_robots(pattern, key), cls, delivery)
                self._tasks.append(loop.create_task(self._count(sub, handler)))

    async def _count(self, sub: Any, handler: Callable[[RobotCount, Any], None]) -> None:
        async for received in sub:
            where = split_key(received.key)
            if where is None:
                continue
            try:
                handler(self.robots.setdefault(where[0], RobotCount()), received.message)
            except Exception as exc:  # one bad message must not stop the count
                log.warning("could not count a message on %s: %s", received.key, exc)

    async def last_health(self, timeout: float) -> None:
        """Every robot's services' health, asked once more (the summary's stale counts)."""
        for pattern in self.patterns:
            selector = for_robots(pattern, self.bus.keys.health())
            try:
                replies = await self.bus.query(selector, ServiceHealth, timeout=timeout, every=True)
            except Exception as exc:  # the periodic reports still count
                log.warning("could not ask the robots' services for their health: %s", exc)
                continue
            for reply in replies:
                if (where := split_key(reply.key)) is not None:
                    self.robots.setdefault(where[0], RobotCount()).on_health(reply.message)

    def stop(self) -> None:
        for task in self._tasks:
            task.cancel()

    def counts(self) -> tuple[int, int]:
        """(described, gestures) over every robot."""
        robots = self.robots.values()
        return sum(len(r.described) for r in robots), sum(r.gestures for r in robots)

    def cut(self) -> list[tuple[str, str]]:
        """("lab-1 gesture 2", why) of each gesture cut, by robot and gesture."""
        return [
            (f"{name} gesture {n}", self.robots[name].cut[n])
            for name in sorted(self.robots)
            for n in sorted(self.robots[name].cut)
        ]

    def stale(self) -> dict[str, int]:
        """Sensor frames dropped as stale, per "robot service"."""
        by: dict[str, int] = {}
        for name, robot in self.robots.items():
            for (service, _), count in robot.stale.items():
                by[f"{name} {service}"] = by.get(f"{name} {service}", 0) + count
        return by

    def per_robot(self) -> str:
        """ "lab-1 2 of 2, lab-2 1 of 2": each robot that showed a gesture."""
        shown = sorted(((n, r) for n, r in self.robots.items() if r.gestures), key=lambda x: x[0])
        return ", ".join(f"{n} {len(r.described)} of {r.gestures}" for n, r in shown)
