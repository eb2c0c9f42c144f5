"""Resume, don't replay (issue 21): a restarted gesture streamer rebuilds its state from a
checkpoint and makes exactly the events its predecessor would have made."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from beyond_self.cognition.episodes import Belief, Cancelled, Ended, GestureTracker, Started
from beyond_self.cognition.episodes.offline import SkeletonInput
from beyond_self.cognition.gestures import extract_features
from beyond_self.cognition.gestures.default_models import default_models
from beyond_self.commands.analyse import _inputs

RECORDINGS = sorted((Path(__file__).resolve().parent.parent / "recordings").glob("*.mcap"))


def described(event: Any) -> tuple[Any, ...]:
    """What an event says, comparable across trackers."""
    if isinstance(event, Started):
        return ("start", event.segment_id, event.frame, event.stamp)
    if isinstance(event, Belief):
        return ("belief", event.segment_id, event.frame, event.final, tuple(event.posterior))
    if isinstance(event, Ended):
        return ("end", event.segment_id, event.frame, event.start_stamp, event.end_stamp)
    assert isinstance(event, Cancelled)
    return ("cancel", event.segment_id, event.frame)


def frames(path: Path, passes: int = 3) -> list[tuple[int, int, Any]]:
    """The recording's skeleton frames (stamp, number, features), played `passes` times, each
    pass later than the one before (as a looped ingest plays it)."""
    one = [
        (item.stamp, item.frame, extract_features(item.hand, item.torso)[0])
        for item in _inputs(path, "right_hand", "torso")
        if isinstance(item, SkeletonInput)
    ]
    period = one[-1][0] - one[0][0] + 1_000_000_000
    return [(stamp + k * period, n, x) for k in range(passes) for stamp, n, x in one]


@pytest.mark.parametrize("path", RECORDINGS, ids=[p.name for p in RECORDINGS])
def test_a_tracker_started_at_any_checkpoint_makes_the_same_events(path: Path) -> None:
    models = default_models()
    stream = frames(path)
    full: GestureTracker[int] = GestureTracker(models)
    after: list[list[Any]] = []  # events made while pushing frame i
    checkpoints: dict[tuple[int, int], int] = {}  # checkpoint -> first frame index it was seen
    for i, (stamp, number, x) in enumerate(stream):
        after.append([described(e) for e in full.push(stamp, number, x, number)])
        assert full.checkpoint is not None
        checkpoints.setdefault(full.checkpoint, i)
    tail = [described(e) for e in full.finish()]
    index = {stamp: i for i, (stamp, _, _) in enumerate(stream)}
    assert len(checkpoints) > 3, "quiet stretches give checkpoints besides the first frame"
    assert max(seg for _, seg in checkpoints) >= 1, "some checkpoint comes after a gesture"
    assert len({seg for _, seg in checkpoints}) > 2, "checkpoints between several gestures"
    found = list(checkpoints.items())
    sample = [found[round(k * (len(found) - 1) / 4)] for k in range(5)]  # first, ..., last
    for (stamp, segments), seen_at in sample:
        start = index[stamp]
        assert seen_at >= start  # a checkpoint is known once its quiet stretch has passed
        fresh: GestureTracker[int] = GestureTracker(models, first_segment_id=segments)
        made = [[described(e) for e in fresh.push(s, n, x, n)] for s, n, x in stream[start:]]
        assert made == after[start:], (path.name, stamp, segments)
        assert [described(e) for e in fresh.finish()] == tail
