"""Cutting a continuous hand stream into gestures: hand at rest vs hand acting, with hysteresis.

Speed alone does not separate gestures in the article's recordings: the hand is as still while
it holds or touches the object as while it rests, and between repetitions it often passes
through its rest pose without stopping. What does separate them is where the hand is: every
action on the table is an excursion of the hand in front of the body and back. So the segmenter
runs two hysteresis detectors on the feature-space trajectory (torso-relative, body units, see
`cognition.gestures.features`):

- reach: a gesture is under way from the frame the hand goes further forward than `reach_on`
  (feature z below it; z points away from the sensor, the person faces the sensor) until it comes
  back behind `reach_off`;
- stillness: the smoothed speed, with `rest_speed` < `move_speed`, refines the bounds: the
  gesture starts at the motion onset before the reach (the last still frame, at most
  `max_lead` frames earlier) and ends when the hand is still again after coming back (at most
  `max_tail` frames later).

With `reach_on=None` the segmenter is speed-only (a rest is `min_rest` still frames), for
streams without a torso-relative frame. Glitches of the tracker are removed by a causal median.
The segmenter is causal: `GestureSegmenter.push` reports each gesture as soon as its end is
known, so services can use it on live streams; `segment_gestures` runs it over an array.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from beyond_self.core.errors import InputError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SegmenterConfig:
    """Thresholds in feature units (body units; speeds per second)."""

    fps: float = 30.0
    median_frames: int = 5  # causal median against tracker glitches
    speed_frames: int = 5  # causal moving average of the speed
    rest_speed: float = 0.6  # below: still
    move_speed: float = 1.2  # above: moving
    reach_on: float | None = -0.9  # feature z below this: acting in front of the body
    reach_off: float = -0.6  # feature z above this: back near the body
    min_rest: int = 8  # still frames that end a gesture (speed-only mode)
    min_gesture: int = 15  # shorter excursions are discarded
    max_lead: int = 45  # how far back before the reach a start may be placed
    max_tail: int = 30  # how long after coming back the end may wait for stillness
    keep_partial: bool = False  # keep gestures cut by the start or the end of the stream

    def __post_init__(self) -> None:
        if self.fps <= 0 or self.median_frames < 1 or self.speed_frames < 1:
            raise InputError("segmenter needs fps > 0, median_frames >= 1, speed_frames >= 1")
        if not 0 <= self.rest_speed <= self.move_speed:
            raise InputError("segmenter needs 0 <= rest_speed <= move_speed (hysteresis)")
        if self.reach_on is not None and not self.reach_on <= self.reach_off:
            raise InputError("segmenter needs reach_on <= reach_off (hysteresis)")
        if self.min_rest < 1 or self.min_gesture < 1 or self.max_lead < 0 or self.max_tail < 0:
            raise InputError("segmenter frame counts must be positive")


@dataclass(frozen=True)
class Segment:
    """Frames [start, stop) of one gesture, 0-based (`first`/`last` give 1-based inclusive)."""

    start: int
    stop: int

    @property
    def first(self) -> int:
        return self.start + 1

    @property
    def last(self) -> int:
        return self.stop

    def __len__(self) -> int:
        return self.stop - self.start


class GestureSegmenter:
    """Causal segmenter: push one position per frame, get the gestures whose end is now known."""

    def __init__(self, config: SegmenterConfig | None = None) -> None:
        self.config = config or SegmenterConfig()
        self.reset()

    def reset(self) -> None:
        cfg = self.config
        self._t = 0
        self._recent: deque[FloatArray] = deque(maxlen=cfg.median_frames)
        self._speeds: deque[float] = deque(maxlen=cfg.speed_frames)
        self._prev: FloatArray | None = None
        self._last_still = 0  # last frame whose smoothed speed was below rest_speed
        self._still_run = 0
        self._active = False  # inside a gesture
        self._returned_at: int | None = None  # frame the hand came back (reach mode)
        self._start = 0
        self._reached = False
        self._last_stop = 0
        self._partial = False  # the current gesture was under way when the stream began

    @property
    def active(self) -> bool:
        """A gesture is under way."""
        return self._active

    @property
    def current_start(self) -> int | None:
        """0-based frame where the gesture under way began (None between gestures), so a
        streaming recogniser can start from the gesture's first frame, not from the frame the
        segmenter noticed it."""
        return self._start if self._active else None

    def push(self, position: ArrayLike) -> Segment | None:
        cfg = self.config
        p = np.asarray(position, dtype=np.float64)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise InputError(f"segmenter position has shape {p.shape}; valid: 3 finite numbers")
        t = self._t
        self._t += 1
        self._recent.append(p)
        smooth = np.median(np.stack(self._recent), axis=0)
        step = 0.0 if self._prev is None else float(np.linalg.norm(smooth - self._prev))
        self._prev = smooth
        self._speeds.append(step * cfg.fps)
        speed = float(np.mean(self._speeds))
        still = speed < cfg.rest_speed
        self._still_run = self._still_run + 1 if still else 0
        if still:
            self._last_still = t
        if cfg.reach_on is None:
            return self._speed_only(t, speed)
        return self._with_reach(t, float(smooth[2]), still)

    def _emit(self, start: int, stop: int) -> Segment | None:
        self._active = False
        self._returned_at = None
        self._last_stop = stop
        partial, self._partial = self._partial, False
        if partial and not self.config.keep_partial:
            return None
        if stop - start >= self.config.min_gesture:
            return Segment(start, stop)
        return None

    def _with_reach(self, t: int, z: float, still: bool) -> Segment | None:
        cfg = self.config
        assert cfg.reach_on is not None
        if not self._active:
            if z < cfg.reach_on:
                onset = max(self._last_still, t - cfg.max_lead, self._last_stop)
                self._active, self._start, self._returned_at = True, onset, None
                self._partial = t == 0
            return None
        if self._returned_at is None:
            if z > cfg.reach_off:
                self._returned_at = t
            return None
        if z < cfg.reach_on:  # went forward again before settling: the next gesture begins
            seg = self._emit(self._start, t - (t - self._returned_at) // 2)
            self._active, self._start = True, self._last_stop
            return seg
        if still or t - self._returned_at >= cfg.max_tail:
            return self._emit(self._start, t)
        return None

    def _speed_only(self, t: int, speed: float) -> Segment | None:
        cfg = self.config
        if not self._active:
            if speed > cfg.move_speed:
                self._active = True
                self._start = max(self._last_still, t - cfg.max_lead, self._last_stop)
            return None
        if self._still_run >= cfg.min_rest:
            return self._emit(self._start, t - cfg.min_rest + 1)
        return None

    def finish(self) -> Segment | None:
        """End of stream: a gesture still under way is cut (kept only with `keep_partial`)."""
        if self._active:
            self._partial = self._partial or self._returned_at is None
            return self._emit(self._start, self._t)
        return None


def segment_gestures(positions: ArrayLike, config: SegmenterConfig | None = None) -> list[Segment]:
    """All gestures of a (T, 3) feature-space trajectory, in order."""
    x = np.asarray(positions, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 3:
        raise InputError(f"positions have shape {x.shape}; valid: (T, 3)")
    seg = GestureSegmenter(config)
    out = [s for s in (seg.push(p) for p in x) if s is not None]
    last = seg.finish()
    if last is not None:
        out.append(last)
    return out
