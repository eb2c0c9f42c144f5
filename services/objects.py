"""Object segmenter: camera frames in; detected objects (every frame) and, per gesture, the
effects of the action on the acted-on object out.

Per frame it segments and labels the objects on the table (Color, Shape, Size by the learned
clusters). Per gesture it keeps the frames from a little before the gesture's start to its end,
and when the "end" event arrives (and camera frames up to that instant have been seen) runs the
recording analysis of `cognition.vision` on them: tracking, hand–object contact, velocities,
and their discretisation into ObjVel, HandVel, ObjHandVel and Contact.
"""

from __future__ import annotations

import asyncio
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from cognition.errors import InputError
from cognition.vision.clusters import ClusterModel
from cognition.vision.pipeline import (
    RecordingAnalyser,
    RecordingAnalysis,
    analyse_frames,
    describe_frame,
)
from runtime.images import CameraMessage, image_from_message
from runtime.reliable import EVENT_CACHE, FRAME_CACHE
from runtime.service import Service
from schemas import (
    CameraFrame,
    CompressedCameraFrame,
    DetectedObject,
    DetectedObjects,
    GestureSegment,
    Header,
    ObjectEffect,
    ObjectEffects,
)


@dataclass
class _Pending:
    segment_id: int
    start_stamp: int
    end_stamp: int
    header: Header
    frame: int


class ObjectSegmenter(Service):
    name = "objects"
    subscribes = ("camera", "camera_compressed", "gesture_segment")
    publishes = ("objects", "effects")
    serves = ()

    def __init__(
        self,
        *,
        clusters: str | None = None,
        lead_s: float = 0.3,
        wait_s: float = 1.0,
        buffer_frames: int = 900,
        fps: float | None = None,
        **base: Any,
    ) -> None:
        super().__init__(**base)
        self.clusters_path = clusters
        self.lead_ns = int(lead_s * 1e9)
        self.wait_s = wait_s
        self.fps = fps
        self.frames: deque[tuple[int, np.ndarray]] = deque(maxlen=buffer_frames)
        self.pending: dict[int, _Pending] = {}
        # gestures under way: their analyser and the stamps of the frames pushed to it
        self.analysers: dict[int, tuple[RecordingAnalyser, list[int]]] = {}
        self.frame_no = 0

    async def setup(self) -> None:
        self.clusters = ClusterModel.load(self.clusters_path)
        keys = self.bus.keys
        self.objects_out = self.publisher(keys.objects, DetectedObjects, cache=FRAME_CACHE)
        self.effects_out = self.publisher(keys.effects, ObjectEffects, cache=EVENT_CACHE)
        self.subscribe(keys.camera, CameraFrame, self.on_camera)
        self.subscribe(keys.camera_compressed, CompressedCameraFrame, self.on_camera)
        self.subscribe(keys.gesture_segment, GestureSegment, self.on_segment, recover=True)

    def on_camera(self, msg: CameraMessage) -> None:
        image = image_from_message(msg)
        self.frames.append((msg.header.stamp, image))
        self.frame_no += 1
        result = describe_frame(image, self.clusters, require_objects=False)
        objects = [
            DetectedObject(
                id=o.id,
                centroid=(float(o.features.centroid[0]), float(o.features.centroid[1])),
                area=float(o.features.area),
                colour=[float(v) for v in o.features.lab],
                shape=[
                    float(o.features.circularity),
                    float(o.features.rectangularity),
                    float(o.features.convexity),
                    float(o.features.eccentricity),
                ],
                size=[float(o.features.diameter_m)],
                colour_label=o.labels.get("Color", ""),
                shape_label=o.labels.get("Shape", ""),
                size_label=o.labels.get("Size", ""),
            )
            for o in result.objects
        ]
        header = self.derive(msg.header, DetectedObjects)
        self.objects_out.put(DetectedObjects(header=header, frame=self.frame_no, objects=objects))
        stamp = msg.header.stamp
        for analyser, pushed in self.analysers.values():
            if not pushed or stamp > pushed[-1]:
                analyser.push(image)
                pushed.append(stamp)
        for pending in list(self.pending.values()):
            if msg.header.stamp >= pending.end_stamp:
                self.finish(pending)

    def _fps(self) -> float:
        if self.fps:
            return self.fps
        stamps = np.array([s for s, _ in self.frames][-16:], dtype=np.float64)
        return float(1e9 / np.median(np.diff(stamps))) if len(stamps) > 2 else 15.0

    def on_segment(self, event: GestureSegment) -> None:
        if event.event == "start":
            # analyse frames as they come (from a little before the start), so that the end of
            # the gesture only has to summarise: the description does not wait for vision
            analyser = RecordingAnalyser(self._fps(), self.clusters)
            pushed: list[int] = []
            for stamp, image in self.frames:
                if stamp >= event.start_stamp - self.lead_ns:
                    analyser.push(image)
                    pushed.append(stamp)
            self.analysers[event.segment_id] = (analyser, pushed)
            return
        if event.end_stamp is None:
            return
        pending = _Pending(
            event.segment_id, event.start_stamp, event.end_stamp, event.header, event.frame
        )
        if self.frames and self.frames[-1][0] >= event.end_stamp:
            self.finish(pending)
            return
        self.pending[event.segment_id] = pending
        # the camera may have stopped (end of a recording): analyse what there is after a while
        asyncio.get_running_loop().call_later(self.wait_s, self._flush, event.segment_id)

    def _flush(self, segment_id: int) -> None:
        pending = self.pending.get(segment_id)
        if pending is not None:
            try:
                self.finish(pending)
            except InputError as exc:
                self._failed("timer", exc)

    def finish(self, pending: _Pending) -> None:
        self.pending.pop(pending.segment_id, None)
        running = self.analysers.pop(pending.segment_id, None)
        if running is not None:
            analyser, pushed = running
            within = sum(1 for stamp in pushed if stamp <= pending.end_stamp)
            if within >= 3:  # frames pushed after the end are left out: same as the batch form
                self._publish_analysis(pending, analyser.finish(within))
                return
        lo = pending.start_stamp - self.lead_ns
        window = [(s, img) for s, img in self.frames if lo <= s <= pending.end_stamp]
        if len(window) < 3:
            # No camera over this gesture: say so (the reasoner then fuses without effects).
            self._publish_effects(pending, [])
            raise InputError(
                f"gesture {pending.segment_id}: only {len(window)} camera frames between its "
                "start and end; effects not measured (valid: a camera stream covering the gesture)"
            )
        stamps = np.array([s for s, _ in window], dtype=np.float64)
        fps = self.fps or float(1e9 / np.median(np.diff(stamps)))
        self._publish_analysis(
            pending, analyse_frames([img for _, img in window], fps, self.clusters)
        )

    def _publish_analysis(self, pending: _Pending, analysis: RecordingAnalysis) -> None:
        eff = analysis.effects
        contact_frames = int(analysis.contact_flags.sum())
        effect = ObjectEffect(
            object_id=0,
            object_velocity=float(eff.object_speed),
            hand_velocity=_optional(eff.hand_speed),
            object_hand_velocity=_optional(eff.relative_speed),
            contact=contact_frames > 0,
            contact_duration=_optional(eff.contact_s),
            labels={k: v for k, v in analysis.labels.items() if k in _EFFECTS},
            object_labels={k: v for k, v in analysis.labels.items() if k not in _EFFECTS},
        )
        self._publish_effects(pending, [effect])

    def _publish_effects(self, pending: _Pending, effects: list[ObjectEffect]) -> None:
        self.effects_out.put(
            ObjectEffects(
                header=self.derive(pending.header, ObjectEffects),
                frame=pending.frame,
                segment_id=pending.segment_id,
                effects=effects,
            )
        )


_EFFECTS = ("ObjVel", "HandVel", "ObjHandVel", "Contact")


def _optional(x: float | None) -> float | None:
    return None if x is None else float(x)
