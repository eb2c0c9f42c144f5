"""The one feature extraction used by training and by recognition.

Feature space (D = 3): the hand position relative to the torso, in "body units": x and z divided by
a horizontal body size (0.33 m), y by a vertical one (0.23 m). This is exactly what the recording
pipeline of the article wrote into the YARP hand logs (scaled by 1000), and what the reference
MATLAB models were trained on, so logs (times 0.001), the reference models, synthetic skeletons and
models trained here all share one space. The constants are the reference pipeline's empirical
values for the 2012 training data (shoulder width and neck-torso distance); `body_scale` measures
them on a skeleton stream when a per-person normalisation is wanted.

Axes follow the depth sensor (OpenNI/Kinect camera frame): x to the right, y up, z away from the
sensor; a person facing the sensor reaches towards it with negative z.

Frame-wise on purpose: a streaming recogniser sees one frame at a time, so a feature may not
depend on the future. Training runs the same function over whole arrays.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from beyond_self.core.errors import InputError

FloatArray = NDArray[np.float64]

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
