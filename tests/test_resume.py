"""Resume, don't replay (issue 21): a restarted gesture streamer rebuilds its state from a
checkpoint and makes exactly the events its predecessor would have made."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from beyond_self.cognition.episodes import Belief, Cancelled, Ended, GestureTracker, Started
from beyond_self.cognition.episodes.offline import SkeletonInput
from beyond_self.cognition.episodes.tracker import TrackerSnapshot
from beyond_self.cognition.gestures import extract_features
from beyond_self.cognition.gestures.default_models import default_models
from beyond_self.commands.analyse import _inputs

RECORDINGS = sorted((Path(__file__).resolve().parent.parent / "recordings").glob("*.mcap"))


def described(event: Any) -> tuple[Any, ...]:
    """What an event says, comparable across trackers."""
    if isinstance(event, Started):
        return ("start", event.segment_id, event.frame, event.stamp, event.seq)
    if isinstance(event, Belief):
        return ("belief", event.segment_id, event.frame, event.final, tuple(event.posterior))
    if isinstance(event, Ended):
        return ("end", event.segment_id, event.frame, event.start_stamp, event.end_stamp, event.seq)
    assert isinstance(event, Cancelled)
    return ("cancel", event.segment_id, event.frame, event.seq)


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
    checkpoints: dict[TrackerSnapshot, int] = {}  # snapshot -> first frame index it was seen
    for i, (stamp, number, x) in enumerate(stream):
        after.append([described(e) for e in full.push(stamp, number, x, number)])
        snapshot = full.snapshot()
        assert snapshot is not None
        checkpoints.setdefault(snapshot, i)
    tail = [described(e) for e in full.finish()]
    index = {stamp: i for i, (stamp, _, _) in enumerate(stream)}
    assert len(checkpoints) > 3, "quiet stretches give checkpoints besides the first frame"
    assert max(c.gestures for c in checkpoints) >= 1, "some checkpoint comes after a gesture"
    assert len({c.gestures for c in checkpoints}) > 2, "checkpoints between several gestures"
    assert all(c.events == 2 * c.gestures for c in checkpoints), "quiet: each one started, ended"
    found = list(checkpoints.items())
    sample = [found[round(k * (len(found) - 1) / 4)] for k in range(5)]  # first, ..., last
    for snapshot, seen_at in sample:
        start = index[snapshot.stamp]
        assert seen_at >= start  # a checkpoint is known once its quiet stretch has passed
        fresh: GestureTracker[int] = GestureTracker.restored(models, snapshot)
        made = [[described(e) for e in fresh.push(s, n, x, n)] for s, n, x in stream[start:]]
        assert made == after[start:], (path.name, snapshot)
        assert [described(e) for e in fresh.finish()] == tail


def test_an_object_watch_started_at_its_restart_point_makes_the_same_outputs() -> None:
    """A restarted object segmenter gets back the gesture events and, from its predecessor's
    restart point on, the camera frames: it then makes exactly the outputs its predecessor
    would have made, without going over the whole camera history again."""
    from test_episodes import streams

    from beyond_self.cognition.episodes import (
        FrameObjects,
        GestureEffects,
        ObjectAtStart,
        ObjectWatch,
    )
    from beyond_self.cognition.vision.clusters import ClusterModel

    cameras, events, progress = streams()
    segments = [e for e in events if isinstance(e, Started | Ended | Cancelled)]
    counts = [sum(1 for e in events[:n] if e in segments) for _, n in progress]
    timed = [(c.stamp, 0, c) for c in cameras] + [
        (getattr(e, "end_stamp", None) or e.stamp, 1, e) for e in segments
    ]
    timed += [(stamp, 2, (stamp, n)) for (stamp, _), n in zip(progress, counts, strict=True)]
    order = [(lane, item) for _, lane, item in sorted(timed, key=lambda t: (t[0], t[1]))]

    def feed(watch: ObjectWatch[int], lane: int, item: Any) -> list[Any]:
        if lane == 0:  # as a replaying segmenter does: the gestures' part, then its objects
            made = watch.camera(item.stamp, item.frame, item.image)
            return [*made, watch.frame_objects(item.stamp, item.frame, item.image, item.frame)]
        if lane == 2:
            return watch.gestures_complete(item[0])
        if isinstance(item, Started):
            return watch.started(item.segment_id, item.stamp, item.ref)
        if isinstance(item, Ended):
            return watch.ended(item.segment_id, item.start_stamp, item.end_stamp, item.frame, 0)
        return watch.cancelled(item.segment_id)

    def said(outputs: list[Any]) -> list[tuple[Any, ...]]:
        out: list[tuple[Any, ...]] = []
        for o in outputs:
            if isinstance(o, FrameObjects):
                out.append(("frame", o.frame, [sorted(x.labels.items()) for x in o.objects]))
            elif isinstance(o, ObjectAtStart):
                out.append(("start", o.segment_id, o.frame, sorted(o.labels.items())))
            elif isinstance(o, GestureEffects):
                out.append(("effects", o.segment_id, sorted(o.effect_labels.items())))
        return out

    clusters = ClusterModel.load()
    full: ObjectWatch[int] = ObjectWatch(clusters)
    after: list[list[tuple[Any, ...]]] = []
    points: list[int] = []
    for lane, item in order:
        after.append(said(feed(full, lane, item)))
        points.append(full.restart_point)
    starts = [i for i, (_, item) in enumerate(order) if isinstance(item, Started)]
    ends = [i for i, (_, item) in enumerate(order) if isinstance(item, Ended)]
    cameras_at = [i for i in range(len(order)) if order[i][0] == 0]
    during = next(i for i in cameras_at if starts[0] < i < ends[0])
    cuts = [during, cameras_at[-5]]  # mid-gesture, and after it
    assert any(points[i] > cameras[0].stamp for i in cuts), "the restart point moves on"
    for cut in cuts:
        fresh: ObjectWatch[int] = ObjectWatch(clusters)
        told_before = {o[1] for outs in after[: cut + 1] for o in outs if o[0] == "effects"}
        fresh.done(told_before)
        got: list[tuple[Any, ...]] = []
        for lane, item in order[: cut + 1]:  # what the caches give back, events first
            if lane == 1:
                got += said(feed(fresh, lane, item))
        for lane, item in order[: cut + 1]:
            if lane == 0 and item.stamp >= points[cut]:
                got += said(feed(fresh, lane, item))
        for lane, item in order[cut + 1 :]:
            got += said(feed(fresh, lane, item))
        wanted = [o for outs in after[cut + 1 :] for o in outs]
        said_ever = {(o[0], o[1]): o for outs in after for o in outs if o[0] != "frame"}
        for o in got:  # what it says again is what was said (a consumer that has it skips it)
            if o[0] != "frame":
                assert said_ever[(o[0], o[1])] == o, (cut, o)
        assert [o for o in wanted if o[0] != "frame" and o not in got] == [], cut  # nothing lost
        frames = [o for o in got if o[0] == "frame"]
        later = [o for o in wanted if o[0] == "frame"]
        assert frames[len(frames) - len(later) :] == later  # the frames from then on alike
