"""Object segmenter: camera frames and gesture events in; detected objects (every frame), the
object each gesture is about (`GestureObject`) and the effects of the action on it
(`ObjectEffects`) out.

The per-gesture logic is `cognition.episodes.ObjectWatch`, which waits on stamps, never on a
wall-clock timer. Gestures come first, so a description is not late on a loaded machine: a
frame's own objects, the costly part, are described in a process of its own
(services/frame_describer.py): a replay's every frame, a live source's newest when frames come
faster (`skip_frames`), never at a gesture's expense (docs/concepts/pipeline.md, event time).
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Mapping
from typing import Any

import msgspec
import numpy as np

from beyond_self.cognition.episodes import GestureEffects, ObjectAtStart, ObjectWatch
from beyond_self.cognition.episodes.objects import WatchSnapshot
from beyond_self.cognition.vision.pipeline import DetectedObject as FoundObject
from beyond_self.runtime.bus.delivery import CAMERA, EVENTS, FRAMES
from beyond_self.runtime.bus.subscription import Subscription
from beyond_self.runtime.recording.images import CameraMessage, image_from_message
from beyond_self.runtime.service import Service
from beyond_self.schemas import (
    CameraFrame,
    CompressedCameraFrame,
    DetectedObject,
    DetectedObjects,
    GestureObject,
    GestureSegment,
    Header,
    ObjectEffect,
    ObjectEffects,
    Progress,
    ServiceHealth,
    StreamEnd,
)
from beyond_self.services import shared
from beyond_self.services.frame_describer import FrameDescriber

_YIELDS_TO_EVENTS = 8  # turns of the event loop a camera frame gives waiting gesture events
LIVE_NICENESS = 10  # of a live source's describer process: what the gestures leave, it gets


class ObjectSegmenter(Service):
    name = "objects"
    subscribes = ("camera", "camera_compressed", "gesture_segment", "stream_end")
    publishes = ("objects", "gesture_object", "effects")
    serves = ()
    fleet = True  # a workstation may serve many robots with one process (runtime.fleet)

    def __init__(
        self,
        *,
        clusters: str | None = None,
        lead_s: float = 0.3,
        fps: float | None = None,
        deadline_s: float = 5.0,
        onset_s: float = 2.0,
        buffer_mb: float = 160.0,
        skip_frames: bool | None = None,
        **base: Any,
    ) -> None:
        super().__init__(**base)
        self.clusters_path = clusters
        # a live source (wall clock) is not held back, a replay (recording clock) is paced
        self.skip_frames = not self.clock.is_recording if skip_frames is None else skip_frames
        self.skipped = 0  # frames not described: a newer one overtook them
        self._waiting: tuple[CameraMessage, np.ndarray] | None = None  # the next to describe
        self._overtaken = 0  # frames skipped since the last DetectedObjects
        self._frame_waiting = asyncio.Event()
        self._gestures_behind = asyncio.Event()  # frames may be queued for gestures' windows
        self.describer: FrameDescriber | None = None
        self.watch_options: dict[str, Any] = dict(
            lead_s=lead_s,
            fps=fps,
            deadline_s=deadline_s,
            onset_s=onset_s,
            buffer_bytes=int(buffer_mb * 2**20),
        )

    @classmethod
    def warm(cls, options: Mapping[str, Any]) -> None:
        shared.clusters(options.get("clusters"))

    async def setup(self) -> None:
        self.watch: ObjectWatch[Header] = ObjectWatch(
            shared.clusters(self.clusters_path), **self.watch_options
        )
        # a live source's descriptions run at a lower priority than the gestures' work
        niceness = LIVE_NICENESS if self.skip_frames else 0
        self.describer = shared.frame_describer(self.clusters_path, niceness)
        keys = self.bus.keys
        # restarted: the gestures whose effects every consumer has are not measured again, and
        # the camera history before the snapshot's restart point is not gone over again
        done = self.done_downstream(keys.effects, "effects")
        self.watch.done(done)
        cameras = [keys.camera, keys.camera_compressed]
        self.keep_state(WatchSnapshot, self.watch.resume, self.watch.snapshot, inputs=cameras)
        # for pacing, the start and the end of every gesture closed before (its effects told,
        # or cancelled) count as received: a gesture streamer restarted before this one may not
        # send them again (its predecessor's consumer had them), and this one does not need them
        closed = done | self.seen_downstream(keys.gesture_segment, ("cancel",))
        self.received_before = 2 * next(n for n in range(1, len(closed) + 2) if n not in closed) - 2
        self.objects_out = self.publisher(keys.objects, DetectedObjects, FRAMES)
        self.at_start_out = self.publisher(keys.gesture_object, GestureObject, EVENTS)
        self.effects_out = self.publisher(keys.effects, ObjectEffects, EVENTS)
        # recovered: restarted mid-gesture, it gets the gesture's frames back from the cache
        self.subscribe(keys.camera, CameraFrame, self.on_camera, CAMERA, paced=True)
        self.subscribe(
            keys.camera_compressed, CompressedCameraFrame, self.on_camera, CAMERA, paced=True
        )
        self.events: list[Subscription[Any]] = [
            self.subscribe(keys.gesture_segment, GestureSegment, self.on_segment, EVENTS),
            self.subscribe(keys.stream_end, StreamEnd, self.on_stream_end, EVENTS),
        ]
        self.subscribe(keys.progress("gestures"), Progress, self.on_gestures_progress)
        self.segments_received = 0
        self.gestures_progress: deque[tuple[int, int]] = deque(maxlen=4096)  # (stamp, events)
        if self.skip_frames:
            self.spawn(self._describe_newest(), "objects of the newest frame")
        self.spawn(self._catch_up(), "gesture windows")

    def on_gestures_progress(self, msg: Progress) -> None:
        stamp = msg.handled.get(self.bus.keys.skeleton, -1)
        events = msg.published.get(self.bus.keys.gesture_segment, 0)
        self.gestures_progress.append((stamp, events))
        self._gestures_complete()

    def _gestures_complete(self) -> None:
        complete = -1
        while self.gestures_progress and self.gestures_progress[0][1] <= self.segments_received:
            complete = self.gestures_progress.popleft()[0]
        if complete >= 0:
            self.emit(self.watch.gestures_complete(complete))

    async def _catch_up(self) -> None:
        """Feed the gestures' windows the frames queued for them, one at a time, letting
        messages through in between: a gesture's lead frames do not hold up the next event."""
        while True:
            await self._gestures_behind.wait()
            self._gestures_behind.clear()
            while self.watch.catch_up():
                await asyncio.sleep(0)

    async def on_camera(self, msg: CameraMessage) -> None:
        for _ in range(_YIELDS_TO_EVENTS):  # a gesture event already here goes first
            if not any(sub.pending for sub in self.events):
                break
            await asyncio.sleep(0)
        image = image_from_message(msg)
        self.emit(self.watch.camera(msg.header.stamp, msg.header.seq, image))
        if not self.skip_frames:
            await self._describe(msg, image)  # before the frame counts as handled: paced
            return
        if self._waiting is not None:
            self.skipped += 1
            self._overtaken += 1
        self._waiting = (msg, image)
        self._frame_waiting.set()

    async def _describe_newest(self) -> None:
        """Describe the newest frame whenever the last description is done (live sources)."""
        while True:
            await self._frame_waiting.wait()
            self._frame_waiting.clear()
            if self._waiting is not None:
                (msg, image), self._waiting = self._waiting, None
                await self._describe(msg, image)

    async def _describe(self, msg: CameraMessage, image: np.ndarray) -> None:
        """Publish the objects of a frame, described in the worker process (unless a gesture
        needed them first): the event loop goes on with the gestures meanwhile."""
        stamp = msg.header.stamp
        objects = self.watch.known_objects(stamp)
        if objects is None:
            assert self.describer is not None, "made in setup, before any subscription"
            objects = await self.describer.describe(image)
            self.watch.described(stamp, objects)
        skipped, self._overtaken = self._overtaken, 0
        self.objects_out.put(
            DetectedObjects(
                header=self.derive(msg.header, DetectedObjects),
                frame=msg.header.seq,
                objects=[detected_object(o) for o in objects],
                skipped=skipped,
            )
        )

    async def teardown(self) -> None:
        if self.describer is not None:
            shared.release_describer(self.describer)

    def health_report(self) -> ServiceHealth:
        return msgspec.structs.replace(super().health_report(), skipped=self.skipped)

    def received_counts(self) -> dict[str, int]:
        # gesture events carry their own index: the last one here says what has arrived, also
        # for an instance restarted mid-stream that got the earlier ones from the cache
        counts = super().received_counts()
        counts[self.bus.keys.gesture_segment] = max(self.segments_received, self.received_before)
        return counts

    def on_segment(self, event: GestureSegment) -> None:
        self.segments_received = max(self.segments_received, event.event_seq)
        self._gestures_complete()
        if event.event == "start":
            self.emit(self.watch.started(event.segment_id, event.start_stamp, event.header))
        elif event.event == "cancel":
            self.emit(self.watch.cancelled(event.segment_id))
        elif event.end_stamp is not None:
            self.emit(
                self.watch.ended(
                    event.segment_id, event.start_stamp, event.end_stamp, event.frame, event.header
                )
            )

    def on_stream_end(self, msg: StreamEnd) -> None:
        stamps = [
            msg.last_stamps[k] for k in ("camera", "camera_compressed") if k in msg.last_stamps
        ]
        self.emit(self.watch.camera_ended(max(stamps) if stamps else None))
        skeleton = msg.last_stamps.get("skeleton")
        if skeleton is not None:
            self.emit(self.watch.skeleton_at(skeleton))

    def emit(self, outputs: list[Any]) -> None:
        self._gestures_behind.set()  # whatever the watch was told may have queued frames
        for out in outputs:
            if isinstance(out, ObjectAtStart):
                self.at_start_out.put(_gesture_object(self.derive(out.ref, GestureObject), out))
            elif isinstance(out, GestureEffects):
                self.effects_out.put(_effects(self.derive(out.ref, ObjectEffects), out))
        if outputs:
            # said at once, not after the frame's own objects: an instance restarted meanwhile
            # learns from the player's copy of this report not to publish them again
            self.publish_progress()


def detected_object(o: FoundObject) -> DetectedObject:
    f = o.features
    return DetectedObject(
        id=o.id,
        centroid=(float(f.centroid[0]), float(f.centroid[1])),
        area=float(f.area),
        colour=[float(v) for v in f.lab],
        shape=[
            float(f.circularity),
            float(f.rectangularity),
            float(f.convexity),
            float(f.eccentricity),
        ],
        size=[float(f.diameter_m)],
        colour_label=o.labels.get("Color", ""),
        shape_label=o.labels.get("Shape", ""),
        size_label=o.labels.get("Size", ""),
    )


def _gesture_object(header: Header, out: ObjectAtStart[Header]) -> GestureObject:
    """The object a gesture is about, as the reasoner joins it to the gesture's beliefs."""
    return GestureObject(
        header=header,
        segment_id=out.segment_id,
        frame=out.frame,
        labels=out.labels,
        reason=out.reason,
    )


def _effects(header: Header, out: GestureEffects[Header]) -> ObjectEffects:
    effects: list[ObjectEffect] = []
    if out.analysis is not None:
        eff = out.analysis.effects
        effects.append(
            ObjectEffect(
                object_id=0,
                object_velocity=float(eff.object_speed),
                hand_velocity=_optional(eff.hand_speed),
                object_hand_velocity=_optional(eff.relative_speed),
                contact=int(out.analysis.contact_flags.sum()) > 0,
                contact_duration=_optional(eff.contact_s),
                labels=out.effect_labels,
                object_labels=out.object_labels,
            )
        )
    return ObjectEffects(
        header=header,
        frame=out.frame,
        segment_id=out.segment_id,
        effects=effects,
        measured=out.analysis is not None,
        reason=out.reason,
    )


def _optional(x: float | None) -> float | None:
    return None if x is None else float(x)
