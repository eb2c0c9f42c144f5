"""Foxglove's message types (SceneUpdate, ImageAnnotations, Log, ...) and our plottable views,
as msgspec Structs laid out field for field as Foxglove documents them, encoded as JSON; their
JSON Schemas come from the same Structs. The views that fill them are runtime.foxglove.views."""

from __future__ import annotations

from typing import Any, ClassVar

import msgspec

from beyond_self.schemas.messages import Time


class ViewStruct(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A whole view message (a Foxglove message type, or one of our plottable ones)."""

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


class SceneUpdate(ViewStruct, frozen=True):
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


class ImageAnnotations(ViewStruct, frozen=True):
    SCHEMA_NAME: ClassVar[str] = "foxglove.ImageAnnotations"

    circles: list[CircleAnnotation]
    points: list[PointsAnnotation]
    texts: list[TextAnnotation]


class Log(ViewStruct, frozen=True):
    SCHEMA_NAME: ClassVar[str] = "foxglove.Log"

    timestamp: Time
    level: int  # 1 debug, 2 info, 3 warning, 4 error, 5 fatal
    message: str
    name: str
    file: str
    line: int


class _GestureView(ViewStruct, frozen=True):
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
