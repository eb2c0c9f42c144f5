"""The ingest's live source (a plug-in, a video, a camera; services/ingest.py): on the wall clock,
never held back; a bounded queue drops its oldest item, counted."""

from __future__ import annotations

import asyncio
import functools
from collections.abc import AsyncIterator
from typing import TYPE_CHECKING, Any, Protocol

from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.images import message_from_image
from beyond_self.runtime.recording.person import PersonFrame, person_messages
from beyond_self.schemas import CameraFrame, SkeletonFrame
from beyond_self.services.plugins import joints_of, load_plugin

if TYPE_CHECKING:
    from beyond_self.runtime.bus.publisher import Publisher
    from beyond_self.runtime.clock import Clock
    from beyond_self.schemas.base import Header, Message
    from beyond_self.services.pose_source import PoseCounts
    from beyond_self.services.sources import Source


class SensorIngest(Protocol):
    """What a live source is played into: the ingest (services.ingest.SensorIngest) is one, so
    neither module imports the other."""

    source: Source
    clock: Clock
    skeleton: Publisher[Any]
    camera: Publisher[Any]
    person_streams: dict[str, Publisher[Any]]
    pose_counts: PoseCounts | None
    dropped_items: int

    def header(self, cls: type[Message], stamp: int | None = None) -> Header: ...
    def sent(self, stream: str, stamp: int) -> None: ...


async def play_live(ingest: SensorIngest) -> None:
    """Play the ingest's live source once through: items pumped into a bounded queue (the
    oldest dropped, counted), each put on the bus as it comes."""
    source: AsyncIterator[tuple[str, Any]]
    if ingest.source.plugin is not None:
        source = load_plugin(ingest.source.plugin)()
    else:
        from beyond_self.services.pose_source import PoseSource

        pose = PoseSource(video=ingest.source.video, camera=ingest.source.camera)
        ingest.pose_counts = pose.counts
        source = aiter(pose)
    queue: asyncio.Queue[tuple[Any, ...]] = asyncio.Queue(ingest.source.queue)
    done = object()

    async def pump() -> None:
        async for item in source:
            if queue.full():  # backpressure: drop the oldest, count it
                queue.get_nowait()
                ingest.dropped_items += 1
            queue.put_nowait(item)
        await queue.put(("", done))

    task = asyncio.get_running_loop().create_task(pump())
    frame = 0
    try:
        while True:
            kind, payload, *own = await queue.get()
            if payload is done:
                break
            frame += 1
            _put(ingest, kind, payload, own, frame)
    finally:
        task.cancel()


def _put(ingest: SensorIngest, kind: str, payload: Any, own: list[int], frame: int) -> None:
    if kind == "skeleton":
        header = ingest.header(SkeletonFrame, *own)
        joints = joints_of(payload)
        ingest.skeleton.put(SkeletonFrame(header=header, frame=frame, joints=joints))
        ingest.sent("skeleton", header.stamp)
    elif kind == "camera":
        header = ingest.header(CameraFrame, *own)
        ingest.camera.put(message_from_image(header, payload))
        ingest.sent("camera", header.stamp)
    elif kind == "person" and isinstance(payload, PersonFrame):
        # one stamp: image, skeleton, pose in the image (the sensor's own if given)
        stamp = int(own[0]) if own else ingest.clock.now_ns()
        stamped = functools.partial(ingest.header, stamp=stamp)
        for stream, msg in person_messages(stamped, payload):
            ingest.person_streams[stream].put(msg)
            ingest.sent(stream, stamp)
    else:
        raise InputError(f"plug-in item kind {kind!r}; valid: skeleton, camera, person")
