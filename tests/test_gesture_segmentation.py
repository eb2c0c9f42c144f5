"""Cutting continuous streams into gestures: one per execution, cut to the movement; rest, drift
and tracker jumps are not gestures (synthetic ground truth and the article's recordings)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from beyond_self.cognition.gestures.datasets import load_gestures
from beyond_self.cognition.gestures.logs import hand_log_stream
from beyond_self.cognition.gestures.segmentation import (
    Discarded,
    GestureSegmenter,
    Segment,
    SegmenterConfig,
    segment_gestures,
)
from beyond_self.cognition.gestures.synthetic import synthesize_continuous
from beyond_self.core.errors import InputError

HUMAN = "saponaro2019/human_data"
REST = np.array([0.9, -1.3, 0.1])  # where the hand rests in the article's recordings


def _iou(a: tuple[int, int], b: tuple[int, int]) -> float:
    inter = min(a[1], b[1]) - max(a[0], b[0])
    return max(inter, 0) / (max(a[1], b[1]) - min(a[0], b[0]))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_finds_every_synthetic_gesture(seed: int) -> None:
    s = synthesize_continuous(5, seed)
    found = segment_gestures(s.features())
    assert len(found) == len(s.gestures)
    for truth, seg in zip(s.gestures, found, strict=True):
        # the gesture starts as the hand leaves its rest, holds the contact with the object,
        # and ends on the way back, before the hand is at rest again
        assert 0 <= seg.start - truth.start <= 0.15 * (truth.stop - truth.start)
        assert truth.contact_start < seg.stop < truth.stop
        assert _iou((truth.start, truth.stop), (seg.start, seg.stop)) > 0.65


def test_streaming_use_reports_each_gesture_once_it_ends() -> None:
    s = synthesize_continuous(["tap", "grasp"], 4)
    seg = GestureSegmenter()
    reported = []
    for t, p in enumerate(s.features()):
        out = seg.push(p)
        if out is not None:
            reported.append((t, out))
    assert [type(out) for _, out in reported] == [Segment, Segment]
    for t, out in reported:
        assert out.stop <= t + 1  # causal: never reports a gesture before its end
    assert seg.finish() is None


def _outcomes(x: np.ndarray) -> list[Segment | Discarded]:
    seg = GestureSegmenter()
    return [r for r in (*(seg.push(p) for p in x), seg.finish()) if r is not None]


def _rest(n: int, rng: np.random.Generator, sigma: float = 0.02) -> np.ndarray:
    return REST + rng.normal(0.0, sigma, (n, 3))


def test_rest_drift_and_small_jumps_are_not_gestures() -> None:
    rng = np.random.default_rng(0)
    # 20 s of rest that drifts by 0.4 body units, with frame-to-frame jumps of 50-100 mm
    # (0.05-0.1 in the logs' thousandths of a body unit) on a third of the frames
    x = _rest(600, rng) + np.linspace(0, 1, 600)[:, None] * np.array([0.2, 0.2, -0.3])
    jumpy = rng.random(600) < 0.33
    x[jumpy] += rng.choice([-1, 1], (int(jumpy.sum()), 3)) * rng.uniform(0.05, 0.1, (1, 3))
    seg = GestureSegmenter()
    assert [r for r in (seg.push(p) for p in x) if r is not None] == []
    assert seg.current_start is None and seg.finish() is None


def test_tracker_failure_and_a_reach_that_never_arrives_are_withdrawn() -> None:
    rng = np.random.default_rng(1)
    # the tracker loses the hand at rest: it jumps between two far places for a second
    far = REST + np.array([0.0, 2.5, -1.5])
    lost = np.where((np.arange(30) % 2 == 0)[:, None], far, REST)
    x = np.concatenate([_rest(30, rng), lost, _rest(40, rng)])
    assert _outcomes(x) == []  # nothing starts
    # ... or while the hand is out: the gesture is withdrawn, saying why
    out = np.linspace(REST, REST + np.array([-0.3, 0.5, -1.6]), 30)
    lost = np.where((np.arange(30) % 2 == 0)[:, None], far, out[-1])
    x = np.concatenate([_rest(30, rng), out, lost, out[::-1], _rest(30, rng)])
    outcomes = _outcomes(x)
    assert len(outcomes) == 1 and isinstance(outcomes[0], Discarded)
    assert outcomes[0].reason.startswith("tracking failed")
    # the hand moves forward a little and comes back: fidgeting, not an action
    out = np.linspace(REST, REST + np.array([0.0, 0.0, -0.6]), 20)
    x = np.concatenate([_rest(30, rng), out, out[::-1], _rest(30, rng)])
    outcomes = _outcomes(x)
    assert len(outcomes) == 1 and isinstance(outcomes[0], Discarded)
    assert "without reaching" in outcomes[0].reason


def test_config_checks_and_bad_input() -> None:
    with pytest.raises(InputError, match="hysteresis"):
        SegmenterConfig(near=0.5, leave=0.4)
    with pytest.raises(InputError, match="turn < back"):
        SegmenterConfig(turn=0.6, back=0.5)
    with pytest.raises(InputError):
        segment_gestures(np.zeros((5, 2)))
    with pytest.raises(InputError, match="finite"):
        GestureSegmenter().push([0.0, float("nan"), 0.0])


# executions counted by eye in plots of the recordings: each is an excursion of the hand from
# near the body to the object and back
REPETITIONS = {"grasp1_hand": 4, "tap1_hand": 3, "touch1_hand": 4, "push1_hand": 3}


@pytest.mark.parametrize(("name", "count"), sorted(REPETITIONS.items()))
def test_article_recordings_split_into_their_executions(
    shared_data: Path, name: str, count: int
) -> None:
    found = segment_gestures(hand_log_stream(shared_data / HUMAN / name)[1])
    assert len(found) == count
    for seg in found:
        assert 60 <= len(seg) <= 180  # 2 to 6 s at 30 frames/s


def test_tap1_is_cut_where_the_article_cut_it(shared_data: Path) -> None:
    """The article's hand-picked ranges (misc/glu_gestures.m), 1-based inclusive, within 10."""
    found = segment_gestures(hand_log_stream(shared_data / HUMAN / "tap1_hand")[1])
    article = [(216, 351), (401, 511), (557, 664)]
    assert len(found) == len(article)
    for seg, (first, last) in zip(found, article, strict=True):
        assert abs(seg.first - first) <= 10 and abs(seg.last - last) <= 10, (seg, first, last)


@pytest.mark.parametrize(
    ("name", "first", "last"),
    [("tap_notable_seated_1", 121, 214), ("norobotview_tap_notable_seated_2", 230, 375)],
)
def test_one_tap_is_one_gesture_holding_the_articles_range(
    shared_data: Path, name: str, first: int, last: int
) -> None:
    found = segment_gestures(hand_log_stream(shared_data / HUMAN / name)[1])
    holding = [s for s in found if s.first <= first and last <= s.last + 10]
    assert len(holding) == 1
    assert all(s is holding[0] or s.last < first or s.first > last for s in found)


def test_dataset_folder_labels_and_leaves_push_out(shared_data: Path) -> None:
    folder = shared_data / HUMAN
    gestures = load_gestures(folder)
    counts = {a: sum(g.action == a for g in gestures) for a in ("grasp", "tap", "touch")}
    assert counts["grasp"] == 4 and counts["touch"] == 4
    assert counts["tap"] >= 5  # tap1's three, and the two seated ones
    assert {g.recording for g in gestures if g.action == "tap"} >= {
        "tap1_hand",
        "tap_notable_seated_1",
        "norobotview_tap_notable_seated_2",
    }
    with_push = load_gestures(folder, push_as="touch")
    assert sum(g.action == "touch" for g in with_push) == 7
    with pytest.raises(InputError, match="MCAP"):
        load_gestures(folder / "x.mcap")
