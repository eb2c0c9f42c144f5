"""Segmentation: the real camera frame of the article, shadows, the hand, bad frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from beyond_self.cognition.vision.background import BackgroundModel
from beyond_self.cognition.vision.clusters import ClusterModel
from beyond_self.cognition.vision.features import measure
from beyond_self.cognition.vision.images import read_image
from beyond_self.cognition.vision.pipeline import describe_frame
from beyond_self.cognition.vision.segmentation import segment
from beyond_self.cognition.vision.tabletop import (
    Camera,
    _draw_shadow,
    make_table,
    random_object,
    render_frame,
)
from beyond_self.core.errors import InputError

LEMON_AND_CUBOID = "saponaro2019/lemon_and_cuboid"
# reference blob descriptors, obj/data.log: first two numbers of each bottle
CUBOID = (204.282318, 110.710175)
LEMON = (131.07933, 108.548279)


@pytest.fixture(scope="module")
def real_frame(shared_data: Path) -> tuple[np.ndarray, np.ndarray]:
    root = shared_data / LEMON_AND_CUBOID
    frame = read_image(root / "imgInput/00000000.ppm", size=(320, 240))
    reference = read_image(root / "imgSeg/00000000.ppm").any(axis=2)
    return frame, reference


def test_reference_descriptors_are_where_the_data_says(shared_data: Path) -> None:
    line = (shared_data / LEMON_AND_CUBOID / "obj/data.log").read_text().split("(")
    assert [float(x) for x in line[1].split()[:2]] == pytest.approx(CUBOID)
    assert [float(x) for x in line[2].split()[:2]] == pytest.approx(LEMON)


def test_lemon_and_cuboid_acceptance(real_frame: tuple[np.ndarray, np.ndarray]) -> None:
    frame, reference = real_frame
    result = describe_frame(frame, ClusterModel.load())
    assert len(result.objects) == 2
    lemon, cuboid = result.objects  # ids are left to right
    assert np.hypot(*np.subtract(lemon.features.centroid, LEMON)) < 5.0
    assert np.hypot(*np.subtract(cuboid.features.centroid, CUBOID)) < 5.0
    assert lemon.labels["Shape"] == "circle"
    assert cuboid.labels["Shape"] == "box"
    fg = result.segmentation.foreground
    iou = (fg & reference).sum() / (fg | reference).sum()
    print(f"foreground IoU vs imgSeg/00000000.ppm: {iou:.3f}")
    assert iou >= 0.8


def test_all_three_real_frames_give_the_same_two_objects(shared_data: Path) -> None:
    root = shared_data / LEMON_AND_CUBOID / "imgInput"
    for name in ("00000001.ppm", "00000002.ppm"):
        objs = segment(read_image(root / name)).objects
        cents = sorted(b.centroid() for b in objs)
        assert len(cents) == 2
        assert np.hypot(*np.subtract(cents[0], LEMON)) < 5.0
        assert np.hypot(*np.subtract(cents[1], CUBOID)) < 5.0


def _scene(
    rng: np.random.Generator, hand_at: tuple[float, float, float] | None
) -> tuple[np.ndarray, np.ndarray, Camera]:
    cam = Camera()
    table = make_table(cam, rng)
    obj = random_object("blue", "circle", "big", rng, jitter=False)
    empty = render_frame(cam, table, [], rng)
    hand = None if hand_at is None else (np.array(hand_at), np.array([0.0, -1.0]))
    return render_frame(cam, table, [(obj, np.array([0.0, 0.0, 0.0]))], rng, hand=hand), empty, cam


def test_shadow_alone_is_not_an_object() -> None:
    rng = np.random.default_rng(3)
    cam = Camera()
    table = make_table(cam, rng)
    shadowed = table.copy()
    _draw_shadow(shadowed, cam, np.array([0.05, 0.0]), 0.3, (0.05, 0.04), 0.0, False, 0.45)
    frame = np.clip(shadowed + 0.5, 0, 255).astype(np.uint8)
    assert (frame.astype(int).sum(2) < table.sum(2) - 60).sum() > 300  # a real, dark shadow
    assert segment(frame).objects == []
    with pytest.raises(InputError, match="no objects found"):
        describe_frame(frame)


def test_hand_touching_an_object_is_split_from_it() -> None:
    rng = np.random.default_rng(4)
    # hand just above (far side of) the big disc, overlapping its outline by ~1 px
    r = 0.045
    frame, empty, cam = _scene(rng, (0.0, r + 0.045 - 0.004, 0.05))
    seg = segment(frame, BackgroundModel.fit([empty]))
    assert len(seg.objects) == 1 and seg.hand is not None
    (obj,) = measure(frame, seg)
    true = cam.project(np.array([0.0, 0.0, r]))
    assert np.hypot(*np.subtract(obj.centroid, true)) < 1.0
    assert obj.circularity > 0.9  # the hand did not eat into it
    assert seg.touching(seg.objects[0])


def test_background_from_empty_frames_and_from_the_frame_agree() -> None:
    rng = np.random.default_rng(5)
    frame, empty, _ = _scene(rng, None)
    a = segment(frame, BackgroundModel.fit([empty])).foreground
    b = segment(frame).foreground
    assert a.sum() > 500
    assert (a & b).sum() / (a | b).sum() > 0.97


def test_bad_frames() -> None:
    with pytest.raises(InputError, match="blank"):
        segment(np.full((240, 320, 3), 128, np.uint8))
    with pytest.raises(InputError, match="at least 16x16"):
        segment(np.zeros((8, 8, 3), np.uint8))
    with pytest.raises(InputError, match="empty"):
        segment(np.zeros((0, 320, 3), np.uint8))
    rng = np.random.default_rng(6)
    frame, empty, _ = _scene(rng, None)
    model = BackgroundModel.fit([empty])
    with pytest.raises(InputError, match="background model is 320x240"):
        segment(frame[:200], model)


def test_640x480_gives_the_same_object_at_twice_the_scale() -> None:
    obj = random_object("yellow", "box", "medium", np.random.default_rng(0), jitter=False)
    cams = (Camera(320, 240), Camera(640, 480))
    feats = []
    for cam in cams:
        rng = np.random.default_rng(8)
        frame = render_frame(cam, make_table(cam, rng), [(obj, np.array([0.1, 0.05, 0.0]))], rng)
        (f,) = measure(frame, segment(frame))
        feats.append(f)
    assert feats[1].area == pytest.approx(4 * feats[0].area, rel=0.05)
    assert feats[1].diameter_m == pytest.approx(feats[0].diameter_m, rel=0.03)
    assert feats[1].rectangularity == pytest.approx(feats[0].rectangularity, abs=0.05)


@pytest.mark.parametrize("shape", [(30, 40), (7, 9), (31, 41)])
@pytest.mark.parametrize("k", [3, 7, 9])
def test_the_table_estimates_median_is_scipys_value_for_value(
    shape: tuple[int, int], k: int
) -> None:
    """median_window replaced scipy's median_filter in the table estimate (a sixth of a frame's
    description); it must give the same numbers, edges included, or every label could move."""
    from scipy import ndimage

    from beyond_self.cognition.vision.background import median_window

    rng = np.random.default_rng(k * 100 + shape[0])
    grid = rng.uniform(0, 255, (*shape, 3)).astype(np.float32)
    grid[: shape[0] // 3] = 200.0  # ties, as on a flat table
    reference = ndimage.median_filter(grid, size=(k, k, 1), mode="nearest")
    assert np.array_equal(median_window(grid, k), reference)


@pytest.mark.parametrize("size", [(240, 320), (239, 317), (1080, 1920)])
def test_block_means_of_bytes_are_the_float_means(size: tuple[int, int]) -> None:
    """The integer path of block_means gives the float32 mean's values exactly."""
    from beyond_self.cognition.vision.background import block_means

    rng = np.random.default_rng(size[1])
    frame = rng.integers(0, 256, (*size, 3), dtype=np.uint8)
    block = max(4, round(min(size) / 30))
    fast = block_means(frame, block)
    slow = block_means(frame.astype(np.float32), block)  # the float path
    assert fast.dtype == slow.dtype == np.float32
    assert np.array_equal(fast, slow)
