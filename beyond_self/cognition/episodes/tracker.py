"""Gesture tracking over a skeleton stream: segmentation, streaming recognition, final belief.

Push one hand position per frame with its stamp; get back what happened: a gesture started (at
the onset the segmenter places, a few frames back, caught up), the belief P_HMM(A | G_1^t) for
each frame, and at its end the final belief then the end. Every start is answered by an end or a
cancel with the reason: the segmenter withdrew it, the stream ended first, or no action's model
fits it (below `GestureModels.floor`): a movement nobody can classify is not described as the
least bad action. `ref` (a message header) is handed back with each event, so a service can copy
that frame's stamp. The final belief is the streaming recogniser's own at the last frame, so an
end costs one frame.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Generic, TypeVar, cast

import msgspec
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
    point_features,
)
from beyond_self.cognition.gestures.logs import MAX_BODY_UNITS, check_positions
from beyond_self.cognition.gestures.segmentation import Discarded, SegmenterConfig
from beyond_self.core.errors import InputError
from beyond_self.core.restorable import Restorable

R = TypeVar("R")


def hand_position(hand: ArrayLike, torso: ArrayLike | None, what: str) -> np.ndarray:
    """The tracker's input for one skeleton frame: the hand relative to the torso in body units
    (without a torso joint, the hand as given: a hand log's frames), or an InputError when it
    is not a hand's (NaN, or beyond `MAX_BODY_UNITS`). The service and `beyond analyse` both
    skip such a frame, so they answer alike."""
    point = point_features(hand, torso)
    if point is not None and max(map(abs, point)) <= MAX_BODY_UNITS:
        return np.array(point)
    x = extract_features(hand, torso)  # says what is wrong with it
    return cast(np.ndarray, check_positions(x, what)[0])


@dataclass(frozen=True)
class Started(Generic[R]):
    segment_id: int
    frame: int
    stamp: int
    ref: R
    seq: int = 0  # the tracker's running count of start, end and cancel events (`events`)


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
        # plain floats: a tenth of numpy's cost per frame, and the same numbers (numpy sums
        # fewer than eight values in order, as `sum` does)
        p = self.result.posterior.tolist()
        total = sum(p)
        return [v / total for v in p]


@dataclass(frozen=True)
class Ended(Generic[R]):
    segment_id: int
    frame: int
    start_stamp: int
    end_stamp: int
    ref: R
    seq: int = 0  # as `Started.seq`


@dataclass(frozen=True)
class Cancelled(Generic[R]):
    segment_id: int
    frame: int
    start_stamp: int
    ref: R
    reason: str = ""  # one line: why the gesture was withdrawn
    cut: bool = False  # it was a gesture, but its frames are gone: a loss, not a withdrawal
    seq: int = 0  # as `Started.seq`


Event = Started[R] | Belief[R] | Ended[R] | Cancelled[R]


@dataclass(frozen=True)
class _Candidate:
    """A frame on trial as the next checkpoint (`GestureTracker._advance`)."""

    at: TrackerSnapshot  # the snapshot it would be
    index: int  # the tracker's frame count when it was taken
    shadow: GestureSegmenter  # a fresh segmenter fed from that frame on


class _Frame(msgspec.Struct, Generic[R], frozen=True, gc=False):
    """One frame kept for the gesture under way and the motion features' look-back.

    Not tracked by the garbage collector (`gc=False`): a tracker keeps `buffer_frames` of them
    (1,800 by default) for as long as it runs, and a fleet's gesture streamer keeps a tracker per
    robot, so as tracked objects they were most of what every full collection walked (87,000 of
    107,000 at 64 robots, 60-90 ms pauses of the streamer's loop). A frame holds arrays, numbers
    and the caller's reference, never a tracker, so it can be part of no reference cycle."""

    t: int  # index in the stream
    x: np.ndarray  # the position as pushed
    smooth: np.ndarray  # after the segmenter's causal median
    stamp: int
    number: int
    ref: R


class TrackerSnapshot(Restorable, frozen=True):
    """What a tracker is rebuilt from (`GestureTracker.snapshot`, `restored`): a skeleton stamp
    from which a fresh tracker, fed the frames from there on, makes exactly the events this one
    makes (its checkpoint, `GestureTracker._advance`), the segments started before it, and the
    events (`Started`, `Ended`, `Cancelled`) made before it, so that their count runs on. The
    state is empty at that stamp, so a snapshot is a few bytes."""

    events: int


class GestureTracker(Generic[R]):
    """Segments and recognises gestures one frame at a time. Frames must come in stamp order;
    segment ids count from 1 in the order gestures start."""

    def __init__(
        self,
        models: GestureModels,
        segmenter: SegmenterConfig | None = None,
        buffer_frames: int = 1800,
        first_segment_id: int = 0,
        first_events: int = 0,
    ) -> None:
        self.models = models
        self.recognizer = StreamingRecognizer(models)
        self.segmenter = GestureSegmenter(segmenter)
        self.buffer: deque[_Frame[R]] = deque(maxlen=buffer_frames)
        self.index = 0
        self.segment_id = first_segment_id  # segments started before this tracker's first frame
        self.events = first_events  # start, end and cancel events made (`Started.seq`)
        self.in_gesture = False
        self.last_stamp: int | None = None
        self._start = 0  # stream index of the gesture's first frame
        self._start_stamp = 0
        self._results: list[FrameResult] = []  # the recogniser's, frame by frame since the start
        self._results_from = -1  # stream index of the frame the first of them is about
        self.checkpoint: TrackerSnapshot | None = None  # see `_advance`
        self._candidate: _Candidate | None = None

    def snapshot(self) -> TrackerSnapshot | None:
        """The newest snapshot (None before the first frame)."""
        return self.checkpoint

    @classmethod
    def restored(
        cls, models: GestureModels, snapshot: TrackerSnapshot | None, buffer_frames: int = 1800
    ) -> GestureTracker[R]:
        """A tracker to be fed the frames from `snapshot.stamp` on (None: from the first)."""
        if snapshot is None:
            return cls(models, buffer_frames=buffer_frames)
        return cls(models, None, buffer_frames, snapshot.gestures, snapshot.events)

    def frames_lost(
        self, under_way: set[int], numbered: int, frame: int, since: int, ref: R, reason: str
    ) -> list[Cancelled[R]]:
        """The frames from stamp `since` up to this frame (number `frame`) are gone: the
        gestures `under_way` elsewhere (started, not closed) cannot be derived again, and are
        cancelled as cut; segments number on after `numbered`, the last one started elsewhere."""
        self.segment_id = max(self.segment_id, numbered)
        return [
            Cancelled(n, frame, since, ref, reason, cut=True, seq=self._numbered())
            for n in sorted(under_way)
        ]

    def _numbered(self) -> int:
        """The next event's `seq`."""
        self.events += 1
        return self.events

    @property
    def memory_frames(self) -> int:
        """Frames a checkpoint must stay quiet for: the segmenter's median and history windows
        (a start may be placed `max_lead` frames back) and the motion features' lag."""
        cfg = self.segmenter.config
        return cfg.median_frames + max(cfg.rest_frames, cfg.max_lead + 1) + MOTION_LAG

    def _advance(self, stamp: int, x: np.ndarray, eventful: bool) -> None:
        """Move the checkpoint: a frame from which a fresh tracker (`first_segment_id` the
        segments started before it), fed this tracker's frames from that one on, makes exactly
        the events this one makes from there on. The first frame is one. Later, a frame is one
        once it is proven: a shadow segmenter started on it, fed the same frames, has stayed
        idle with this one (no gesture under way, no event) for `memory_frames` frames and is
        now in the same state (its window, rest pose, jump count), so from here both run alike.
        Proving rather than bounding keeps the checkpoint exact whatever the segmenter's
        thresholds. A restarted gesture streamer resumes from it (services/gestures.py)."""
        if self.checkpoint is None:
            self.checkpoint = TrackerSnapshot(stamp, self.segment_id, self.events)
        if eventful or self.in_gesture or not self.segmenter.idle:
            self._candidate = None
            return
        if self._candidate is None:
            shadow = GestureSegmenter(self.segmenter.config)
            at = TrackerSnapshot(stamp, self.segment_id, self.events)
            self._candidate = _Candidate(at, self.index, shadow)
        candidate = self._candidate
        if candidate.shadow.push(x) is not None or not candidate.shadow.idle:
            self._candidate = None  # a fresh tracker would have started a gesture here
            return
        quiet = self.index - candidate.index
        if quiet >= self.memory_frames and candidate.shadow.course() == self.segmenter.course():
            self.checkpoint = candidate.at
            self._candidate = None

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
            events.append(self._belief(self._recognise(self._features(item)), item))
        self._advance(stamp, item.x, bool(events))
        return events

    def _recognise(self, x: np.ndarray) -> FrameResult:
        result = self.recognizer.push(x)
        self._results.append(result)
        return result

    def finish(self) -> list[Event[R]]:
        """End of the stream: end the gesture under way, or cancel it if it is not kept."""
        if not self.in_gesture:
            return []
        outcome = self.segmenter.finish()
        if isinstance(outcome, Segment):
            return self._end(outcome)
        reason = outcome.reason if outcome is not None else "the stream ended"
        return [self._cancel(reason)]

    def _cancel(self, reason: str, *, cut: bool = False) -> Cancelled[R]:
        self.in_gesture = False
        last = self.buffer[-1]
        return Cancelled(
            self.segment_id, last.number, self._start_stamp, last.ref, reason, cut, self._numbered()
        )

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
        started = Started(self.segment_id, first.number, first.stamp, first.ref, self._numbered())
        events: list[Event[R]] = [started]
        self.recognizer.reset()
        self._results, self._results_from = [], first.t
        events += [self._belief(self._recognise(self._features(f)), f) for f in frames]
        return events

    def _end(self, segment: Segment) -> list[Event[R]]:
        frames = self._since(segment.start, segment.stop)
        if not frames:
            return [self._cancel("its frames are no longer buffered", cut=True)]
        n = segment.stop - segment.start
        if segment.start == self._results_from and len(frames) == n <= len(self._results):
            result = self._results[n - 1]  # over exactly the gesture's frames already
        else:
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
            Ended(
                self.segment_id,
                last.number,
                frames[0].stamp,
                last.stamp,
                last.ref,
                self._numbered(),
            ),
        ]
