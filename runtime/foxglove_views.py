"""Foxglove views of bus messages: what the bridge and `beyond record --foxglove` add next to the
messages themselves, so Foxglove's stock panels show them without a plug-in.

- `beyond/<robot>/foxglove/scene`: the skeleton as a `foxglove.SceneUpdate` (a sphere per joint,
  coloured by tracking confidence, and a line list of bones) for the 3D panel;
- `.../foxglove/objects`: detected objects as `foxglove.ImageAnnotations` (a circle of the
  object's area at its centroid and its Color/Shape/Size labels) for the Image panel, stamped
  like the camera frame they were found in, so Foxglove draws them over that frame;
- `.../foxglove/posterior` and `.../foxglove/affordance`: the action posterior and the effect
  predictions as maps from value to probability, so a Plot panel path reads
  `.posterior.grasp` or `.effects.ObjVel.fast`;
- `.../foxglove/log`: each description as a `foxglove.Log` line for the Log panel.

The view types are our own msgspec Structs laid out as Foxglove's (documented) message types and
encoded as JSON, Foxglove's schema-described encoding that any WebSocket client reads as is;
their JSON Schemas come from the same Structs. Stamps are Foxglove `Time`, never bare integers.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import msgspec

from beyond_self.schemas.base import Message
from beyond_self.schemas.codec import self_contained_schema
from beyond_self.schemas.keys import split_key
from beyond_self.schemas.messages import (
    ActionPosterior,
    AffordancePrediction,
    Description,
    DetectedObjects,
    SkeletonFrame,
    Time,
)

VIEW_PREFIX = "foxglove"  # beyond/<robot>/foxglove/<view>: never a bus key


class _View(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    SCHEMA_NAME: ClassVar[str] = ""


class Vector3(msgspec.Struct, frozen=True):
    x: float
    y: float
    z: float


class Quaternion(msgspec.Struct, frozen=True):
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    w: float = 1.0


class Pose(msgspec.Struct, frozen=True):
    position: Vector3
    orientation: Quaternion = Quaternion()


class Color(msgspec.Struct, frozen=True):
    r: float
    g: float
    b: float
    a: float = 1.0


class Point2(msgspec.Struct, frozen=True):
    x: float
    y: float


class KeyValuePair(msgspec.Struct, frozen=True):
    key: str
    value: str


class SpherePrimitive(msgspec.Struct, frozen=True):
    pose: Pose
    size: Vector3
    color: Color


class LinePrimitive(msgspec.Struct, frozen=True):
    type: int  # 0 line strip, 1 line loop, 2 line list
    pose: Pose
    thickness: float
    scale_invariant: bool
    points: list[Vector3]
    color: Color
    colors: list[Color] = msgspec.field(default_factory=list)
    indices: list[int] = msgspec.field(default_factory=list)


class TextPrimitive(msgspec.Struct, frozen=True):
    pose: Pose
    billboard: bool
    font_size: float
    scale_invariant: bool
    color: Color
    text: str


class SceneEntity(msgspec.Struct, frozen=True):
    timestamp: Time
    frame_id: str
    id: str
    lifetime: Time  # a Duration: 0 = until replaced by an entity of the same id
    frame_locked: bool
    metadata: list[KeyValuePair]
    spheres: list[SpherePrimitive]
    lines: list[LinePrimitive]
    texts: list[TextPrimitive]
    # primitives we never draw; present because Foxglove's schema requires every list
    arrows: list[Any] = msgspec.field(default_factory=list)
    cubes: list[Any] = msgspec.field(default_factory=list)
    cylinders: list[Any] = msgspec.field(default_factory=list)
    triangles: list[Any] = msgspec.field(default_factory=list)
    models: list[Any] = msgspec.field(default_factory=list)


class SceneUpdate(_View, frozen=True):
    SCHEMA_NAME: ClassVar[str] = "foxglove.SceneUpdate"

    deletions: list[Any]
    entities: list[SceneEntity]


class CircleAnnotation(msgspec.Struct, frozen=True):
    timestamp: Time
    position: Point2
    diameter: float
    thickness: float
    fill_color: Color
    outline_color: Color


class PointsAnnotation(msgspec.Struct, frozen=True):
    timestamp: Time
    type: int  # 1 points, 2 line loop, 3 line strip, 4 line list
    points: list[Point2]
    outline_color: Color
    outline_colors: list[Color]
    fill_color: Color
    thickness: float


class TextAnnotation(msgspec.Struct, frozen=True):
    timestamp: Time
    position: Point2
    text: str
    font_size: float
    text_color: Color
    background_color: Color


class ImageAnnotations(_View, frozen=True):
    SCHEMA_NAME: ClassVar[str] = "foxglove.ImageAnnotations"

    circles: list[CircleAnnotation]
    points: list[PointsAnnotation]
    texts: list[TextAnnotation]


class Log(_View, frozen=True):
    SCHEMA_NAME: ClassVar[str] = "foxglove.Log"

    timestamp: Time
    level: int  # 1 debug, 2 info, 3 warning, 4 error, 5 fatal
    message: str
    name: str
    file: str
    line: int


class _GestureView(_View, frozen=True):
    """What a plot of a gesture's beliefs keys on: when, which gesture, which skeleton frame, and
    whether it is the gesture's last word (the fields come first in every such view)."""

    timestamp: Time
    segment_id: int
    frame: int
    final: bool


class PosteriorView(_GestureView, frozen=True):
    """The streaming action posterior by action name (plottable: `.posterior.tap`)."""

    SCHEMA_NAME: ClassVar[str] = "beyond.view.ActionPosterior"

    posterior: dict[str, float]
    normalised_log_likelihood: dict[str, float]
    best: str


class AffordanceView(_GestureView, frozen=True):
    """Predicted effects as nested maps (plottable: `.effects.ObjVel.fast`) and their argmax."""

    SCHEMA_NAME: ClassVar[str] = "beyond.view.AffordancePrediction"

    action_belief: dict[str, float]
    effects: dict[str, dict[str, float]]
    most_likely: dict[str, str]


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
    struct: type[_View]
    make: Callable[[Any], _View]

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
