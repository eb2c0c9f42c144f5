"""The live per-frame path computes on plain floats (numpy's per-call cost was most of a frame's
in a fleet's gesture streamer): its numbers must be numpy's own, bit for bit, so that a live
stream, a replay and `beyond analyse` of whole arrays still agree."""

from __future__ import annotations

import numpy as np
import pytest

from beyond_self.cognition.episodes.tracker import hand_position
from beyond_self.cognition.gestures.features import (
    HandSmoother,
    extract_features,
    median_point,
    median_rows,
    point_features,
)
from beyond_self.core.errors import InputError


def test_a_frames_features_on_floats_are_extract_features_bits() -> None:
    rng = np.random.default_rng(5)
    for _ in range(2000):
        hand, torso = rng.normal(0, 1.5, 3).tolist(), rng.normal(0, 1.5, 3).tolist()
        fast = point_features(hand, torso)
        assert fast is not None
        assert np.array(fast).tobytes() == extract_features(hand, torso)[0].tobytes()
        alone = point_features(tuple(hand), None)
        assert alone is not None
        assert np.array(alone).tobytes() == extract_features(hand)[0].tobytes()


def test_the_median_of_a_few_points_is_median_rows_bits() -> None:
    rng = np.random.default_rng(6)
    for n in range(1, 16):
        for _ in range(50):
            # rounded: ties, as a still hand gives (+ 0.0: no -0.0, which equals 0.0 and which
            # of the two a median picks is up to the sort, numpy's SIMD one included)
            rows = np.round(rng.normal(0, 1, (n, 3)), 1) + 0.0
            points = [(float(a), float(b), float(c)) for a, b, c in rows]
            assert np.array(median_point(points)).tobytes() == median_rows(rows).tobytes()


def test_the_smoother_is_the_causal_median_of_its_window() -> None:
    rng = np.random.default_rng(7)
    xs = rng.normal(0, 1, (40, 3))
    smoother = HandSmoother(5)
    for t, x in enumerate(xs):
        expected = median_rows(xs[max(0, t - 4) : t + 1])
        assert smoother.push(x).tobytes() == expected.tobytes()


@pytest.mark.parametrize(
    ("hand", "said"),
    [
        ((float("nan"), 0.0, 0.0), "NaN or infinite"),
        ((5.0, 0.0, 0.0), "body units from the torso"),  # 15 body units across
        ((0.1, 0.2), "shape"),
    ],
)
def test_a_frame_that_is_not_a_hands_still_says_why(hand: tuple[float, ...], said: str) -> None:
    with pytest.raises(InputError, match=said):
        hand_position(hand, (0.0, 0.0, 0.0), "skeleton frame 3")
