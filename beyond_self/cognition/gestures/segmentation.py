"""Cutting a continuous hand stream into gestures: one per execution, cut to the movement.

Every action on an object is an excursion of the hand from its rest pose and back. On the
smoothed torso-relative trajectory: the rest pose is where the hand stays still (re-estimated at
every rest, so drift is followed); a gesture starts when the hand goes `leave` forward of it,
placed back to where it left; it must reach `reach` and ends on the way back, placed where the
hand had come `turn` of the way. An excursion that never reaches, is mostly tracker jumps, or is
too short or long is reported `Discarded`, with why. After an end the hand must rest again. The
segmenter is causal: `GestureSegmenter.push` reports a gesture once its end is known, so services
use it live; `segment_gestures` runs it over an array. docs/science/gestures.md gives the figures.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from beyond_self.cognition.gestures.features import HandSmoother, Point, median_point
from beyond_self.core.errors import InputError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SegmenterConfig:
    """Thresholds in body units (see `cognition.gestures.features`) and frames."""

    median_frames: int = 5  # causal median against tracker glitches
    rest_frames: int = 15  # a rest: this many frames ...
    rest_radius: float = 0.12  # ... all within this distance of their median
    leave: float = 0.4  # forward of the rest pose that starts a gesture
    near: float = 0.3  # the start: the last frame this close to the rest pose
    reach: float = 0.8  # how far forward a gesture must reach
    back: float = 0.45  # on the way back: distance to rest below (1 - back) of its maximum
    turn: float = 1 / 3  # the end: where the hand had come this part of the way back
    jump: float = 0.5  # a step longer than this between two frames is a tracker jump
    max_jumps: float = 0.1  # a gesture with more jumps than this share of its frames is not one
    min_gesture: int = 20  # frames
    max_gesture: int = 900  # frames (30 s)
    max_lead: int = 45  # frames a start may be placed before the frame that noticed it
    keep_partial: bool = False  # keep a gesture still under way when the stream ends

    def __post_init__(self) -> None:
        if self.median_frames < 1 or self.rest_frames < 2:
            raise InputError("segmenter needs median_frames >= 1 and rest_frames >= 2")
        lengths = (self.rest_radius, self.leave, self.near, self.reach, self.jump)
        if not all(np.isfinite(v) and v > 0 for v in lengths):
            raise InputError("segmenter distances must be positive")
        if not (self.near < self.leave <= self.reach):
            raise InputError("segmenter needs near < leave <= reach (hysteresis)")
        if not (0 < self.turn < self.back < 1) or not 0 <= self.max_jumps <= 1:
            raise InputError("segmenter needs 0 < turn < back < 1 and 0 <= max_jumps <= 1")
        if not 1 <= self.min_gesture <= self.max_gesture or self.max_lead < 0:
            raise InputError("segmenter needs 1 <= min_gesture <= max_gesture, max_lead >= 0")


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


@dataclass(frozen=True)
class Discarded:
    """A started gesture that turned out not to be one; `reason` says why (one line)."""

    start: int
    stop: int
    reason: str


_IDLE, _ACTIVE, _RETURNING = range(3)


class GestureSegmenter:
    """Causal segmenter: push one position per frame; get a `Segment` when a gesture's end is
    known, a `Discarded` when a gesture announced by `current_start` is withdrawn, else None."""

    def __init__(self, config: SegmenterConfig | None = None) -> None:
        self.config = config or SegmenterConfig()
        self.reset()

    def reset(self) -> None:
        cfg = self.config
        self._t = 0
        self._smoother = HandSmoother(cfg.median_frames)
        history = max(cfg.rest_frames, cfg.max_lead + 1)
        self._recent: deque[Point] = deque(maxlen=history)  # smoothed, last frames
        self._smoothed: FloatArray | None = None  # the last of them, as the tracker keeps it
        self._jumped: deque[bool] = deque(maxlen=history)  # ... and whether each jumped
        self._distances: deque[float] = deque(maxlen=cfg.max_gesture + 1)  # in the gesture
        self._raw_prev: Point | None = None
        self._since_jump = 0  # frames since the last tracker jump
        self._state = _IDLE
        self._rest: Point | None = None
        self._start = 0
        self._farthest = 0.0  # distance to the rest pose
        self._forward = 0.0  # forward reach
        self._jumps = 0
        self._from_start = False  # under way since the stream's first frame

    @property
    def active(self) -> bool:
        """A gesture is under way."""
        return self._state == _ACTIVE

    @property
    def idle(self) -> bool:
        """No gesture under way, and not on the way back from one."""
        return self._state == _IDLE

    def course(self) -> tuple[object, ...]:
        """Everything that decides what this segmenter does from here on while it is idle (its
        windows, rest pose, whether a jump is still in its median), not where in the stream it
        is: two idle segmenters with equal courses, fed the same frames, report the same
        gestures (a restarted tracker's proof that it resumes exactly, cognition.episodes)."""
        return (
            self._state,
            tuple(_exact(q) for q in self._smoother.window),
            tuple(_exact(q) for q in self._recent),
            tuple(self._jumped),
            None if self._raw_prev is None else _exact(self._raw_prev),
            min(self._since_jump, self.config.median_frames),
            None if self._rest is None else _exact(self._rest),
        )

    @property
    def current_start(self) -> int | None:
        """0-based frame where the gesture under way began (None between gestures), so a
        streaming recogniser can start from the gesture's first frame, not from the frame the
        segmenter noticed it."""
        return self._start if self._state == _ACTIVE else None

    @property
    def smoothed(self) -> FloatArray:
        """The last frame's position after the causal median (what the segmenter used)."""
        assert self._smoothed is not None, "pushed a frame before"
        return self._smoothed

    def push(self, position: ArrayLike) -> Segment | Discarded | None:
        cfg = self.config
        p = np.asarray(position, dtype=np.float64)
        if p.shape != (3,):
            raise InputError(f"segmenter position has shape {p.shape}; valid: 3 finite numbers")
        # one frame's arithmetic on plain floats: numpy's per-call cost is most of a frame's
        point: Point = tuple(p.tolist())
        if not all(map(math.isfinite, point)):
            raise InputError(f"segmenter position is {point}; valid: 3 finite numbers")
        t = self._t
        self._t += 1
        previous = self._raw_prev
        jumped = previous is not None and _length(point, previous) > cfg.jump
        self._raw_prev = point
        self._since_jump = 0 if jumped else self._since_jump + 1
        smooth = self._smoother.push_point(point)
        self._smoothed = np.array(smooth)
        self._recent.append(smooth)
        self._jumped.append(jumped)
        if self._state == _RETURNING and (
            self._resting() is not None or self._distance(smooth) < cfg.near
        ):
            self._state = _IDLE
        if self._state == _IDLE:
            rest = self._resting()
            if rest is not None:
                self._rest = rest
            steady = self._since_jump >= cfg.median_frames  # no jump left in the median
            if steady and self._rest is not None and self._rest[2] - smooth[2] > cfg.leave:
                self._begin(t)
            return None
        if self._state == _ACTIVE:
            return self._follow(t, smooth, jumped)
        return None

    def finish(self) -> Segment | Discarded | None:
        """End of stream: a gesture still under way is cut (kept only with `keep_partial`)."""
        if self._state != _ACTIVE:
            return None
        self._state = _IDLE
        if self.config.keep_partial and not self._from_start:
            return self._judge(self._start, self._t)
        return Discarded(self._start, self._t, "still under way when the stream ended")

    # -- internals -----------------------------------------------------------------------

    def _distance(self, q: Point) -> float:
        return _length(q, self._rest) if self._rest is not None else 0.0

    def _resting(self) -> Point | None:
        n = self.config.rest_frames
        recent = self._recent
        if len(recent) < n:
            return None
        window = list(recent)[-n:]
        centre = median_point(window)
        radius = self.config.rest_radius
        if any(_length(q, centre) > radius for q in window):
            return None
        return centre

    def _begin(self, t: int) -> None:
        cfg = self.config
        recent = list(self._recent)
        back = 0  # frames before t: walk back while the hand is away from rest
        while back < min(cfg.max_lead, len(recent) - 1):
            if self._distance(recent[-2 - back]) <= cfg.near:
                break
            back += 1
        self._state = _ACTIVE
        self._start = t - back
        self._from_start = self._start == 0
        self._distances.clear()
        for q in recent[len(recent) - 1 - back :]:
            self._distances.append(self._distance(q))
        self._farthest = max(self._distances)
        rest_z = self._rest[2]  # type: ignore[index]
        self._forward = max(rest_z - q[2] for q in recent[-1 - back :])
        self._jumps = sum(list(self._jumped)[-1 - back :])

    def _follow(self, t: int, smooth: Point, jumped: bool) -> Segment | Discarded | None:
        cfg = self.config
        assert self._rest is not None
        d = self._distance(smooth)
        self._distances.append(d)
        self._farthest = max(self._farthest, d)
        forward = self._rest[2] - smooth[2]
        self._forward = max(self._forward, forward)
        self._jumps += jumped
        if self._forward < cfg.reach and forward < cfg.leave / 2:
            self._state = _IDLE
            return Discarded(self._start, t + 1, "the hand came back without reaching forward")
        if t + 1 - self._start > cfg.max_gesture:
            self._state = _RETURNING
            return Discarded(
                self._start, t + 1, f"longer than {cfg.max_gesture} frames without coming back"
            )
        if self._forward < cfg.reach or d >= (1 - cfg.back) * self._farthest:
            return None
        # on the way back: the end is the last frame still `turn` of the way out
        self._state = _RETURNING
        keep = (1 - cfg.turn) * self._farthest
        dists = list(self._distances)
        stop = len(dists)
        while stop > 1 and dists[stop - 1] < keep:
            stop -= 1
        return self._judge(self._start, self._start + stop)

    def _judge(self, start: int, stop: int) -> Segment | Discarded:
        cfg = self.config
        if stop - start < cfg.min_gesture:
            return Discarded(start, stop, f"shorter than {cfg.min_gesture} frames")
        if self._jumps > cfg.max_jumps * (self._t - start):
            return Discarded(
                start, stop, f"tracking failed: {self._jumps} jumps in {self._t - start} frames"
            )
        return Segment(start, stop)


def _exact(q: Point) -> bytes:
    """A point's exact bits, so that courses compare as the arrays' bytes did (-0.0 is not 0.0)."""
    return np.array(q).tobytes()


def _length(a: Point, b: Point) -> float:
    """|a - b|, summed as numpy's norm of the rows of an array sums them (x, then y, then z)."""
    dx, dy, dz = a[0] - b[0], a[1] - b[1], a[2] - b[2]
    return math.sqrt(dx * dx + dy * dy + dz * dz)


def segment_gestures(positions: ArrayLike, config: SegmenterConfig | None = None) -> list[Segment]:
    """All gestures of a (T, 3) feature-space trajectory, in order."""
    x = np.asarray(positions, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 3:
        raise InputError(f"positions have shape {x.shape}; valid: (T, 3)")
    seg = GestureSegmenter(config)
    found = [seg.push(p) for p in x]
    found.append(seg.finish())
    return [s for s in found if isinstance(s, Segment)]
