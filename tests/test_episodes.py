"""The per-gesture logic (cognition.episodes) gives the same outputs whatever order its input
streams interleave in: only the order within each stream is kept, as on the bus."""

from __future__ import annotations

import gc
import random
from collections.abc import Callable
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from beyond_self.cognition.bn import learn_network, synthetic_dataset
from beyond_self.cognition.episodes import (
    Anticipation,
    Belief,
    Cancelled,
    Ended,
    FrameObjects,
    FusionJoin,
    GestureEffects,
    GestureReport,
    GestureTracker,
    Lost,
    ObjectAtStart,
    ObjectWatch,
    Outcome,
    Started,
)
from beyond_self.cognition.episodes.objects import EVICTED_KEPT, LOOK_BACK_FRAMES
from beyond_self.cognition.episodes.offline import CameraInput, SkeletonInput, analyse_stream
from beyond_self.cognition.gestures import extract_features
from beyond_self.cognition.gestures.default_models import default_models
from beyond_self.cognition.vision.clusters import ClusterModel
from beyond_self.commands.analyse import _inputs
from beyond_self.schemas.base import Header

RECORDING = Path(__file__).resolve().parent.parent / "recordings" / "touch-box.mcap"


@cache
def streams() -> tuple[list[CameraInput], list[Any], list[tuple[int, int]]]:
    """Camera frames, the tracker's events, and (skeleton stamp, events published so far)
    after every skeleton frame (what the gesture streamer's Progress says)."""
    items = list(_inputs(RECORDING, "right_hand", "torso"))
    tracker: GestureTracker[int] = GestureTracker(default_models())
    events: list[Any] = []
    progress: list[tuple[int, int]] = []
    for item in items:
        if isinstance(item, SkeletonInput):
            x = extract_features(item.hand, item.torso)[0]
            events += tracker.push(item.stamp, item.frame, x, item.frame)
            progress.append((item.stamp, len(events)))
    events += tracker.finish()
    cameras = [i for i in items if isinstance(i, CameraInput)]
    return cameras, events, progress


def interleave(rng: random.Random, *lanes: list[Any]) -> list[tuple[int, Any]]:
    """A random merge of the lanes keeping each lane's order."""
    pos = [0] * len(lanes)
    out = []
    while any(p < len(lane) for p, lane in zip(pos, lanes, strict=True)):
        k = rng.choice([i for i, lane in enumerate(lanes) if pos[i] < len(lane)])
        out.append((k, lanes[k][pos[k]]))
        pos[k] += 1
    return out


def watch_outputs(
    order: list[tuple[int, Any]],
    described: Callable[[int], bool] = lambda frame: True,
    steps: Callable[[], int] = lambda: 0,
    **options: Any,
) -> list[tuple[Any, ...]]:
    """The watch's outputs for the inputs in `order`, the objects of the frames `described`
    asked for after each (a live object segmenter skips some), and `steps()` calls of
    `catch_up` after each input (a service makes them between messages)."""
    watch: ObjectWatch[int] = ObjectWatch(ClusterModel.load(), **options)
    segment_events = [e for e in streams()[1] if isinstance(e, Started | Ended | Cancelled)]
    seen = 0
    outputs: list[Any] = []
    for lane, item in order:
        for _ in range(steps()):
            watch.catch_up()
        if lane == 0:
            outputs += watch.camera(item.stamp, item.frame, item.image)
            if described(item.frame):
                outputs.append(watch.frame_objects(item.stamp, item.frame, item.image, item.frame))
        elif lane == 1:
            seen += 1
            if isinstance(item, Started):
                outputs += watch.started(item.segment_id, item.stamp, item.ref)
            elif isinstance(item, Ended):
                outputs += watch.ended(
                    item.segment_id, item.start_stamp, item.end_stamp, item.frame, item.ref
                )
            else:
                outputs += watch.cancelled(item.segment_id)
        else:  # the streamer's progress: complete up to its stamp once its events are all here
            stamp, published = item
            published = sum(
                1 for e in streams()[1][:published] if isinstance(e, Started | Ended | Cancelled)
            )
            if published <= seen:
                outputs += watch.gestures_complete(stamp)
    outputs += watch.camera_ended(streams()[0][-1].stamp)
    assert seen == len(segment_events)
    summary: list[tuple[Any, ...]] = []
    for out in outputs:
        if isinstance(out, FrameObjects):
            summary.append(
                ("frame", out.frame, tuple(sorted(o.labels.items()) for o in out.objects))
            )
        elif isinstance(out, ObjectAtStart):
            summary.append(("start", out.segment_id, out.frame, sorted(out.labels.items())))
        elif isinstance(out, GestureEffects):
            summary.append(("effects", out.segment_id, sorted(out.effect_labels.items())))
    return summary


def stamp_order() -> list[tuple[int, Any]]:
    """Camera frames and gesture events in stamp order, as the offline analysis feeds them."""
    cameras, events, _ = streams()
    segment_events = [e for e in events if isinstance(e, Started | Ended | Cancelled)]
    return sorted(
        [(0, c) for c in cameras] + [(1, e) for e in segment_events],
        key=lambda x: x[1].stamp if x[0] == 0 else getattr(x[1], "end_stamp", None) or x[1].stamp,
    )


@cache
def watch_reference() -> list[tuple[Any, ...]]:
    """The object watch's outputs in stamp order (the same for every example: computed once)."""
    return watch_outputs(stamp_order())


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), share=st.sampled_from([0.0, 0.3, 1.0]))
def test_object_watch_ignores_arrival_order_and_skipped_frames(seed: int, share: float) -> None:
    """Any interleaving, any share of the frames described for their own sake (a live segmenter
    skips frames under load), and the gestures' frames analysed early or late (`catch_up`): the
    per-gesture results are the reference's, and every frame described has the reference's
    objects."""
    cameras, events, progress = streams()
    segment_events = [e for e in events if isinstance(e, Started | Ended | Cancelled)]
    reference = watch_reference()
    rng = random.Random(seed)
    order = interleave(rng, cameras, segment_events, progress)
    chosen = {c.frame for c in cameras if rng.random() < share}
    shuffled = watch_outputs(order, chosen.__contains__, lambda: rng.randrange(3))
    assert [o for o in shuffled if o[0] != "frame"] == [o for o in reference if o[0] != "frame"]
    assert [o for o in shuffled if o[0] == "frame"] == [
        o for o in reference if o[0] == "frame" and o[1] in chosen
    ]
    kinds = {s[0] for s in reference}
    assert kinds == {"frame", "start", "effects"}  # the recording's gesture was seen and measured


def test_the_history_cap_analyses_a_gestures_queued_frames_before_dropping_them() -> None:
    """Nobody catches up (no `catch_up` calls) and the history holds a dozen frames, fewer than
    the gesture has: the frames it queued are analysed as the cap drops them, not lost."""
    cameras, _, _ = streams()
    capped = watch_outputs(
        stamp_order(), lambda frame: False, buffer_bytes=12 * cameras[0].image.nbytes
    )
    reference = watch_reference()
    assert [o for o in capped if o[0] != "frame"] == [o for o in reference if o[0] != "frame"]
    assert any(o[0] == "effects" and o[2] for o in capped)  # measured


def test_a_start_looks_back_past_frames_dropped_undescribed() -> None:
    """The object at a start is the last frame at or before it that showed one, also when that
    frame and many after it were dropped from the history before anyone described them."""
    cameras, _, _ = streams()
    with_object = cameras[0]
    table = np.broadcast_to(
        np.median(with_object.image.reshape(-1, 3), axis=0).astype(np.uint8),
        with_object.image.shape,
    )
    step = 66_666_667
    frames = [(with_object.stamp, 1, with_object.image)] + [
        (with_object.stamp + k * step, k + 1, table)
        for k in range(1, LOOK_BACK_FRAMES + EVICTED_KEPT + 8)
    ]
    start = frames[-1][0] + step
    results = []
    for eager in (False, True):
        watch: ObjectWatch[int] = ObjectWatch(ClusterModel.load())
        for stamp, frame, image in frames:
            watch.camera(stamp, frame, image)
            if eager:
                watch.frame_objects(stamp, frame, image, frame)
        watch.gestures_complete(start + 10**10)  # all but the last look-back can be dropped
        assert len(watch.buffer) == LOOK_BACK_FRAMES
        watch.camera(start + step, len(frames) + 1, table)
        results += [o for o in watch.started(1, start, 0) if isinstance(o, ObjectAtStart)]
    assert [(r.frame, r.reason) for r in results] == [(1, ""), (1, "")]
    assert (
        results[0].labels
        == results[1].labels
        == {
            "Color": "green2",
            "Shape": "box",
            "Size": "medium",
        }
    )


def test_an_hour_without_frames_is_a_pause_not_a_reason_to_refuse_or_drop() -> None:
    """Issue 39: the skeleton's complete time jumps an hour (the robot idled) before the start
    of a gesture that began before the pause is heard of (the segmenter places onsets back):
    the start is taken, its object comes from the frames before the pause, and a gesture open
    across the pause is not dropped as a stray start."""
    cameras, _, _ = streams()
    step, hour = 66_666_667, 3600 * 10**9
    frames = [(cameras[0].stamp + k * step, k + 1, cameras[0].image) for k in range(10)]
    watch: ObjectWatch[int] = ObjectWatch(ClusterModel.load())
    for stamp, frame, image in frames:
        watch.camera(stamp, frame, image)
    before = frames[-1][0]
    watch.gestures_complete(before + hour)  # the skeleton ran on past the pause first
    watch.camera(before + hour, 11, cameras[0].image)
    outputs = watch.started(1, before - 2 * step, 0)  # began before the pause: not refused
    (start,) = [o for o in outputs if isinstance(o, ObjectAtStart)]
    assert (start.frame, start.reason) == (8, "")
    assert start.labels == {"Color": "green2", "Shape": "box", "Size": "medium"}
    # open across a second pause of a day: still under way, then ended and measured
    watch.gestures_complete(before + hour + 24 * hour)
    for k in range(1, 6):
        watch.camera(before + hour + 24 * hour + k * step, 11 + k, cameras[0].image)
    assert 1 in watch.windows and watch.abandoned == 0
    end = before + 25 * hour + 5 * step
    outputs = watch.ended(1, before - 2 * step, end, 20, 0)
    outputs += watch.camera_ended(end)
    assert [o.segment_id for o in outputs if isinstance(o, GestureEffects)] == [1]


@pytest.fixture(scope="module")
def network():  # type: ignore[no-untyped-def]
    return learn_network(synthetic_dataset())


def join_outputs(network: Any, order: list[tuple[int, Any]]) -> list[tuple[Any, ...]]:
    join: FusionJoin[int] = FusionJoin(network)
    join.objects_alive(True)
    actions = list(default_models().actions)
    out: list[Any] = []
    for lane, item in order:
        if lane == 0:
            if isinstance(item, Belief):
                belief = dict(zip(actions, item.posterior, strict=True))
                out += join.belief(
                    item.segment_id, item.frame, item.stamp, belief, item.ref, item.final
                )
            elif isinstance(item, Started):
                out += join.started(item.segment_id, item.stamp)
            elif isinstance(item, Ended):
                out += join.ended(item.segment_id, item.start_stamp, item.end_stamp)
        elif lane == 1:
            out += join.object_seen(item[0], item[1])
        else:
            out += join.effects_seen(item[0], item[1], item[2])
    return [
        (type(o).__name__, o.segment_id, o.frame, sorted(o.prediction.action_belief.items()),
         sorted(o.words.items()) if isinstance(o, Outcome) else ())
        for o in out
        if isinstance(o, Anticipation | Outcome)
    ]  # fmt: skip


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_fusion_join_ignores_arrival_order(network: Any, seed: int) -> None:
    _, events, _ = streams()
    gesture_events = [e for e in events if isinstance(e, Belief | Started | Ended)]
    ids = sorted({e.segment_id for e in gesture_events})
    objects = [(i, {"Color": "green2", "Shape": "box", "Size": "medium"}) for i in ids]
    effects = [(i, {}, {"ObjVel": "slow", "Contact": "short"}) for i in ids]
    lanes = (gesture_events, objects, effects)
    in_order = [(0, e) for e in gesture_events] + [(1, o) for o in objects]
    reference = join_outputs(network, in_order + [(2, f) for f in effects])
    assert reference and reference[-1][0] == "Outcome"
    assert join_outputs(network, interleave(random.Random(seed), *lanes)) == reference


def test_offline_run_describes_the_recording(network: Any) -> None:
    run = analyse_stream(
        _inputs(RECORDING, "right_hand", "torso"),
        gesture_models=default_models(),
        clusters=ClusterModel.load(),
        network=network,
    )
    assert [o.segment_id for o in run.outcomes] == [1]
    belief = run.outcomes[0].prediction.action_belief
    assert max(belief, key=belief.__getitem__) == "touch"  # the recording shows a touch
    assert run.object_at_start[1].labels == {"Color": "green2", "Shape": "box", "Size": "medium"}
    assert run.effects[1].analysis is not None
    assert any("touch" in line for line in run.lines if line.endswith('"'))


def test_report_skips_a_start_that_never_completes() -> None:
    report = GestureReport()
    report.started(1, 10)  # a stray start: nothing else ever comes for it
    report.started(2, 40)
    report.believed(2)
    report.ended(2, 80)
    report.recognised(2, {"tap": 0.9, "grasp": 0.1}, {"Shape": "circle"})
    assert report.release() == []  # gesture 2 is not described yet: 1 may still complete
    report.described(2, "the robot tapped the ball")
    lines = report.release()
    assert lines[0] == "gesture 2: started at frame 40" and lines[-1].endswith(
        '"the robot tapped the ball"'
    )
    assert report.all_printed


def test_a_gesture_waits_for_its_beliefs_whatever_overtakes_them() -> None:
    """Under load a belief can be held up (a gap filled from the gesture streamer's cache) while
    the end, the recognition and the description, down other paths, arrive: the gesture's lines
    wait for its final belief, or for a belief about a later gesture (beliefs come in order),
    and are then the same as when nothing was held up (CI: 'looks like grasp' missing once)."""

    def said(report: GestureReport, n: int) -> None:
        report.started(n, 10 * n)
        report.ended(n, 10 * n + 5)
        report.recognised(n, {"grasp": 0.9, "tap": 0.1}, {})
        report.described(n, "the robot grasped the ball")

    in_order, overtaken = GestureReport(), GestureReport()
    in_order.started(1, 10)
    in_order.belief(1, 11, ["grasp", "tap"], [0.9, 0.1])
    in_order.believed(1)
    said(in_order, 1)
    expected = in_order.release()
    assert "gesture 1: frame 11, looks like grasp (P_HMM 0.90)" in expected

    said(overtaken, 1)
    assert overtaken.release() == []  # ended, recognised, described: its beliefs are not in
    overtaken.belief(1, 11, ["grasp", "tap"], [0.9, 0.1])
    assert overtaken.release() == []
    overtaken.believed(1)
    assert overtaken.release() == expected

    said(overtaken, 2)  # its final belief lost for good: a belief about gesture 3 releases it
    assert overtaken.release() == []
    overtaken.belief(3, 31, ["grasp", "tap"], [0.9, 0.1])
    assert [line for line in overtaken.release() if "looks like" in line] == []
    assert overtaken.gestures[2].printed
    overtaken.believed(5)
    said(overtaken, 4)  # first heard of after a belief about a later gesture: its beliefs are in
    assert overtaken.gestures[4].final_belief


def test_a_trackers_frame_buffer_stays_out_of_the_garbage_collector() -> None:
    """A fleet's gesture streamer keeps a tracker per robot, each with up to 1,800 frames: as
    tracked objects they made every full collection walk them (bench/fleet.py,
    runtime.process.heap)."""
    hand = [i for i in _inputs(RECORDING, "right_hand", "torso") if isinstance(i, SkeletonInput)]
    tracker: GestureTracker[Header] = GestureTracker(default_models())
    for item in hand:
        ref = Header(version=1, source="test", seq=item.frame, stamp=item.stamp)
        tracker.push(item.stamp, item.frame, extract_features(item.hand, item.torso)[0], ref)
    assert len(tracker.buffer) == len(hand) > 100
    assert not any(gc.is_tracked(frame) for frame in tracker.buffer)
    assert tracker.buffer[-1].ref.seq == hand[-1].frame  # and the frame keeps what it was given


def test_tracker_cancels_a_gesture_the_source_cut_short() -> None:
    _, events, _ = streams()
    assert [type(e).__name__ for e in events if not isinstance(e, Belief)] == ["Started", "Ended"]
    tracker: GestureTracker[int] = GestureTracker(default_models())
    cameras, _, _ = streams()
    hand = [i for i in _inputs(RECORDING, "right_hand", "torso") if isinstance(i, SkeletonInput)]
    cut = next(e for e in events if isinstance(e, Started)).frame + 20  # mid-gesture
    out = []
    for item in hand[:cut]:
        out += tracker.push(item.stamp, item.frame, extract_features(item.hand, item.torso)[0], 0)
    out += tracker.finish()
    assert isinstance(out[-1], Cancelled | Ended)
    assert any(isinstance(e, Started) for e in out)
    assert len(cameras) > 0


def test_a_long_run_keeps_a_bounded_record_of_the_gestures_it_told() -> None:
    """The lines of a soak's thousands of gestures: each printed once, the record of old ones
    forgotten (issue 21: resident memory flat)."""
    from beyond_self.cognition.episodes.join import Recent
    from beyond_self.cognition.episodes.report import KEPT

    report = GestureReport()
    printed = 0
    for n in range(1, 2 * KEPT + 50):
        report.started(n, 10)
        report.believed(n)
        report.ended(n, 20)
        report.recognised(n, {"tap": 1.0}, {})
        report.described(n, "the robot tapped the ball")
        printed += len(report.release())
    assert printed == (2 * KEPT + 49) * 4  # started, ended, recognised, described
    assert len(report.gestures) == KEPT
    recent = Recent(size=3)
    for n in range(10):
        recent.add(n)
    assert [n in recent for n in (6, 7, 8, 9)] == [False, True, True, True]


def test_a_late_reasoner_gets_the_posterior_history_before_the_segment_history(
    network: Any,
) -> None:
    """A workstation started late gets each stream's history as a batch of its own, in no fixed
    order. Two gestures 40 s of stream time apart: every posterior (up to the second gesture's
    final one) before any start or end event. The first gesture's end event is only late, not
    lost: both are described (the join dropped the first once the posteriors had run 30 s past
    it, whatever the segment stream said)."""
    join: FusionJoin[int] = FusionJoin(network, expect_objects=False)
    second = 40 * 10**9
    belief = {"tap": 0.9, "grasp": 0.05, "touch": 0.05}
    out: list[Any] = []
    for segment_id, start in ((1, 0), (2, second)):
        for frame in range(3):
            stamp = start + frame * 33_333_333
            out += join.belief(segment_id, frame, stamp, belief, frame, final=frame == 2)
    for segment_id, start in ((1, 0), (2, second)):
        out += join.started(segment_id, start)
        out += join.ended(segment_id, start, start + 2 * 33_333_333)
    assert [o.segment_id for o in out if isinstance(o, Outcome)] == [1, 2]
    # a gesture whose end never comes is still given up once the segment stream moves on
    lost: FusionJoin[int] = FusionJoin(network, expect_objects=False)
    lost.started(1, 0)
    lost.belief(1, 0, 0, belief, 0, final=True)
    outcomes = lost.started(2, second) + lost.belief(2, 0, second, belief, 0, final=True)
    outcomes += lost.ended(2, second, second + 1)
    assert [o.segment_id for o in outcomes if isinstance(o, Outcome)] == [2]


def test_a_lost_final_belief_gives_its_gesture_up_and_holds_nothing_back(network: Any) -> None:
    """A link cut longer than the streamer's cache: gesture 1's final belief is lost for good.
    Told so with the first belief after the gap, the join gives 1 up at once (`Lost`) and
    describes 2 and 3; without being told it would wait 30 s of belief stream time."""
    belief = {"tap": 0.9, "grasp": 0.05, "touch": 0.05}
    join: FusionJoin[int] = FusionJoin(network, expect_objects=False)
    out = join.started(1, 0) + join.belief(1, 0, 0, belief, 0) + join.ended(1, 0, 10)
    out += join.started(2, 20) + join.ended(2, 20, 30) + join.started(3, 40)
    assert not [o for o in out if isinstance(o, Outcome | Lost)]  # 1 holds 2 back
    out = join.beliefs_missed(2, 7) + join.belief(2, 1, 30, belief, 1, final=True)
    out += join.belief(3, 0, 40, belief, 0, final=True) + join.ended(3, 40, 40)
    told = [(type(o).__name__, o.segment_id) for o in out if isinstance(o, Outcome | Lost)]
    assert told == [("Lost", 1), ("Outcome", 2), ("Outcome", 3)]
    assert "7 belief(s)" in next(o.reason for o in out if isinstance(o, Lost))
    # whatever comes about 1 afterwards (a late repeat) changes nothing
    assert join.belief(1, 1, 10, belief, 1, final=True) == []


def test_a_lost_object_or_effects_message_gives_its_gesture_up(network: Any) -> None:
    """While the object segmenter is alive a gesture waits for its object and its effects;
    one of those lost for good (a chaos run: a gesture object no cache held) held every later
    gesture back for ever, and `up` never ended. Told so with the next message of the same
    stream, the join gives the gesture up (`Lost`) and goes on."""
    belief = {"tap": 0.9, "grasp": 0.05, "touch": 0.05}
    labels = {"Color": "green1"}

    def whole_but(join: FusionJoin[int], segment_id: int, start: int, piece: str) -> list[Any]:
        out = join.started(segment_id, start)
        if piece != "object":
            out += join.object_seen(segment_id, labels)
        out += join.belief(segment_id, 0, start, belief, 0, final=True)
        out += join.ended(segment_id, start, start + 10)
        if piece != "effects":
            out += join.effects_seen(segment_id, labels, {})
        return out

    for piece, told in (("object", "objects_missed"), ("effects", "effects_missed")):
        join: FusionJoin[int] = FusionJoin(network)
        join.objects_alive(True)
        out = whole_but(join, 1, 0, piece) + whole_but(join, 2, 20, "")
        assert not [o for o in out if isinstance(o, Outcome | Lost)], piece  # 1 holds 2 back
        out = getattr(join, told)(3, 1) + whole_but(join, 3, 40, "")
        said = [(type(o).__name__, o.segment_id) for o in out if isinstance(o, Outcome | Lost)]
        assert said == [("Lost", 1), ("Outcome", 2), ("Outcome", 3)], piece
        assert f"its {piece} was lost (1 " in next(o.reason for o in out if isinstance(o, Lost))
        # a gesture that has the piece is not given up by a later loss of it
        out = join.started(4, 60) + join.object_seen(4, labels) + join.effects_seen(4, labels, {})
        assert getattr(join, told)(9, 2) == [], piece
        out = join.belief(4, 0, 60, belief, 0, final=True) + join.ended(4, 60, 70)
        assert [o.segment_id for o in out if isinstance(o, Outcome)] == [4], piece


def test_a_cancel_after_the_end_changes_nothing(network: Any) -> None:
    """A restarted streamer that lost its frames cancels each gesture its consumers had not
    yet told it ended (their ledgers lag): one whose end has arrived is whole, and is
    described as if no cancel had come; one still under way is dropped."""
    belief = {"tap": 0.9, "grasp": 0.05, "touch": 0.05}
    join: FusionJoin[int] = FusionJoin(network, expect_objects=False)
    out = join.started(1, 0) + join.ended(1, 0, 10)
    out += join.cancelled(1) + join.started(2, 20) + join.cancelled(2)
    out += join.belief(1, 0, 10, belief, 0, final=True)
    out += join.belief(2, 0, 30, belief, 0, final=True)
    assert [o.segment_id for o in out if isinstance(o, Outcome)] == [1]
    watch: ObjectWatch[int] = ObjectWatch(ClusterModel.load())
    watch.started(1, 0, 0)
    watch.ended(1, 0, 10, 1, 0)
    assert watch.cancelled(1) == [] and 1 in watch.windows
    watch.started(2, 20, 0)
    watch.cancelled(2)
    assert 2 not in watch.windows
