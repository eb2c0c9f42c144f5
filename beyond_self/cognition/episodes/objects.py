"""What the camera says about each gesture: the object it is about and the effects on it.

Per gesture, exactly once: the object acted on as seen when it began (`ObjectAtStart`) and the
effects over its own frames (`GestureEffects`), measured or with the reason why not. Apart, per
frame: its labelled objects (`frame_objects`), the costliest step, which a live source may skip
without changing any per-gesture result. Each decision waits for proof in stamp order (a frame at
or after the instant, the camera's end, or a camera silent while the skeleton moved `deadline_s`
on), never for the wall clock; memory is bounded by counts and bytes, never by the distance
between stamps. More: docs/concepts/pipeline.md, "Event time".
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Generic, TypeVar

import numpy as np

from beyond_self.cognition.vision.clusters import ClusterModel
from beyond_self.cognition.vision.pipeline import (
    DetectedObject,
    RecordingAnalyser,
    RecordingAnalysis,
    describe_frame,
)
from beyond_self.core.errors import InputError
from beyond_self.core.restorable import Restorable

R = TypeVar("R")
EFFECT_VARIABLES = ("ObjVel", "HandVel", "ObjHandVel", "Contact")
MIN_WINDOW_FRAMES = 3
FPS_FRAMES = 4  # frames of a gesture's window its frame rate is measured on
EVICTED_KEPT = 16  # dropped frames nobody described, kept for a start that looks back to them
# frames up to the complete skeleton time kept for a start still to be announced: the default
# onset_s + lead_s at 30 fps, counted so that a pause in the stamps does not shorten it
LOOK_BACK_FRAMES = 72


@dataclass(frozen=True)
class FrameObjects(Generic[R]):
    stamp: int
    frame: int
    ref: R
    objects: list[DetectedObject]


@dataclass(frozen=True)
class ObjectAtStart(Generic[R]):
    segment_id: int
    frame: int  # camera frame the labels come from, 0 if none
    labels: dict[str, str]
    reason: str
    ref: R  # of the gesture's start event


@dataclass(frozen=True)
class GestureEffects(Generic[R]):
    segment_id: int
    frame: int  # the gesture's last skeleton frame
    analysis: RecordingAnalysis | None
    reason: str  # why not measured, when analysis is None
    ref: R  # of the gesture's end event

    @property
    def effect_labels(self) -> dict[str, str]:
        labels = self.analysis.labels if self.analysis else {}
        return {k: v for k, v in labels.items() if k in EFFECT_VARIABLES}

    @property
    def object_labels(self) -> dict[str, str]:
        labels = self.analysis.labels if self.analysis else {}
        return {k: v for k, v in labels.items() if k not in EFFECT_VARIABLES}


Output = ObjectAtStart[R] | GestureEffects[R]


class WatchSnapshot(Restorable, frozen=True):
    """What an object watch is rebuilt from (`ObjectWatch.snapshot`, `resume`): its restart
    point, the first camera stamp it needs again, and the gestures started by then."""


@dataclass
class _Buffered:
    stamp: int
    frame: int
    image: np.ndarray
    objects: list[DetectedObject] | None = None  # None until described

    @property
    def labels(self) -> dict[str, str]:
        """Labels of the biggest object (empty when none); the frame must be described."""
        assert self.objects is not None
        biggest = max(self.objects, key=lambda o: o.features.area, default=None)
        return dict(biggest.labels) if biggest else {}


@dataclass
class _Window(Generic[R]):
    segment_id: int
    start_stamp: int
    lo: int  # first stamp of the window (start - lead)
    start_ref: R
    pending: deque[_Buffered] = field(default_factory=deque)  # its frames not yet taken in
    stamps: list[int] = field(default_factory=list)  # of the frames taken in
    early: deque[np.ndarray] = field(default_factory=deque)  # taken in, not yet analysed
    analyser: RecordingAnalyser | None = None
    object_decided: bool = False
    end: tuple[int, int, R] | None = None  # (end stamp, end frame, ref) once ended
    opened_at: int = 0  # camera frames handled when it opened


class ObjectWatch(Generic[R]):
    """Camera frames and gesture events in, per-gesture results out; per-frame objects on request.

    lead_s: the window of a gesture opens this long before its first frame (the hand approaching
    shows in the camera before the skeleton segmenter calls it a gesture). fps: the camera's rate,
    or None to measure it on each window's first frames. onset_s: how far back of the skeleton
    the gesture segmenter may place an onset. buffer_bytes: the cap on camera history kept."""

    def __init__(
        self,
        clusters: ClusterModel,
        *,
        lead_s: float = 0.3,
        fps: float | None = None,
        deadline_s: float = 5.0,
        onset_s: float = 2.0,
        buffer_bytes: int = 160 * 2**20,
        max_open: int = 8,
        max_gesture_frames: int = 1800,
    ) -> None:
        for name, value in (("lead_s", lead_s), ("deadline_s", deadline_s), ("onset_s", onset_s)):
            if not np.isfinite(value) or value < 0:
                raise InputError(f"{name} {value} must be a finite number >= 0")
        if fps is not None and (not np.isfinite(fps) or fps <= 0):
            raise InputError(f"fps {fps} must be positive (or unset: measured)")
        self.clusters = clusters
        self.lead_ns = round(lead_s * 1e9)
        self.deadline_ns = round(deadline_s * 1e9)
        self.onset_ns = round(onset_s * 1e9)
        self.max_open = max_open
        self.max_gesture_frames = max_gesture_frames
        self.abandoned = 0  # gestures dropped: not ended within max_gesture_frames
        self.frames_handled = 0  # camera frames handled: what an open gesture's age counts
        self.complete_until = -1  # gesture events are complete up to this skeleton stamp
        self.evicted_early = 0  # frames the byte cap dropped while a gesture could need them
        # the last dropped frame known to show an object, and the frames dropped after it that
        # nobody described (a later start may look back to them)
        self._last_evicted: tuple[int, int, dict[str, str]] | None = None
        self._evicted_unknown: list[_Buffered] = []
        self.buffer_bytes = buffer_bytes
        self.fps = fps
        self.buffer: deque[_Buffered] = deque()
        self._by_stamp: dict[int, _Buffered] = {}
        self._buffered_bytes = 0
        self.watermark = -1  # stamp of the last camera frame handled
        self.camera_last: int | None = None  # last camera stamp, from the stream's end marker
        self.camera_done = False
        self.skeleton_time = -1
        self.windows: dict[int, _Window[R]] = {}
        self.told: deque[int] = deque(maxlen=4096)  # gestures told elsewhere (`done`)
        self.gestures_started = 0  # the highest gesture id started (`snapshot`)

    def snapshot(self) -> WatchSnapshot:
        """Where a fresh watch takes over from this one (`restart_point`, from 0), and the
        gestures started by now: restored with `resume`."""
        return WatchSnapshot(max(0, self.restart_point), self.gestures_started)

    def resume(self, snapshot: WatchSnapshot | None) -> None:
        """Go on from `snapshot` (None: from the first frame): fed the camera frames from its
        stamp on, and the gesture events and progress again."""
        self.gestures_started = snapshot.gestures if snapshot is not None else 0

    # -- inputs ---------------------------------------------------------------------------

    def camera(self, stamp: int, frame: int, image: np.ndarray) -> list[Output[R]]:
        """One camera frame, for the gestures: kept, queued for the windows of the gestures
        under way, and the results it completes. Its own objects: `frame_objects`."""
        if stamp <= self.watermark:
            raise InputError(
                f"camera frame {frame} stamped {stamp} is not after the last one handled "
                f"({self.watermark}); valid: frames in increasing stamp order"
            )
        item = _Buffered(stamp, frame, image)
        self._keep(item)
        self.watermark = stamp
        self.frames_handled += 1
        for window in self.windows.values():
            if stamp >= window.lo and (window.end is None or window.end[0] >= stamp):
                window.pending.append(item)
        if self.camera_last is not None and stamp >= self.camera_last:
            self.camera_done = True
        return self._decide()

    def started(self, segment_id: int, start_stamp: int, ref: R) -> list[Output[R]]:
        repeat = segment_id in self.windows or segment_id in self.told
        if not repeat and len(self.windows) >= self.max_open:
            raise InputError(
                f"gesture {segment_id} refused: {len(self.windows)} gestures already under way "
                f"(valid: at most {self.max_open} at once)"
            )
        self.gestures_started = max(self.gestures_started, segment_id)
        if repeat:
            return []  # a repeat (recovered from a cache): already under way, or told
        window = _Window(segment_id, start_stamp, start_stamp - self.lead_ns, ref)
        window.opened_at = self.frames_handled
        window.pending.extend(b for b in self.buffer if b.stamp >= window.lo)
        self.windows[segment_id] = window
        self._skeleton_at(start_stamp)
        return self._decide()

    def ended(
        self, segment_id: int, start_stamp: int, end_stamp: int, frame: int, ref: R
    ) -> list[Output[R]]:
        if end_stamp < start_stamp:
            raise InputError(
                f"gesture {segment_id} ends at {end_stamp}, before its start {start_stamp}"
            )
        if segment_id in self.told:
            return []
        window = self.windows.get(segment_id)
        outputs: list[Output[R]] = []
        if window is None:  # its start was never seen: open the window from the buffer
            outputs = self.started(segment_id, start_stamp, ref)
            window = self.windows[segment_id]
        if window.end is None:
            window.end = (end_stamp, frame, ref)
            while window.pending and window.pending[-1].stamp > end_stamp:
                window.pending.pop()  # after its end: not the gesture's
        self._skeleton_at(end_stamp)
        return outputs + self._decide()

    @property
    def restart_point(self) -> int:
        """A camera stamp from which a fresh watch, fed the frames from it on (and the gesture
        events and progress again), makes the outputs this one makes from now on: no frame
        before it is kept, in an open window or the last evicted one that showed an object (a
        later gesture's start looks back to it), and every frame after it is handled or still
        to come. -1: from the first frame. A restarted object segmenter starts there rather
        than going over all the camera history a cache gives back (services/objects.py)."""
        if self.complete_until < 0:
            return -1
        points = [self.complete_until - self.onset_ns - self.lead_ns, self.watermark + 1]
        points += [w.lo for w in self.windows.values()]
        if self.buffer:
            points.append(self.buffer[0].stamp)
        if self._last_evicted is not None:
            points.append(self._last_evicted[0])
        if self._evicted_unknown:  # undescribed, kept aside for a later start's look-back
            points.append(self._evicted_unknown[0].stamp)
        return min(points)

    def done(self, segment_ids: set[int]) -> list[Output[R]]:
        """These gestures were told elsewhere (by a previous instance, whose results every
        consumer has): what comes about them is a repeat, not measured again."""
        for segment_id in sorted(segment_ids):
            self.windows.pop(segment_id, None)
            self.told.append(segment_id)
        return self._decide()

    def cancelled(self, segment_id: int) -> list[Output[R]]:
        window = self.windows.get(segment_id)
        if window is not None and window.end is not None:
            return []  # whole already: a restarted streamer cancels what it did not see end
        self.windows.pop(segment_id, None)
        return self._decide()

    def gestures_complete(self, stamp: int) -> list[Output[R]]:
        """Every gesture event derived from the skeleton up to `stamp` has been received."""
        self.complete_until = max(self.complete_until, stamp)
        self._skeleton_at(stamp)
        self._evict()
        return self._decide()

    def skeleton_at(self, stamp: int) -> list[Output[R]]:
        """The skeleton stream has reached `stamp` (deadlines for a silent camera)."""
        self._skeleton_at(stamp)
        return self._decide()

    def camera_ended(self, last_stamp: int | None) -> list[Output[R]]:
        """The source has ended; its last camera frame was stamped `last_stamp` (None: the
        stream had no camera)."""
        self.camera_last = last_stamp if last_stamp is not None else -1
        if self.watermark >= self.camera_last:
            self.camera_done = True
        return self._decide()

    def catch_up(self) -> bool:
        """Push one frame a gesture under way has not taken in yet (the oldest, of the earliest
        gesture); False when there is none. The frames a gesture needs are pushed at the latest
        when its effects are decided, so calling this changes no output: a service calls it
        between messages, so a gesture's start (the lead frames it looks back to) and its frames
        are analysed while they come, and its end costs one frame."""
        return any(self._step(self.windows[segment_id]) for segment_id in sorted(self.windows))

    # -- per-frame objects ------------------------------------------------------------------

    def describe(self, image: np.ndarray) -> list[DetectedObject]:
        """The labelled objects of one frame. Reads nothing the watch changes, so it may run on
        another thread while the watch goes on; hand the result back with `described`."""
        return describe_frame(image, self.clusters, require_objects=False).objects

    def known_objects(self, stamp: int) -> list[DetectedObject] | None:
        """The objects of the kept frame stamped `stamp` if it has been described already."""
        item = self._by_stamp.get(stamp)
        return None if item is None else item.objects

    def described(self, stamp: int, objects: list[DetectedObject]) -> None:
        """`describe`'s result for the frame stamped `stamp`, kept for the gestures' use."""
        item = self._by_stamp.get(stamp)
        if item is not None and item.objects is None:
            item.objects = objects

    def frame_objects(self, stamp: int, frame: int, image: np.ndarray, ref: R) -> FrameObjects[R]:
        """The objects of a frame (`camera` first): described now unless it was already."""
        objects = self.known_objects(stamp)
        if objects is None:
            objects = self.describe(image)
            self.described(stamp, objects)
        return FrameObjects(stamp, frame, ref, objects)

    # -- internals ------------------------------------------------------------------------

    def _skeleton_at(self, stamp: int) -> None:
        self.skeleton_time = max(self.skeleton_time, stamp)

    def _keep(self, item: _Buffered) -> None:
        self.buffer.append(item)
        self._by_stamp[item.stamp] = item
        self._buffered_bytes += item.image.nbytes
        self._evict()

    def _evict(self) -> None:
        # a frame can go once no gesture, open or still to be announced, can need it: the
        # segmenter places an onset at most `onset_s` of its frames back, and across a pause
        # that is a count of frames, not a time, so the last LOOK_BACK_FRAMES frames up to the
        # complete skeleton time stay too
        keep_from = self.complete_until - self.onset_ns - self.lead_ns
        for window in self.windows.values():
            keep_from = min(keep_from, window.lo)
        before = sum(1 for b in self.buffer if b.stamp <= self.complete_until)
        while self.buffer and self.buffer[0].stamp < keep_from and before > LOOK_BACK_FRAMES:
            self._drop_oldest()
            before -= 1
        while len(self.buffer) > 1 and self._buffered_bytes > self.buffer_bytes:
            self.evicted_early += 1
            oldest = self.buffer[0].stamp
            for window in self.windows.values():  # analysed now, so its image can go
                while window.pending and window.pending[0].stamp <= oldest:
                    self._step(window)
            self._drop_oldest()

    def _drop_oldest(self) -> None:
        old = self.buffer.popleft()
        del self._by_stamp[old.stamp]
        self._buffered_bytes -= old.image.nbytes
        # a later start looks back to the last frame that showed an object
        if old.objects is None:
            self._evicted_unknown.append(old)
            if len(self._evicted_unknown) > EVICTED_KEPT:
                self._settle_evicted()
        elif labels := old.labels:
            self._last_evicted = (old.stamp, old.frame, labels)
            self._evicted_unknown.clear()

    def _settle_evicted(self) -> None:
        """Describe the dropped frames nobody described, newest first, until one shows an
        object: only it can still be looked back to."""
        for item in reversed(self._evicted_unknown):
            if labels := self._labels(item):
                self._last_evicted = (item.stamp, item.frame, labels)
                break
        self._evicted_unknown.clear()

    def _labels(self, item: _Buffered) -> dict[str, str]:
        if item.objects is None:
            item.objects = self.describe(item.image)
        return item.labels

    def _step(self, window: _Window[R]) -> bool:
        """One frame's work for `window`, in stamp order (False: none left): analyse the oldest
        frame taken in, or take in the next one. A window's first frames wait until its frame
        rate is measured on them (`FPS_FRAMES`), then are analysed one per step."""
        if window.analyser is not None and window.early:
            window.analyser.push(window.early.popleft())
            return True
        if not window.pending:
            return False
        item = window.pending.popleft()
        window.stamps.append(item.stamp)
        if window.analyser is not None:
            window.analyser.push(item.image)
            return True
        window.early.append(item.image)
        if self.fps is not None or len(window.stamps) >= FPS_FRAMES:
            fps = self.fps or float(1e9 / np.median(np.diff(window.stamps)))
            window.analyser = RecordingAnalyser(fps, self.clusters)
        return True

    def _silent_since(self, stamp: int) -> bool:
        return self.watermark < stamp and self.skeleton_time >= stamp + self.deadline_ns

    def _decide(self) -> list[Output[R]]:
        outputs: list[Output[R]] = []
        for segment_id in sorted(self.windows):
            window = self.windows[segment_id]
            if (
                window.end is None
                and self.frames_handled - window.opened_at > self.max_gesture_frames
            ):
                del self.windows[segment_id]  # a start no end followed: not a gesture
                self.abandoned += 1
                continue
            if not window.object_decided:
                s = window.start_stamp
                if not (self.watermark >= s or self.camera_done or self._silent_since(s)):
                    continue
                window.object_decided = True
                outputs.append(self._object_at_start(window))
            if window.end is None:
                continue
            e = window.end[0]
            if self.watermark > e or self.camera_done or self._silent_since(e):
                outputs.append(self._effects(window))
                del self.windows[segment_id]
        return outputs

    def _object_at_start(self, window: _Window[R]) -> ObjectAtStart[R]:
        """The biggest object of the last frame at or before the start that showed one (frames
        described on the way back, newest first, as few as it takes)."""
        start = window.start_stamp
        for item in reversed([*self._evicted_unknown, *self.buffer]):
            if item.stamp <= start and (labels := self._labels(item)):
                return ObjectAtStart(window.segment_id, item.frame, labels, "", window.start_ref)
        if self._last_evicted is not None and self._last_evicted[0] <= start:
            _, frame, labels = self._last_evicted
            return ObjectAtStart(window.segment_id, frame, dict(labels), "", window.start_ref)
        if self.watermark < 0:
            reason = "no camera frame before the gesture began"
        elif self.watermark < start and not self.camera_done:
            reason = "the camera stopped before the gesture began"
        else:
            reason = "no object on the table when the gesture began"
        return ObjectAtStart(window.segment_id, 0, {}, reason, window.start_ref)

    def _effects(self, window: _Window[R]) -> GestureEffects[R]:
        assert window.end is not None
        end_stamp, frame, ref = window.end
        while self._step(window):  # what nobody caught up on yet
            pass
        within = sum(1 for s in window.stamps if window.lo <= s <= end_stamp)
        if within < MIN_WINDOW_FRAMES:
            what = "no camera stream" if self.watermark < 0 else f"only {within} camera frames"
            reason = (
                f"effects not measured: {what} between the gesture's start and end "
                f"(valid: at least {MIN_WINDOW_FRAMES})"
            )
            return GestureEffects(window.segment_id, frame, None, reason, ref)
        if window.analyser is None:  # fewer than FPS_FRAMES frames in all: measure on them
            fps = float(1e9 / np.median(np.diff(window.stamps)))
            window.analyser = RecordingAnalyser(fps, self.clusters)
            while window.early:
                window.analyser.push(window.early.popleft())
        try:
            analysis = window.analyser.finish(within)
        except InputError as exc:
            return GestureEffects(
                window.segment_id, frame, None, f"effects not measured: {exc}", ref
            )
        return GestureEffects(window.segment_id, frame, analysis, "", ref)
