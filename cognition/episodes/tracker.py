"""Gesture tracking over a skeleton stream: segmentation, streaming recognition, final belief.

Push one hand position per frame with its stamp; get back what happened at that frame: a gesture
started (from the frame the segmenter places its onset, which can be a few frames back: those
are caught up), the belief P_HMM(A | G_1^t) for each frame of the gesture, and at its end the
final belief over exactly its frames followed by the end. A started gesture is cancelled, with
the reason, when the segmenter withdraws it (not a gesture after all: see
`cognition.gestures.segmentation`), when the stream ends before it does, or when no action's
model fits it (its per-frame log-likelihood under the best model is below the models' floor,
`GestureModels.floor`): a movement nobody can classify is not described as the least bad
action. So every start is answered, by an end or a cancel.

The recogniser sees the features its models were trained on (`GestureModels.features`): the
position frame by frame, or the motion relative to the gesture's first frame, which the tracker
computes from the segmenter's smoothed positions as the gesture unfolds.

`ref` is whatever the caller wants handed back with each event (a message header): events say
which input frame they derive from, so a service can copy that frame's stamp and sequence.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Generic, TypeVar, cast

import numpy as np
from numpy.typing import ArrayLike

from beyond_self.cognition.gestures import (
    FrameResult,
    GestureModels,
    GestureSegmenter,
    Segment,
    StreamingRecognizer,
    recognize_sequence,
)
from beyond_self.cognition.gestures.features import (
    MOTION,
    MOTION_LAG,
    extract_features,
    motion_frame,
)
from beyond_self.cognition.gestures.logs import check_positions
from beyond_self.cognition.gestures.segmentation import Discarded, SegmenterConfig
from beyond_self.core.errors import InputError

R = TypeVar("R")


def hand_position(hand: ArrayLike, torso: ArrayLike | None, what: str) -> np.ndarray:
    """The tracker's input for one skeleton frame: the hand relative to the torso in body units
    (without a torso joint, the hand as given: a hand log's frames), or an InputError when it
    is not a hand's (NaN, or beyond `MAX_BODY_UNITS`). The service and `beyond analyse` both
    skip such a frame, so they answer alike."""
    x = extract_features(hand, torso)
    return cast(np.ndarray, check_positions(x, what)[0])


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
    reason: str = ""  # one line: why the gesture was withdrawn


Event = Started[R] | Belief[R] | Ended[R] | Cancelled[R]


@dataclass(frozen=True)
class _Frame(Generic[R]):
    t: int  # index in the stream
    x: np.ndarray  # the position as pushed
    smooth: np.ndarray  # after the segmenter's causal median
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
    ) -> None:
        self.models = models
        self.recognizer = StreamingRecognizer(models)
        self.segmenter = GestureSegmenter(segmenter)
        self.buffer: deque[_Frame[R]] = deque(maxlen=buffer_frames)
        self.index = 0
        self.segment_id = 0
        self.in_gesture = False
        self.last_stamp: int | None = None
        self._start = 0  # stream index of the gesture's first frame
        self._start_stamp = 0

    def push(self, stamp: int, number: int, x: np.ndarray, ref: R) -> list[Event[R]]:
        """The events at this frame (x: the hand in body units, see extract_features)."""
        if self.last_stamp is not None and stamp <= self.last_stamp:
            raise InputError(
                f"skeleton frame {number} stamped {stamp} is not after the previous frame "
                f"({self.last_stamp}); valid: frames in increasing stamp order"
            )
        outcome = self.segmenter.push(x)  # validates x before anything changes
        self.last_stamp = stamp
        item = _Frame(
            self.index,
            np.asarray(x, dtype=np.float64),
            self.segmenter.smoothed,
            stamp,
            number,
            ref,
        )
        self.index += 1
        self.buffer.append(item)
        events: list[Event[R]] = []
        if self.in_gesture:
            if isinstance(outcome, Segment):
                events += self._end(outcome)
            elif isinstance(outcome, Discarded):
                events.append(self._cancel(outcome.reason))
        start = self.segmenter.current_start
        if start is not None and not self.in_gesture:
            events += self._begin(start)
        elif self.in_gesture:
            events.append(self._belief(self.recognizer.push(self._features(item)), item))
        return events

    def finish(self) -> list[Event[R]]:
        """End of the stream: end the gesture under way, or cancel it if it is not kept."""
        if not self.in_gesture:
            return []
        outcome = self.segmenter.finish()
        if isinstance(outcome, Segment):
            return self._end(outcome)
        reason = outcome.reason if outcome is not None else "the stream ended"
        return [self._cancel(reason)]

    def _cancel(self, reason: str) -> Cancelled[R]:
        self.in_gesture = False
        last = self.buffer[-1]
        return Cancelled(self.segment_id, last.number, self._start_stamp, last.ref, reason)

    def _since(self, start: int, stop: int | None = None) -> list[_Frame[R]]:
        return [f for f in self.buffer if f.t >= start and (stop is None or f.t < stop)]

    def _features(self, item: _Frame[R]) -> np.ndarray:
        """The recogniser's input for one frame of the gesture under way."""
        if self.models.features != MOTION:
            return item.x
        first = self.buffer[0].t
        origin = self.buffer[max(self._start - first, 0)].smooth
        gap = min(item.t - first, MOTION_LAG)  # frames before the buffer are gone
        earlier = self.buffer[item.t - first - gap].smooth
        return motion_frame(item.smooth, earlier, gap, origin, item.t - self._start)

    def _belief(self, result: FrameResult, item: _Frame[R], final: bool = False) -> Belief[R]:
        return Belief(self.segment_id, item.number, item.stamp, item.ref, result, final)

    def _begin(self, start: int) -> list[Event[R]]:
        frames = self._since(start) or [self.buffer[-1]]
        self.segment_id += 1
        self.in_gesture = True
        first = frames[0]
        self._start = first.t
        self._start_stamp = first.stamp
        events: list[Event[R]] = [Started(self.segment_id, first.number, first.stamp, first.ref)]
        self.recognizer.reset()
        events += [self._belief(self.recognizer.push(self._features(f)), f) for f in frames]
        return events

    def _end(self, segment: Segment) -> list[Event[R]]:
        frames = self._since(segment.start, segment.stop)
        if not frames:
            return [self._cancel("its frames are no longer buffered")]
        features = np.stack([self._features(f) for f in frames])
        result = recognize_sequence(self.models, features).final
        floor = self.models.floor
        if floor is not None and float(np.max(result.normalized)) < floor:
            best = float(np.max(result.normalized))
            return [
                self._cancel(
                    f"no action fits it (best {result.best}, log-likelihood {best:.1f} per "
                    f"frame, the models' floor {floor:.1f})"
                )
            ]
        self.in_gesture = False
        last = frames[-1]
        return [
            self._belief(result, last, final=True),
            Ended(self.segment_id, last.number, frames[0].stamp, last.stamp, last.ref),
        ]
