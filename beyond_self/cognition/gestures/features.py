"""The features gestures are recognised on, the same in training and in recognition.

Everything starts from the hand relative to the torso in "body units" (x, z over 0.33 m, y over
0.23 m), exactly what the article's hand logs hold (times 1000), in the depth sensor's frame (x
right, y up, z away). Two spaces, named in every model file: "position" (D = 3, the article's
models) and "motion" (D = 7: the hand relative to the gesture's first frame, its velocity and
the time since the start, after a causal 5-frame median). Motion does not depend on where the
person stands or rests the hand, and its velocity and time carry the tempo that tells a grasp
(about 5 s, with a hold) from a touch (about 3 s) whose paths are alike. Every feature is causal:
a streaming recogniser sees one frame at a time.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Mapping
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from beyond_self.core.errors import InputError, unknown

FloatArray = NDArray[np.float64]
Point = tuple[float, float, float]  # one frame's position, on plain floats (the live path)

HORIZONTAL_BODY_SCALE = 0.33  # m, the reference pipeline's shoulder-width normaliser
VERTICAL_BODY_SCALE = 0.23  # m, the reference pipeline's neck-to-torso normaliser
LOG_SCALE = 0.001  # hand logs -> feature space
FEATURE_DIM = 3


def _as_positions(x: ArrayLike, what: str) -> FloatArray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != FEATURE_DIM:
        raise InputError(
            f"{what} has shape {np.shape(x)}; valid: (3,) for one frame or (T, 3) for T frames"
        )
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{what} holds NaN or infinite values; valid: finite positions")
    return arr


def extract_features(
    hand: ArrayLike,
    torso: ArrayLike | None = None,
    *,
    scale: float = 1.0,
    body: tuple[float, float] = (HORIZONTAL_BODY_SCALE, VERTICAL_BODY_SCALE),
) -> FloatArray:
    """Features of T frames (T, 3), or of one frame given as (3,) (returned as (1, 3)).

    With a torso joint: (hand - torso) * scale / (h, v, h), `body` = (h, v) in the same units as
    the positions after `scale` (metres for a skeleton). Without one, the hand position times
    `scale`: right for the hand logs (already torso-relative and normalised; scale 0.001), and the
    raw-position fallback of a tracker that gives only the hand.
    """
    if not np.isfinite(scale) or scale <= 0:
        raise InputError(f"feature scale {scale!r} is invalid; valid: a positive finite number")
    h = _as_positions(hand, "hand position")
    if torso is None:
        return h * scale
    t = _as_positions(torso, "torso position")
    if t.shape != h.shape:
        raise InputError(
            f"torso positions have shape {t.shape} but hand positions {h.shape}; they must match"
        )
    horizontal, vertical = body
    if not (horizontal > 0 and vertical > 0):
        raise InputError(f"body scale {body!r} is invalid; valid: two positive lengths")
    divisor = np.array([horizontal, vertical, horizontal])
    return cast(np.ndarray, (h - t) * scale / divisor)


def point_features(hand: object, torso: object) -> Point | None:
    """`extract_features` of one frame given as plain (x, y, z) sequences, on plain floats
    (the same operations, so the same numbers; a live stream's frame cost numpy more in calls
    than in arithmetic), or None when the positions are not three finite numbers each: then
    `extract_features` says what is wrong."""
    if not isinstance(hand, tuple | list) or len(hand) != FEATURE_DIM:
        return None
    hx, hy, hz = (float(v) for v in hand)
    if torso is None:
        point = (hx, hy, hz)
    elif isinstance(torso, tuple | list) and len(torso) == FEATURE_DIM:
        tx, ty, tz = (float(v) for v in torso)
        h, v = HORIZONTAL_BODY_SCALE, VERTICAL_BODY_SCALE
        point = ((hx - tx) / h, (hy - ty) / v, (hz - tz) / h)
    else:
        return None
    return point if all(map(math.isfinite, point)) else None


def features_from_joints(
    joints: Mapping[str, ArrayLike],
    *,
    hand: str = "right_hand",
    torso: str = "torso",
    body: tuple[float, float] = (HORIZONTAL_BODY_SCALE, VERTICAL_BODY_SCALE),
) -> FloatArray:
    """Features of a skeleton stream in metres (a dict of joint name -> (T, 3) or (3,))."""
    if hand not in joints:
        raise InputError(f"skeleton has no joint {hand!r}; joints present: {', '.join(joints)}")
    return extract_features(joints[hand], joints.get(torso), body=body)


def body_scale(joints: Mapping[str, ArrayLike]) -> tuple[float, float]:
    """A person's (shoulder width, neck-torso distance), medians over a skeleton stream.

    For a per-person amplitude normalisation, as the article's MATLAB pipeline did; pass the
    result as `body=` to the feature functions, identically in training and recognition.
    """
    needed = ("left_shoulder", "right_shoulder", "neck", "torso")
    missing = [j for j in needed if j not in joints]
    if missing:
        raise InputError(
            f"body scale needs joints {', '.join(needed)}; missing {', '.join(missing)}"
        )
    ls, rs, neck, torso = (_as_positions(joints[j], j) for j in needed)
    width = float(np.median(np.linalg.norm(ls - rs, axis=1)))
    height = float(np.median(np.linalg.norm(neck - torso, axis=1)))
    if width <= 0 or height <= 0:
        raise InputError("body scale: shoulders or neck coincide with each other or the torso")
    return width, height


def median_rows(rows: FloatArray) -> FloatArray:
    """The per-column median of a few rows (np.median's numbers, at a fraction of its cost)."""
    ordered = np.sort(rows, axis=0)
    n = len(ordered)
    mid: FloatArray = ordered[n // 2] if n % 2 else (ordered[n // 2 - 1] + ordered[n // 2]) / 2
    return mid


def median_of(values: list[float]) -> float:
    """`median_rows`' number for one column, on plain floats: a live stream's few values a
    frame cost numpy more in calls than in arithmetic."""
    ordered = sorted(values)
    n = len(ordered)
    return ordered[n // 2] if n % 2 else (ordered[n // 2 - 1] + ordered[n // 2]) / 2


def median_point(points: Iterable[Point]) -> Point:
    """The per-axis median of a few points (`median_rows`' numbers)."""
    xs, ys, zs = zip(*points, strict=True)
    return median_of(list(xs)), median_of(list(ys)), median_of(list(zs))


class HandSmoother:
    """Causal median of the last `frames` positions: a tracker glitch of up to `frames // 2`
    frames never reaches the segmenter or the motion features."""

    def __init__(self, frames: int = 5) -> None:
        self._recent: deque[Point] = deque(maxlen=frames)

    def push(self, position: FloatArray) -> FloatArray:
        return np.array(self.push_point(tuple(position.tolist())))

    def push_point(self, position: Point) -> Point:
        """`push` on plain floats (the segmenter's per-frame path)."""
        self._recent.append(position)
        return median_point(self._recent)

    @property
    def window(self) -> tuple[Point, ...]:
        """The positions the next median is taken over, with the next one."""
        return tuple(self._recent)


def smooth_positions(positions: ArrayLike, frames: int = 5) -> FloatArray:
    """`HandSmoother` over a whole (T, 3) array (the same numbers, frame for frame)."""
    x = _as_positions(positions, "positions")
    head = min(frames - 1, len(x))
    out = np.empty_like(x)
    for t in range(head):  # fewer frames than the window yet
        out[t] = median_rows(x[: t + 1])
    if len(x) > head:
        windows = np.lib.stride_tricks.sliding_window_view(x, frames, axis=0)  # (T-k+1, 3, k)
        ordered = np.sort(windows, axis=-1)
        out[head:] = (
            ordered[..., frames // 2]
            if frames % 2
            else (ordered[..., frames // 2 - 1] + ordered[..., frames // 2]) / 2
        )
    return out


POSITION = "position"
MOTION = "motion"
FEATURE_SPACES: dict[str, int] = {POSITION: 3, MOTION: 7}  # name -> dimension
MOTION_LAG = 3  # frames between the two positions of a velocity
NOMINAL_FPS = 30.0  # velocities are per frame times this, whatever the stream's jitter


def check_space(space: str) -> int:
    """The dimension of a feature space, or an InputError naming the valid ones."""
    if space not in FEATURE_SPACES:
        raise unknown("feature space", space, tuple(FEATURE_SPACES))
    return FEATURE_SPACES[space]


def motion_frame(
    position: FloatArray, earlier: FloatArray, gap: int, origin: FloatArray, since: int
) -> FloatArray:
    """One "motion" feature vector: `position` and `earlier` (`gap` frames before) smoothed,
    `origin` the gesture's first smoothed position, `since` frames after it."""
    velocity = (position - earlier) * (NOMINAL_FPS / gap) if gap > 0 else 0.0 * position
    return np.concatenate([position - origin, velocity, [since / NOMINAL_FPS]])


def gesture_features(
    space: str, positions: ArrayLike, start: int = 0, stop: int | None = None
) -> FloatArray:
    """Features of frames [start, stop) of a stream of positions (T, 3) in body units.

    The frames before `start` are context only (the smoothing and the first velocities look
    back), so a gesture cut out of a stream gets exactly the features the streaming recogniser
    computed while it unfolded.
    """
    check_space(space)
    x = _as_positions(positions, "positions")
    end = len(x) if stop is None else stop
    if not 0 <= start < end <= len(x):
        raise InputError(f"gesture frames {start}:{end} outside the stream's 0:{len(x)}")
    if space == POSITION:
        return x[start:end].copy()
    smooth = smooth_positions(x[:end])
    t = np.arange(start, end)
    gap = np.minimum(t, MOTION_LAG)
    earlier = smooth[t - gap]
    with np.errstate(invalid="ignore", divide="ignore"):
        velocity = (smooth[t] - earlier) * (NOMINAL_FPS / gap)[:, None]
    velocity[gap == 0] = 0.0
    since = ((t - start) / NOMINAL_FPS)[:, None]
    return np.hstack([smooth[t] - smooth[start], velocity, since])
