"""The whole pipeline over a recording, in one process, with no bus: the specification.

`analyse_stream` feeds skeleton and camera frames in stamp order through the same classes the
services run (`GestureTracker`, `ObjectWatch`, `FusionJoin`, the describer's exact N-best and
`GestureReport`). A run of the services over the same recording, at any rate and under any
load, must print the same lines; `beyond analyse` prints these.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from beyond_self.cognition.bn.model import BayesNet
from beyond_self.cognition.descriptions import nbest_exact
from beyond_self.cognition.episodes.join import Anticipation, FusionJoin, Lost, Outcome, Output
from beyond_self.cognition.episodes.objects import GestureEffects, ObjectAtStart, ObjectWatch
from beyond_self.cognition.episodes.report import GestureReport
from beyond_self.cognition.episodes.tracker import (
    Belief,
    Cancelled,
    Ended,
    GestureTracker,
    Started,
    hand_position,
)
from beyond_self.cognition.gestures import GestureModels
from beyond_self.cognition.vision.clusters import ClusterModel
from beyond_self.core.errors import InputError


@dataclass(frozen=True)
class SkeletonInput:
    stamp: int
    frame: int
    hand: tuple[float, float, float]
    torso: tuple[float, float, float] | None


@dataclass(frozen=True)
class CameraInput:
    stamp: int
    frame: int
    image: np.ndarray


@dataclass
class OfflineRun:
    lines: list[str] = field(default_factory=list)
    outcomes: list[Outcome[int]] = field(default_factory=list)  # ref: the final belief's stamp
    sentences: dict[int, list[tuple[str, float]]] = field(default_factory=dict)
    object_at_start: dict[int, ObjectAtStart[None]] = field(default_factory=dict)
    effects: dict[int, GestureEffects[None]] = field(default_factory=dict)
    skipped: int = 0  # skeleton frames that were not a hand's (counted, as a service counts them)
    cancelled: dict[int, str] = field(default_factory=dict)  # segment id -> why


def analyse_stream(
    items: Iterable[SkeletonInput | CameraInput],
    *,
    gesture_models: GestureModels,
    clusters: ClusterModel,
    network: BayesNet,
    nbest: int = 5,
    legacy_offset: bool = False,
    lead_s: float = 0.3,
    fps: float | None = None,
    camera_deadline_s: float = 5.0,
    objects_deadline_s: float = 30.0,
    on_line: Callable[[str], None] | None = None,
    on_event: Callable[[Belief[None] | Anticipation[int] | Outcome[int]], None] | None = None,
) -> OfflineRun:
    """Items must come in stamp order within each kind (a recording's order is fine).
    `on_event` sees every belief and every fused output (the ref of an output is the stamp of
    the belief it fuses), in order: what the services publish, for `foxglove --export`."""
    tracker: GestureTracker[None] = GestureTracker(gesture_models)
    watch: ObjectWatch[None] = ObjectWatch(
        clusters, lead_s=lead_s, fps=fps, deadline_s=camera_deadline_s
    )
    join: FusionJoin[int] = FusionJoin(network, deadline_s=objects_deadline_s)
    join.objects_alive(True)  # the watch below is always there
    report = GestureReport()
    run = OfflineRun()
    actions = list(gesture_models.actions)

    def joined(outputs: list[Output[int]]) -> None:
        for out in outputs:
            if isinstance(out, Lost):
                continue  # only a bus loses beliefs
            if on_event is not None:
                on_event(out)
            if isinstance(out, Anticipation):
                report.anticipation(out.segment_id, out.frame, out.prediction.effects)
                continue
            run.outcomes.append(out)
            p = out.prediction
            report.recognised(out.segment_id, p.action_belief, p.evidence)
            best = nbest_exact(out.words, nbest, legacy_offset=legacy_offset)
            run.sentences[out.segment_id] = [(s.sentence, s.score) for s in best]
            if best:
                report.described(out.segment_id, best[0].sentence)

    def watched(outputs: list[Any]) -> None:
        for out in outputs:
            if isinstance(out, ObjectAtStart):
                run.object_at_start[out.segment_id] = out
                joined(join.object_seen(out.segment_id, out.labels))
            elif isinstance(out, GestureEffects):
                run.effects[out.segment_id] = out
                joined(join.effects_seen(out.segment_id, out.object_labels, out.effect_labels))

    def tracked(events: list[Any]) -> None:
        for ev in events:
            if isinstance(ev, Started):
                report.started(ev.segment_id, ev.frame)
                watched(watch.started(ev.segment_id, ev.stamp, None))
                joined(join.started(ev.segment_id, ev.stamp))
            elif isinstance(ev, Belief):
                if on_event is not None:
                    on_event(ev)
                if ev.final:
                    report.believed(ev.segment_id)
                else:
                    report.belief(ev.segment_id, ev.frame, actions, ev.posterior)
                belief = dict(zip(actions, ev.posterior, strict=True))
                joined(join.belief(ev.segment_id, ev.frame, ev.stamp, belief, ev.stamp, ev.final))
            elif isinstance(ev, Ended):
                report.ended(ev.segment_id, ev.frame)
                watched(watch.ended(ev.segment_id, ev.start_stamp, ev.end_stamp, ev.frame, None))
                joined(join.ended(ev.segment_id, ev.start_stamp, ev.end_stamp))
            elif isinstance(ev, Cancelled):
                run.cancelled[ev.segment_id] = ev.reason
                report.cancelled(ev.segment_id)
                watched(watch.cancelled(ev.segment_id))
                joined(join.cancelled(ev.segment_id))

    def release() -> None:
        for line in report.release():
            run.lines.append(line)
            if on_line is not None:
                on_line(line)

    last_camera: int | None = None
    for item in items:
        if isinstance(item, SkeletonInput):
            try:  # a frame that is not a hand's is skipped, as the gesture streamer skips it
                x = hand_position(item.hand, item.torso, f"skeleton frame {item.frame}")
                events = tracker.push(item.stamp, item.frame, x, None)
            except InputError:
                run.skipped += 1
                continue
            tracked(events)
        else:
            last_camera = item.stamp
            watched(watch.camera(item.stamp, item.frame, item.image))
        release()
    tracked(tracker.finish())
    watched(watch.camera_ended(last_camera))
    release()
    return run
