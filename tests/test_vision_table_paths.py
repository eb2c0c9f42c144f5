"""The table model's and the segmenter's fast paths give the values of the plain formulas.

Each fast path (integer medians, channel planes, the frame's distortions kept from the table
estimate, components labelled in the box around the candidates) must give the same numbers as
the straightforward computation, value for value: a label could move on one pixel's difference.
"""

from __future__ import annotations

import numpy as np
import pytest

from beyond_self.cognition.vision.background import (
    BackgroundModel,
    _means,
    _noise,
    block_means,
    block_sums,
    distortions,
    median_window,
)
from beyond_self.cognition.vision.segmentation import SegmentParams, _pick_hand
from beyond_self.cognition.vision.tabletop import Camera, simulate_experiment


def _frame(size: tuple[int, int], seed: int) -> np.ndarray:
    """A tabletop frame with an object and the hand, of `size` (width, height)."""
    rng = np.random.default_rng(seed)
    exp = simulate_experiment("grasp", "blue", "box", "big", rng, camera=Camera(*size))
    return np.asarray(exp.frames[len(exp.frames) // 2])


@pytest.mark.parametrize("block", [4, 8, 16])
def test_the_median_of_tile_sums_is_the_median_of_tile_means(block: int) -> None:
    rng = np.random.default_rng(block)
    frame = rng.integers(0, 256, (10 * block + 3, 13 * block - 1, 3), dtype=np.uint8)
    frame[: 4 * block] = 90  # ties, as on a flat table
    sums = block_sums(frame, block)
    for k in (3, 7):
        got = _means(median_window(sums, k), block)
        assert np.array_equal(got, median_window(block_means(frame, block), k))


@pytest.mark.parametrize("size", [(320, 240), (333, 251)])
def test_the_planes_compare_a_frame_as_the_formula_does(size: tuple[int, int]) -> None:
    frame = _frame(size, 1)
    model = BackgroundModel.from_frame(_frame(size, 2))
    mean = np.ascontiguousarray(model.mean)
    for every in (1, 3):
        grid = (slice(None, None, every), slice(None, None, every))
        alpha, cd = model.compare(frame, every=every)
        ref_alpha, ref_cd = distortions(frame[grid], mean[grid])
        assert np.array_equal(alpha, ref_alpha) and np.array_equal(cd, ref_cd)


def test_the_estimate_keeps_the_frames_own_distortions_and_noise() -> None:
    frame = _frame((320, 240), 3)
    model, alpha, cd = BackgroundModel.estimate(frame)
    again = BackgroundModel(mean=model.mean.copy())
    ref_alpha, ref_cd = again.compare(frame)
    assert np.array_equal(alpha, ref_alpha) and np.array_equal(cd, ref_cd)
    assert model.noise == _noise(frame, again)
    assert np.array_equal(BackgroundModel.from_frame(frame).mean, model.mean)


def test_the_hand_picked_in_a_box_is_the_one_picked_in_the_frame() -> None:
    rng = np.random.default_rng(4)
    shape = (240, 320)
    params = SegmentParams()
    found = 0
    for trial in range(20):
        mask = np.zeros(shape, dtype=bool)
        for _ in range(3):  # blobs of several sizes, some big enough to be a hand
            y, x = rng.integers(20, 200), rng.integers(20, 280)
            r = rng.integers(3, 16)
            yy, xx = np.ogrid[: shape[0], : shape[1]]
            mask |= (yy - y) ** 2 + (xx - x) ** 2 <= r * r
        ys, xs = np.nonzero(mask)
        box = (slice(ys.min(), ys.max() + 1), slice(xs.min(), xs.max() + 1))
        hand_px = (float(rng.uniform(0, 320)), float(rng.uniform(0, 240))) if trial % 2 else None
        whole = _pick_hand(mask, shape, hand_px, params)
        boxed = _pick_hand(mask[box], shape, hand_px, params, (box[0].start, box[1].start))
        if whole is None:
            assert boxed is None
            continue
        assert boxed is not None
        found += 1
        assert boxed.bbox == whole.bbox and boxed.touches_border == whole.touches_border
        assert np.array_equal(boxed.mask, whole.mask)
    assert found >= 5  # the boxes held hands to pick
