"""Run as a script (tests/test_tutorial_exercise.py): the object segmenter of the package on the
import path, on a private bus, given the first camera frame of a recording; prints the first
object of its `DetectedObjects` as JSON."""

from __future__ import annotations

import asyncio
import json
import os
import sys

import msgspec

from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.clock import Clock
from beyond_self.runtime.recording.reader import read_recording
from beyond_self.schemas import CompressedCameraFrame, DetectedObjects
from beyond_self.services.objects import ObjectSegmenter


async def probe(recording: str, robot: str, port: int) -> dict[str, object]:
    frame = next(
        m.message()
        for m in read_recording(recording)
        if m.cls is CompressedCameraFrame and m.key.endswith("/camera/compressed")
    )
    with Bus.open(BusConfig(robot=robot, port=port)) as bus:
        segmenter = ObjectSegmenter(bus=bus, clock=Clock("recording"), skip_frames=False)
        task = asyncio.create_task(segmenter.run(install_signals=False))
        await asyncio.wait_for(segmenter.started.wait(), 60)
        found = bus.subscribe(bus.keys.objects, DetectedObjects)
        camera = bus.publisher(bus.keys.camera_compressed, CompressedCameraFrame)
        await camera.wait_matching(timeout=20)
        camera.put(frame)  # type: ignore[arg-type]
        received = await asyncio.wait_for(anext(aiter(found)), 120)
        segmenter.stop()
        await asyncio.wait_for(task, 30)
    return msgspec.to_builtins(received.message.objects[0])  # type: ignore[no-any-return]


if __name__ == "__main__":
    print(json.dumps(asyncio.run(probe(sys.argv[1], sys.argv[2], int(sys.argv[3])))), flush=True)
    # past the interpreter's teardown of Zenoh's threads, which can abort a process that
    # finished (as Service.main leaves, runtime/README.md)
    os._exit(0)
