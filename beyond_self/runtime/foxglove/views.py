"""Foxglove views of bus messages, added by the bridge and `beyond record --foxglove`, so
Foxglove's stock panels show them without a plug-in.

Under `beyond/<robot>/foxglove/`: `scene` (the skeleton as a `SceneUpdate`), `pose` and `objects`
(`ImageAnnotations` over the image they were found in, stamped like it), `posterior` and
`affordance` (maps from value to probability, for Plot paths such as `.posterior.grasp`) and `log`
(each description as a `Log` line). The view types are our msgspec Structs laid out as
Foxglove's documented types and encoded as JSON; stamps are Foxglove `Time`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import msgspec

from beyond_self.runtime.foxglove.types import (
    AffordanceView,
    CircleAnnotation,
    Color,
    ImageAnnotations,
    KeyValuePair,
    LinePrimitive,
    Log,
    Point2,
    PointsAnnotation,
    Pose,
    PosteriorView,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    TextAnnotation,
    Vector3,
    ViewStruct,
)
from beyond_self.schemas.base import Message
from beyond_self.schemas.codec import self_contained_schema
from beyond_self.schemas.keys import split_key
from beyond_self.schemas.messages import (
    ActionPosterior,
    AffordancePrediction,
    Description,
    DetectedObjects,
    PersonPose,
    SkeletonFrame,
    Time,
)

VIEW_PREFIX = "foxglove"  # beyond/<robot>/foxglove/<view>: never a bus key


# --- skeleton -> scene ---------------------------------------------------------------------

BONES: tuple[tuple[str, str], ...] = (
    ("head", "neck"),
    ("neck", "torso"),
    ("neck", "left_shoulder"),
    ("left_shoulder", "left_elbow"),
    ("left_elbow", "left_hand"),
    ("neck", "right_shoulder"),
    ("right_shoulder", "right_elbow"),
    ("right_elbow", "right_hand"),
    # a pose model's skeleton has legs too (cognition.pose)
    ("torso", "left_hip"),
    ("left_hip", "left_knee"),
    ("left_knee", "left_foot"),
    ("torso", "right_hip"),
    ("right_hip", "right_knee"),
    ("right_knee", "right_foot"),
)
JOINT_SIZE = 0.06  # m
BONE = Color(0.85, 0.85, 0.9)
ZERO = Time(sec=0, nsec=0)


def _confidence_colour(c: float) -> Color:
    """Green tracked, amber inferred, red lost (Kinect's 1 / 0.5 / 0)."""
    return Color(r=round(min(1.0, 2 * (1 - c)), 3), g=round(min(1.0, 2 * c), 3), b=0.2)


def scene(frame: SkeletonFrame) -> SceneUpdate:
    stamp = Time.from_ns(frame.header.stamp)
    spheres = [
        SpherePrimitive(
            pose=Pose(position=Vector3(*joint.position)),
            size=Vector3(JOINT_SIZE, JOINT_SIZE, JOINT_SIZE),
            color=_confidence_colour(joint.confidence),
        )
        for joint in frame.joints.values()
    ]
    points = [
        Vector3(*frame.joints[end].position)
        for a, b in BONES
        if a in frame.joints and b in frame.joints
        for end in (a, b)
    ]
    lines = [
        LinePrimitive(
            type=2,
            pose=Pose(position=Vector3(0.0, 0.0, 0.0)),
            thickness=0.02,
            scale_invariant=False,
            points=points,
            color=BONE,
        )
    ]
    entity = SceneEntity(
        timestamp=stamp,
        frame_id=frame.frame_id,
        id=f"skeleton/{frame.user}",
        lifetime=ZERO,
        frame_locked=False,
        metadata=[KeyValuePair("frame", str(frame.frame))],
        spheres=spheres,
        lines=lines if points else [],
        texts=[],
    )
    return SceneUpdate(deletions=[], entities=[entity])


# --- objects -> image annotations ----------------------------------------------------------

OUTLINE = Color(1.0, 0.2, 0.8)
CLEAR = Color(0.0, 0.0, 0.0, 0.0)
LABEL_BACKGROUND = Color(0.0, 0.0, 0.0, 0.6)
WHITE = Color(1.0, 1.0, 1.0)


def image_annotations(objects: DetectedObjects) -> ImageAnnotations:
    stamp = Time.from_ns(objects.header.stamp)
    circles, texts = [], []
    for o in objects.objects:
        x, y = o.centroid
        diameter = 2 * math.sqrt(max(o.area, 0.0) / math.pi)
        circles.append(
            CircleAnnotation(
                timestamp=stamp,
                position=Point2(x, y),
                diameter=round(diameter, 2),
                thickness=2.0,
                fill_color=CLEAR,
                outline_color=OUTLINE,
            )
        )
        texts.append(
            TextAnnotation(
                timestamp=stamp,
                position=Point2(x - diameter / 2, y - diameter / 2 - 4),
                text=f"#{o.id} {o.colour_label} {o.shape_label} {o.size_label}",
                font_size=12.0,
                text_color=WHITE,
                background_color=LABEL_BACKGROUND,
            )
        )
    return ImageAnnotations(circles=circles, points=[], texts=texts)


# --- a person's pose -> image annotations --------------------------------------------------

KEYPOINT_SIZE = 6.0  # px


def pose_annotations(pose: PersonPose) -> ImageAnnotations:
    """The pose over the image it was estimated from: a dot per joint, coloured by confidence
    (green seen, red guessed), and the skeleton's bones; stamped like that image."""
    stamp = Time.from_ns(pose.header.stamp)
    points = pose.keypoints
    joints = PointsAnnotation(
        timestamp=stamp,
        type=1,
        points=[Point2(*k.position) for k in points.values()],
        outline_color=BONE,
        outline_colors=[_confidence_colour(k.confidence) for k in points.values()],
        fill_color=BONE,
        thickness=KEYPOINT_SIZE,
    )
    bones = PointsAnnotation(
        timestamp=stamp,
        type=4,
        points=[
            Point2(*points[end].position)
            for a, b in BONES
            if a in points and b in points
            for end in (a, b)
        ],
        outline_color=BONE,
        outline_colors=[],
        fill_color=CLEAR,
        thickness=2.0,
    )
    return ImageAnnotations(circles=[], points=[bones, joints], texts=[])


# --- beliefs -> plottable fields; descriptions -> log --------------------------------------


def posterior(p: ActionPosterior) -> PosteriorView:
    by_action = dict(zip(p.actions, p.posterior, strict=True))
    return PosteriorView(
        timestamp=Time.from_ns(p.header.stamp),
        segment_id=p.segment_id,
        frame=p.frame,
        final=p.final,
        posterior=by_action,
        normalised_log_likelihood=dict(zip(p.actions, p.normalised_log_likelihood, strict=True)),
        best=max(by_action, key=by_action.__getitem__) if by_action else "",
    )


def affordance(p: AffordancePrediction) -> AffordanceView:
    return AffordanceView(
        timestamp=Time.from_ns(p.header.stamp),
        segment_id=p.segment_id,
        frame=p.frame,
        final=p.final,
        action_belief=p.action_belief,
        effects=p.effects,
        most_likely={var: max(d, key=d.__getitem__) for var, d in p.effects.items() if d},
    )


def log_line(d: Description) -> Log:
    best = d.sentences[0] if d.sentences else None
    text = f'"{best.text}" (score {best.score:.3g})' if best else "(no sentence)"
    state = "final" if d.final else "anticipated"
    return Log(
        timestamp=Time.from_ns(d.header.stamp),
        level=2,
        message=f"gesture {d.segment_id} {state}: {text}",
        name=d.header.source,
        file="description",
        line=d.segment_id,
    )


# --- the table -----------------------------------------------------------------------------


@dataclass(frozen=True)
class View:
    name: str  # last key chunk: beyond/<robot>/foxglove/<name>
    source: type[Message]
    struct: type[ViewStruct]
    make: Callable[[Any], ViewStruct]

    @property
    def schema_name(self) -> str:
        return self.struct.SCHEMA_NAME

    def schema(self) -> bytes:
        schema = self_contained_schema(self.struct)
        schema["title"] = self.struct.SCHEMA_NAME
        return msgspec.json.encode(schema, order="sorted")

    def topic(self, root: str) -> str:
        return f"{root}/{VIEW_PREFIX}/{self.name}"


VIEWS: tuple[View, ...] = (
    View("scene", SkeletonFrame, SceneUpdate, scene),
    View("objects", DetectedObjects, ImageAnnotations, image_annotations),
    View("pose", PersonPose, ImageAnnotations, pose_annotations),
    View("posterior", ActionPosterior, PosteriorView, posterior),
    View("affordance", AffordancePrediction, AffordanceView, affordance),
    View("log", Description, Log, log_line),
)
VIEWS_OF: dict[type[Message], tuple[View, ...]] = {
    cls: tuple(v for v in VIEWS if v.source is cls) for cls in {v.source for v in VIEWS}
}
_encoder = msgspec.json.Encoder()


def encode_view(view: View, message: Message) -> bytes:
    return _encoder.encode(view.make(message))


def is_view_key(key: str) -> bool:
    split = split_key(key)
    return split is not None and split[1].startswith(f"{VIEW_PREFIX}/")


def root_of(key: str) -> str | None:
    split = split_key(key)
    return None if split is None else f"beyond/{split[0]}"
