"""Object segmenter: camera frames and gesture events in; detected objects (every frame), the
object each gesture is about (`GestureObject`) and the effects of the action on it
(`ObjectEffects`) out.

The per-gesture logic is `cognition.episodes.ObjectWatch`, which waits on stamps, never on a
wall-clock timer. Gestures come first, so a description is not late on a loaded machine: a
frame's own objects, the costly part, are described in a process of its own
(services/frame_describer.py), scheduled by runtime.service_frames: a replay's every frame, a
live source's newest (`skip_frames`), never at a gesture's expense (docs/concepts/pipeline.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import msgspec
import numpy as np

from beyond_self.cognition.episodes import GestureEffects, ObjectAtStart, ObjectWatch
from beyond_self.cognition.episodes.objects import WatchSnapshot
from beyond_self.cognition.vision.pipeline import DetectedObject as FoundObject
from beyond_self.runtime.bus.delivery import CAMERA, EVENTS, FRAMES
from beyond_self.runtime.bus.subscription import Subscription
from beyond_self.runtime.process import native_heap
from beyond_self.runtime.recording.images import CameraMessage, image_from_message
from beyond_self.runtime.service import Service
from beyond_self.runtime.service_frames import FrameSchedule, Steps
from beyond_self.schemas import (
    CameraFrame,
    CompressedCameraFrame,
    DetectedObject,
    DetectedObjects,
    GestureObject,
    GestureSegment,
    Header,
    ObjectEffects,
    ServiceHealth,
    StreamEnd,
)
from beyond_self.services import shared
from beyond_self.services.frame_describer import HEAP_KEPT_BYTES, FrameDescriber
from beyond_self.services.object_messages import effects_message, gesture_object


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
        # the gestures' windows segment frames in this process: their arrays stay in its heap
        native_heap.keep_freed(HEAP_KEPT_BYTES)

    async def setup(self) -> None:
        self.watch: ObjectWatch[Header] = ObjectWatch(
            shared.clusters(self.clusters_path), **self.watch_options
        )
        keys = self.bus.keys
        # restarted: the gestures whose effects every consumer has are not measured again
        self.watch.done(self.downstream(keys.effects).done("effects"))
        cameras = [keys.camera, keys.camera_compressed]
        self.keep_state(WatchSnapshot, self.watch.resume, self.watch.snapshot, inputs=cameras)
        self.objects_out = self.publisher(keys.objects, DetectedObjects, FRAMES)
        # told in progress at once, not after the frame's own objects: an instance restarted
        # meanwhile learns from the player's copy of the report not to publish them again
        self.at_start_out = self.publisher(
            keys.gesture_object, GestureObject, EVENTS, progress=True
        )
        self.effects_out = self.publisher(keys.effects, ObjectEffects, EVENTS, progress=True)
        # recovered: restarted mid-gesture, it gets the gesture's frames back from the cache
        self.subscribe(keys.camera, CameraFrame, self.on_camera, CAMERA, paced=True)
        self.subscribe(
            keys.camera_compressed, CompressedCameraFrame, self.on_camera, CAMERA, paced=True
        )
        events: list[Subscription[Any]] = [
            self.subscribe(keys.gesture_segment, GestureSegment, self.on_segment, EVENTS,
                           producer="gestures", complete=self.on_gestures_complete),
            self.subscribe(keys.stream_end, StreamEnd, self.on_stream_end, EVENTS),
        ]  # fmt: skip
        # gestures first: a frame's own objects wait, a live source's newest frame only
        self.frames = FrameSchedule(self, self._describe, events, newest=self.skip_frames)
        self.describer = shared.frame_describer(self.clusters_path, self.frames.niceness)
        self.windows = Steps(self, self.watch.catch_up, "gesture windows")

    def on_gestures_complete(self, stamp: int) -> None:
        self.emit(self.watch.gestures_complete(stamp))

    async def on_camera(self, msg: CameraMessage) -> None:
        await self.frames.events_first()
        image = image_from_message(msg)
        self.emit(self.watch.camera(msg.header.stamp, msg.header.seq, image))
        await self.frames.put((msg, image))

    async def _describe(self, frame: tuple[CameraMessage, np.ndarray]) -> None:
        """Publish the objects of a frame, described in the worker process (unless a gesture
        needed them first): the event loop goes on with the gestures meanwhile."""
        msg, image = frame
        objects = self.watch.known_objects(msg.header.stamp)
        if objects is None:
            assert self.describer is not None, "made in setup, before any subscription"
            objects = await self.describer.describe(image)
            self.watch.described(msg.header.stamp, objects)
        self.objects_out.put(
            DetectedObjects(
                header=self.derive(msg.header, DetectedObjects),
                frame=msg.header.seq,
                objects=[detected_object(o) for o in objects],
                skipped=self.frames.overtaken(),
            )
        )

    async def teardown(self) -> None:
        if self.describer is not None:
            shared.release_describer(self.describer)

    def health_report(self) -> ServiceHealth:
        return msgspec.structs.replace(super().health_report(), skipped=self.frames.skipped)

    def on_segment(self, event: GestureSegment) -> None:
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
        self.windows.poke()  # whatever the watch was told may have queued frames
        for out in outputs:
            if isinstance(out, ObjectAtStart):
                self.at_start_out.put(gesture_object(self.derive(out.ref, GestureObject), out))
            elif isinstance(out, GestureEffects):
                self.effects_out.put(effects_message(self.derive(out.ref, ObjectEffects), out))


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
