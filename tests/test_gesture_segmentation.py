"""Cutting continuous streams into gestures: synthetic ground truth and the article's recordings."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from beyond_self.cognition.gestures.datasets import load_gestures
from beyond_self.cognition.gestures.features import extract_features
from beyond_self.cognition.gestures.logs import read_hand_log
from beyond_self.cognition.gestures.segmentation import (
    GestureSegmenter,
    SegmenterConfig,
    segment_gestures,
)
from beyond_self.cognition.gestures.synthetic import synthesize_continuous
from beyond_self.core.errors import InputError


def _iou(a: tuple[int, int], b: tuple[int, int]) -> float:
    inter = min(a[1], b[1]) - max(a[0], b[0])
    return max(inter, 0) / (max(a[1], b[1]) - min(a[0], b[0]))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_finds_every_synthetic_gesture(seed: int) -> None:
    s = synthesize_continuous(5, seed)
    found = segment_gestures(s.features())
    assert len(found) == len(s.gestures)
    for truth, seg in zip(s.gestures, found, strict=True):
        assert _iou((truth.start, truth.stop), (seg.start, seg.stop)) > 0.65


def test_streaming_use_reports_each_gesture_once_it_ends() -> None:
    s = synthesize_continuous(["tap", "grasp"], 4)
    seg = GestureSegmenter()
    reported = []
    for t, p in enumerate(s.features()):
        out = seg.push(p)
        if out is not None:
            reported.append((t, out))
    assert len(reported) == 2
    for t, out in reported:
        assert out.stop <= t + 1  # causal: never reports a gesture before its end
    assert seg.finish() is None


def test_speed_only_mode_and_config_checks() -> None:
    # a hand that is still, moves for 1 s, is still again: one gesture without a reach cue
    still = np.zeros((40, 3))
    move = np.linspace([0, 0, 0], [0.0, 2.0, 0.0], 30)  # 2 units/s
    x = np.concatenate([still, move, np.repeat(move[-1:], 40, axis=0)])
    found = segment_gestures(x, SegmenterConfig(reach_on=None))
    assert len(found) == 1
    assert abs(found[0].start - 40) <= 3 and abs(found[0].stop - 70) <= 8
    with pytest.raises(InputError):
        SegmenterConfig(rest_speed=2.0, move_speed=1.0)
    with pytest.raises(InputError):
        segment_gestures(np.zeros((5, 2)))


# repetitions counted by eye in plots of the recordings: each is an excursion of the hand from
# near the body to the object on the table and back
REPETITIONS = {"grasp1_hand": 4, "tap1_hand": 3, "touch1_hand": 4, "push1_hand": 3}


@pytest.mark.parametrize(("name", "count"), sorted(REPETITIONS.items()))
def test_article_recordings_split_into_their_repetitions(
    shared_data: Path, name: str, count: int
) -> None:
    log = read_hand_log(shared_data / "saponaro2019/human_data" / name)
    found = segment_gestures(extract_features(log.xyz, scale=0.001))
    assert len(found) == count
    for seg in found:
        assert 60 <= len(seg) <= 240  # 2 to 8 s at 30 frames/s


def test_dataset_folder_labels_and_leaves_push_out(shared_data: Path) -> None:
    folder = shared_data / "saponaro2019/human_data"
    gestures = load_gestures(folder)
    counts = {a: sum(g.action == a for g in gestures) for a in ("grasp", "tap", "touch")}
    assert counts == {"grasp": 4, "tap": 3, "touch": 4}
    with_push = load_gestures(folder, push_as="touch")
    assert sum(g.action == "touch" for g in with_push) == 7
    with pytest.raises(InputError, match="MCAP"):
        load_gestures(folder / "x.mcap")
