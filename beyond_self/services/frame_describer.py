"""The object segmenter's per-frame description, in a process of its own.

Describing a frame (the table estimated from it, every object measured and labelled) is the
object segmenter's costliest work, and no gesture result waits for it. On a thread it shared the
GIL with the gestures' work, so the frame that completes a gesture waited behind it; in a process
of its own, at a lower priority when the source is live, the system runs the gestures' work first
and a live segmenter skips the frames nothing was left for. A replay's describer keeps its
priority: every frame is described. The worker dies with the segmenter
(runtime.process.lifeline).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import multiprocessing
import os

import numpy as np

from beyond_self.cognition.vision.clusters import ClusterModel
from beyond_self.cognition.vision.pipeline import DetectedObject, describe_frame
from beyond_self.runtime.process import lifeline

_clusters: ClusterModel | None = None  # the worker's own copy, loaded once


class FrameDescriber:
    """`await describe(image)`: the frame's labelled objects, computed in the worker process."""

    def __init__(self, clusters: str | None, niceness: int = 0) -> None:
        context = multiprocessing.get_context("spawn")  # nothing of ours (a Zenoh session) forked
        parent = lifeline.child_env()[lifeline.ENV]  # submit() below starts it from this thread
        self._pool = concurrent.futures.ProcessPoolExecutor(
            1, mp_context=context, initializer=_start, initargs=(clusters, niceness, parent)
        )
        self._pool.submit(_ready)  # start it now, not at the first frame

    async def describe(self, image: np.ndarray) -> list[DetectedObject]:
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._pool, _describe, image)

    def close(self) -> None:
        """Stop the worker and wait for it (at most the frame it is on): a pool left to the
        interpreter's exit kept its queues' semaphores, and every `beyond demo` ended with
        multiprocessing's "leaked semaphore objects" warning from the object segmenter."""
        self._pool.shutdown(wait=True, cancel_futures=True)


def _start(clusters: str | None, niceness: int, parent: str) -> None:
    global _clusters
    lifeline.bind({lifeline.ENV: parent})
    from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

    threadpool_limits(limits=1, user_api="blas")
    if niceness:
        os.nice(niceness)
    _clusters = ClusterModel.load(clusters)


def _ready() -> bool:
    return _clusters is not None


def _describe(image: np.ndarray) -> list[DetectedObject]:
    assert _clusters is not None, "the worker's initializer loads the clusters"
    return describe_frame(image, _clusters, require_objects=False).objects
