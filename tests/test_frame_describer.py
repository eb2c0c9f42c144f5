"""The object segmenter's frame describer: frames through shared memory, objects back.

Frames of two sizes from several callers at once each get their own frame's objects, the ones
`describe_frame` gives; a frame goes to the worker in a slot of memory both map (one per frame
under way, reused, never the pipe); a bad frame's error is the caller's; closing stops the
worker. One describer for the whole file: the worker takes a second to start.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
from pathlib import Path

import numpy as np
import pytest

from beyond_self.cognition.vision.clusters import ClusterModel
from beyond_self.cognition.vision.pipeline import describe_frame
from beyond_self.cognition.vision.tabletop import Camera, simulate_experiment
from beyond_self.core.errors import InputError
from beyond_self.services.frame_describer import FrameDescriber


def _frames(size: tuple[int, int], seed: int, n: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    exp = simulate_experiment("tap", "yellow", "circle", "big", rng, camera=Camera(*size))
    step = max(1, len(exp.frames) // n)
    return [np.asarray(f) for f in exp.frames[::step][:n]]


def _frame_slots() -> int:
    """Memory slots this process has open for the describer (memfds, by name)."""
    fds = Path("/proc/self/fd")
    names = []
    for fd in os.listdir(fds):
        with contextlib.suppress(FileNotFoundError):  # closed meanwhile by another thread
            names.append(os.readlink(fds / fd))
    return sum("beyond-frame" in name for name in names)


@pytest.mark.skipif(not hasattr(os, "memfd_create"), reason="no memfd_create on this system")
def test_frames_go_through_shared_slots_and_come_back_described() -> None:
    clusters = ClusterModel.load(None)
    small, large = _frames((320, 240), 1, 3), _frames((400, 300), 2, 3)

    async def run() -> None:
        describer = FrameDescriber(None)
        try:
            frames = small + large
            got = await asyncio.gather(*(describer.describe(f) for f in frames))
            for frame, objects in zip(frames, got, strict=True):
                expected = describe_frame(frame, clusters, require_objects=False).objects
                assert [o.labels for o in objects] == [o.labels for o in expected]
                assert [o.features for o in objects] == pytest.approx(
                    [o.features for o in expected]
                )
            assert any(got)  # the frames showed objects
            slots = _frame_slots()
            assert 1 <= slots <= len(frames)  # at most one per frame under way
            for frame in small + small:  # one at a time: the slots are reused
                await describer.describe(frame)
            assert _frame_slots() == slots
            with pytest.raises(InputError, match="16x16"):
                await describer.describe(np.zeros((8, 8, 3), np.uint8))
        finally:
            describer.close()
        assert _frame_slots() == 0

    asyncio.run(run())
