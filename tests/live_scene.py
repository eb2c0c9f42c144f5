"""A live source plug-in for tests (`beyond up --live-source live_scene:scene`): a recording's
skeleton and camera frames delivered at real time, as a tracker and a camera deliver them,
played one or more times with a silence in between.

The ingest stamps each item with its own clock when it takes it, as it does for a real sensor, so
the run is a live one (a replay would reuse the recording's stamps). Set by the environment:
`BEYOND_TEST_SCENE` (the recording), `BEYOND_TEST_PASSES` (how many times it is played, 1 by
default) and `BEYOND_TEST_PAUSE` (seconds the sensors are silent between two passes, 0 by
default).
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import AsyncIterator
from typing import Any

import beyond_self.schemas as s
from beyond_self.runtime.recording.images import image_from_message
from beyond_self.runtime.recording.reader import read_recording


async def scene() -> AsyncIterator[tuple[str, Any]]:
    items = [item.message() for item in read_recording(os.environ["BEYOND_TEST_SCENE"])]
    passes = int(os.environ.get("BEYOND_TEST_PASSES", "1"))
    pause_s = float(os.environ.get("BEYOND_TEST_PAUSE", "0"))
    loop = asyncio.get_running_loop()
    first = items[0].header.stamp
    for n in range(passes):
        if n:
            await asyncio.sleep(pause_s)  # the sensors fall silent
        began = loop.time()
        for msg in items:
            await asyncio.sleep(max(0.0, began + (msg.header.stamp - first) / 1e9 - loop.time()))
            if isinstance(msg, s.SkeletonFrame):
                yield "skeleton", {name: joint.position for name, joint in msg.joints.items()}
            elif isinstance(msg, s.CameraFrame | s.CompressedCameraFrame):
                yield "camera", image_from_message(msg)
