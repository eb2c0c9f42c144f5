"""Gesture tracking over a skeleton stream: segmentation, streaming recognition, final belief.

Push one hand position per frame with its stamp; get back what happened at that frame: a gesture
started (from the frame the segmenter places its onset, which can be a few frames back: those
are caught up), the belief P_HMM(A | G_1^t) for each frame of the gesture, and at its end the
final belief over exactly its frames followed by the end. `finish()` at the end of the stream
ends a gesture under way, or cancels it when the segmenter would not keep it (the hand never
came back), so every start is answered.

`ref` is whatever the caller wants handed back with each event (a message header): events say
which input frame they derive from, so a service can copy that frame's stamp and sequence.

The final belief is the streaming recogniser's own at the gesture's last frame (it has run over
exactly the gesture's frames since its start), so a gesture's end costs nothing more than a
frame; it is recomputed over the gesture's frames only when the segmenter's segment is not the
one the recogniser followed.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np

from beyond_self.cognition.gestures import (
    FrameResult,
    GestureModels,
    GestureSegmenter,
    Segment,
    StreamingRecognizer,
    recognize_sequence,
)
from beyond_self.cognition.gestures.segmentation import SegmenterConfig

R = TypeVar("R")


@dataclass(frozen=True)
class Started(Generic[R]):
    segment_id: int
    frame: int
    stamp: int
    ref: R


@dataclass(frozen=True)
class Belief(Generic[R]):
    segment_id: int
    frame: int
    stamp: int
    ref: R
    result: FrameResult
    final: bool = False

    @property
    def posterior(self) -> list[float]:
        """P_HMM(A | G_1^t) as published (normalised once more against rounding drift)."""
        p = self.result.posterior
        return [float(v) for v in p / p.sum()]


@dataclass(frozen=True)
class Ended(Generic[R]):
    segment_id: int
    frame: int
    start_stamp: int
    end_stamp: int
    ref: R


@dataclass(frozen=True)
class Cancelled(Generic[R]):
    segment_id: int
    frame: int
    start_stamp: int
    ref: R


Event = Started[R] | Belief[R] | Ended[R] | Cancelled[R]


@dataclass(frozen=True)
class _Frame(Generic[R]):
    t: int  # index in the stream
    x: np.ndarray
    stamp: int
    number: int
    ref: R


class GestureTracker(Generic[R]):
    """Segments and recognises gestures one frame at a time. Frames must come in stamp order;
    segment ids count from 1 in the order gestures start."""

    def __init__(
        self,
        models: GestureModels,
        segmenter: SegmenterConfig | None = None,
        buffer_frames: int = 1800,
        first_segment_id: int = 0,
    ) -> None:
        self.models = models
        self.recognizer = StreamingRecognizer(models)
        self.segmenter = GestureSegmenter(segmenter)
        self.buffer: deque[_Frame[R]] = deque(maxlen=buffer_frames)
        self.index = 0
        self.segment_id = first_segment_id  # segments started before this tracker's first frame
        self.in_gesture = False
        self.last_stamp: int | None = None
        self._segmenter_start: int | None = None
        self._start_stamp = 0
        self._results: list[FrameResult] = []  # the recogniser's, frame by frame since the start
        self._results_from = -1  # stream index of the frame the first of them is about
        self.checkpoint: tuple[int, int] | None = None  # (stamp, segment_id): see `_advance`
        self._quiet: deque[int] = deque(maxlen=self.memory_frames + 1)  # stamps

    @property
    def memory_frames(self) -> int:
        """Frames after which the segmenter no longer depends on what came before them, while
        no gesture is under way: its median and speed windows, and how far back it may place a
        gesture's start (cognition.gestures.segmentation)."""
        cfg = self.segmenter.config
        return cfg.max_lead + cfg.median_frames + cfg.speed_frames + 1

    def _advance(self, stamp: int, z: float, eventful: bool) -> None:
        """Move the checkpoint: a frame from which a fresh tracker (`first_segment_id` the
        segments started before it), fed this tracker's frames from that one on, makes exactly
        the events this one makes from there on. The first frame is one. So is a frame opening
        `memory_frames` + 1 frames with no gesture under way, no event, and the hand behind the
        reach threshold (raw, so that the fresh tracker's first, shorter medians cannot cross it):
        neither tracker can start a gesture on them, and after them their states agree. A
        speed-only segmenter (no reach threshold) has no checkpoint but the first frame.
        A restarted gesture streamer resumes from it (services/gestures.py)."""
        if self.checkpoint is None:
            self.checkpoint = (stamp, self.segment_id)
        reach = self.segmenter.config.reach_on
        if reach is None or eventful or self.in_gesture or self.segmenter.active or z < reach:
            self._quiet.clear()
            return
        self._quiet.append(stamp)
        if len(self._quiet) == self._quiet.maxlen:
            self.checkpoint = (self._quiet[0], self.segment_id)

    def push(self, stamp: int, number: int, x: np.ndarray, ref: R) -> list[Event[R]]:
        """The events at this frame (x: the hand in feature space, see extract_features)."""
        if self.last_stamp is not None and stamp <= self.last_stamp:
            from beyond_self.core.errors import InputError

            raise InputError(
                f"skeleton frame {number} stamped {stamp} is not after the previous frame "
                f"({self.last_stamp}); valid: frames in increasing stamp order"
            )
        ended = self.segmenter.push(x)  # validates x before anything changes
        self.last_stamp = stamp
        item = _Frame(self.index, np.asarray(x, dtype=np.float64), stamp, number, ref)
        self.index += 1
        self.buffer.append(item)
        events: list[Event[R]] = []
        if self.in_gesture:
            if ended is not None:
                events += self._end(ended)
            elif self.segmenter.current_start != self._segmenter_start:
                events.append(self._cancel())  # discarded by the segmenter (too short)
        start = self.segmenter.current_start
        if start is not None and not self.in_gesture:
            events += self._begin(start)
        elif self.in_gesture:
            events.append(self._belief(self._recognise(item.x), item))
        self._advance(stamp, float(item.x[2]), bool(events))
        return events

    def _recognise(self, x: np.ndarray) -> FrameResult:
        result = self.recognizer.push(x)
        self._results.append(result)
        return result

    def finish(self) -> list[Event[R]]:
        """End of the stream: end the gesture under way, or cancel it if it is not kept."""
        if not self.in_gesture:
            return []
        segment = self.segmenter.finish()
        if segment is not None:
            return self._end(segment)
        return [self._cancel()]

    def _cancel(self) -> Cancelled[R]:
        self.in_gesture = False
        last = self.buffer[-1]
        return Cancelled(self.segment_id, last.number, self._start_stamp, last.ref)

    def _since(self, start: int, stop: int | None = None) -> list[_Frame[R]]:
        return [f for f in self.buffer if f.t >= start and (stop is None or f.t < stop)]

    def _belief(self, result: FrameResult, item: _Frame[R], final: bool = False) -> Belief[R]:
        return Belief(self.segment_id, item.number, item.stamp, item.ref, result, final)

    def _begin(self, start: int) -> list[Event[R]]:
        frames = self._since(start) or [self.buffer[-1]]
        self.segment_id += 1
        self.in_gesture = True
        self._segmenter_start = start
        first = frames[0]
        self._start_stamp = first.stamp
        events: list[Event[R]] = [Started(self.segment_id, first.number, first.stamp, first.ref)]
        self.recognizer.reset()
        self._results, self._results_from = [], first.t
        events += [self._belief(self._recognise(f.x), f) for f in frames]
        return events

    def _end(self, segment: Segment) -> list[Event[R]]:
        frames = self._since(segment.start, segment.stop)
        self.in_gesture = False
        if not frames:
            last = self.buffer[-1]
            return [Cancelled(self.segment_id, last.number, last.stamp, last.ref)]
        n = segment.stop - segment.start
        if segment.start == self._results_from and len(frames) == n <= len(self._results):
            result = self._results[n - 1]  # over exactly the gesture's frames already
        else:
            result = recognize_sequence(self.models, np.stack([f.x for f in frames])).final
        last = frames[-1]
        return [
            self._belief(result, last, final=True),
            Ended(self.segment_id, last.number, frames[0].stamp, last.stamp, last.ref),
        ]
