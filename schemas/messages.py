"""Every message type on the bus, one Struct each.

Field names follow the article's variables (SPEC.md): effect variables ObjVel, HandVel, ObjHandVel,
Contact; object features Color, Size, Shape with their cluster labels. Distributions are
`dict[value, probability]` so a reader needs no side table to know what each number means.
The two camera types are field-for-field Foxglove's well-known `foxglove.RawImage` and
`foxglove.CompressedImage` (plus our header), so recordings display in Foxglove as they are.
"""

from __future__ import annotations

import math
from typing import Annotated, ClassVar, Literal

import msgspec

from schemas.base import Header, Message

# Bytes per pixel of the raw encodings Foxglove understands.
RAW_ENCODINGS: dict[str, int] = {
    "rgb8": 3,
    "bgr8": 3,
    "rgba8": 4,
    "bgra8": 4,
    "mono8": 1,
    "mono16": 2,
    "16UC1": 2,
    "32FC1": 4,
}
COMPRESSED_FORMATS = ("jpeg", "png", "webp")


def _check_distribution(name: str, dist: dict[str, float]) -> None:
    if not dist:
        raise ValueError(f"{name} is an empty distribution")
    for value, p in dist.items():
        if not (0.0 <= p <= 1.0) or math.isnan(p):
            raise ValueError(f"{name}[{value!r}] = {p} is not a probability in [0, 1]")
    total = sum(dist.values())
    if abs(total - 1.0) > 1e-6:
        raise ValueError(f"{name} sums to {total:.6g}, not 1")


# Checked by msgspec's C decoder (fast enough for 30 Hz x many joints): finite, bounded values.
# NaN and infinities fail the bounds; they would not survive JSON recordings either.
Coordinate = Annotated[float, msgspec.Meta(ge=-1e6, le=1e6)]
Probability = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]


class Joint(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A tracked joint: position in metres in the sensor frame, and tracking confidence in [0, 1]
    (Kinect/OpenNI report 0 not tracked, 0.5 inferred, 1 tracked). Values are checked when
    decoded (not when constructed, to keep publishing cheap)."""

    position: tuple[Coordinate, Coordinate, Coordinate]
    confidence: Probability = 1.0


class SkeletonFrame(Message, frozen=True):
    """One frame of a body tracker: joint name -> position and confidence."""

    frame: int
    joints: dict[str, Joint]
    user: int = 0
    frame_id: str = "depth_camera"


class Time(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Foxglove's timestamp layout."""

    sec: int
    nsec: int

    @classmethod
    def from_ns(cls, ns: int) -> Time:
        return cls(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)

    def to_ns(self) -> int:
        return self.sec * 1_000_000_000 + self.nsec


class CameraFrame(Message, frozen=True):
    """An uncompressed image; the same fields as foxglove.RawImage (timestamp = header stamp)."""

    SCHEMA_NAME: ClassVar[str] = "foxglove.RawImage"

    timestamp: Time
    frame_id: str
    width: int
    height: int
    encoding: str
    step: int
    data: bytes

    def __post_init__(self) -> None:
        if self.encoding not in RAW_ENCODINGS:
            raise ValueError(
                f"encoding {self.encoding!r} unknown; valid: {', '.join(RAW_ENCODINGS)}"
            )
        if self.timestamp.to_ns() != self.header.stamp:
            raise ValueError(f"timestamp {self.timestamp.to_ns()} differs from header stamp")
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"size {self.width}x{self.height} must be positive")
        if self.step < self.width * RAW_ENCODINGS[self.encoding]:
            raise ValueError(f"step {self.step} too small for {self.width} px of {self.encoding}")
        if len(self.data) != self.step * self.height:
            raise ValueError(
                f"data has {len(self.data)} bytes, expected step*height = {self.step * self.height}"
            )

    @classmethod
    def build(
        cls,
        header: Header,
        width: int,
        height: int,
        data: bytes,
        encoding: str = "rgb8",
        frame_id: str = "camera",
    ) -> CameraFrame:
        """A frame with timestamp and step derived from the header and encoding."""
        bpp = RAW_ENCODINGS.get(encoding, 1)
        return cls(
            header=header,
            timestamp=Time.from_ns(header.stamp),
            frame_id=frame_id,
            width=width,
            height=height,
            encoding=encoding,
            step=width * bpp,
            data=data,
        )


class CompressedCameraFrame(Message, frozen=True):
    """A compressed image; the fields of foxglove.CompressedImage plus its size for consumers."""

    SCHEMA_NAME: ClassVar[str] = "foxglove.CompressedImage"

    timestamp: Time
    frame_id: str
    format: str
    data: bytes
    width: int = 0
    height: int = 0

    def __post_init__(self) -> None:
        if self.timestamp.to_ns() != self.header.stamp:
            raise ValueError(f"timestamp {self.timestamp.to_ns()} differs from header stamp")
        if self.format not in COMPRESSED_FORMATS:
            raise ValueError(
                f"format {self.format!r} unknown; valid: {', '.join(COMPRESSED_FORMATS)}"
            )


class DetectedObject(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """One segmented object: continuous features and the cluster labels they fall in
    (the network's Color, Shape and Size values)."""

    id: int
    centroid: tuple[float, float]
    area: float
    colour: list[float]
    shape: list[float]
    size: list[float]
    colour_label: str
    shape_label: str
    size_label: str


class DetectedObjects(Message, frozen=True):
    frame: int
    objects: list[DetectedObject]


class ObjectEffect(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Measured effect of an action on one object: velocities (metres or pixels per second,
    as `units` says), contact, and their discretisation into the network's effect values
    (labels keys: ObjVel, HandVel, ObjHandVel, Contact)."""

    object_id: int
    object_velocity: float
    hand_velocity: float | None  # None: the hand was not seen
    object_hand_velocity: float | None
    contact: bool
    contact_duration: float | None
    labels: dict[str, str] = msgspec.field(default_factory=dict)
    # the acted-on object's Color, Shape, Size labels (it may not be the biggest on the table)
    object_labels: dict[str, str] = msgspec.field(default_factory=dict)
    units: str = "m/s"


class ObjectEffects(Message, frozen=True):
    """The effects measured over one gesture (`segment_id` of the gesture streamer).

    Version 2: the object segmenter sends exactly one per gesture, also when it could not measure
    (`measured` false, `reason` says why: no camera stream, too few frames over the gesture, the
    camera stopped), so a consumer never has to guess from a timer whether effects will come."""

    VERSION: ClassVar[int] = 2

    frame: int
    effects: list[ObjectEffect]
    segment_id: int = 0
    measured: bool = True
    reason: str = ""


class GestureObject(Message, frozen=True):
    """The object a gesture is about, as the camera saw it when the gesture began: the biggest
    object of the last camera frame stamped at or before the gesture's first frame. One per
    gesture; `labels` is empty and `reason` says why when no frame showed an object. The
    reasoner's anticipation joins on it by `segment_id`, never on "the latest objects seen"."""

    segment_id: int
    frame: int  # the camera frame the labels come from (0: none)
    labels: dict[str, str]
    reason: str = ""


class GestureSegment(Message, frozen=True):
    """A gesture starts or ends; `end_stamp` is set on "end".

    Version 2: "cancel" withdraws a started gesture the segmenter did not keep (too short, or
    still under way when the source ended), so no consumer waits for an end that never comes."""

    VERSION: ClassVar[int] = 2

    event: Literal["start", "end", "cancel"]
    segment_id: int
    frame: int
    start_stamp: int
    end_stamp: int | None = None
    event_seq: int = 0  # 1, 2, ... over the streamer's events: a receiver knows what it has

    def __post_init__(self) -> None:
        if self.event == "end" and self.end_stamp is None:
            raise ValueError("an 'end' event needs end_stamp")


class ActionPosterior(Message, frozen=True):
    """P_HMM(A | G_1^t) at frame t of a segment, with the per-action log-likelihoods
    (cumulative, and divided by t as plotted in the article)."""

    segment_id: int
    frame: int
    actions: list[str]
    posterior: list[float]
    log_likelihood: list[float]
    normalised_log_likelihood: list[float]
    final: bool = False  # over exactly the gesture's frames, published just before its "end"

    def __post_init__(self) -> None:
        n = len(self.actions)
        for name in ("posterior", "log_likelihood", "normalised_log_likelihood"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"{name} has {len(getattr(self, name))} values for {n} actions")
        _check_distribution("posterior", dict(zip(self.actions, self.posterior, strict=True)))


class AffordancePrediction(Message, frozen=True):
    """P_comb over effect variables given the observed evidence and the action belief."""

    segment_id: int
    frame: int
    action_belief: dict[str, float]
    evidence: dict[str, str]
    effects: dict[str, dict[str, float]]
    final: bool = False  # anticipation while the gesture unfolds, or the belief once complete

    def __post_init__(self) -> None:
        _check_distribution("action_belief", self.action_belief)
        for var, dist in self.effects.items():
            _check_distribution(f"effects[{var!r}]", dist)


class WordProbabilities(Message, frozen=True):
    """P(word present | evidence) per vocabulary word."""

    segment_id: int
    words: dict[str, float]
    evidence: dict[str, str] = msgspec.field(default_factory=dict)
    action_belief: dict[str, float] = msgspec.field(default_factory=dict)
    final: bool = True

    def __post_init__(self) -> None:
        for word, p in self.words.items():
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"P({word!r}) = {p} is not in [0, 1]")


class ScoredSentence(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    text: str
    score: float


class Evidence(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """What a description was computed from: hard values and soft distributions."""

    hard: dict[str, str] = msgspec.field(default_factory=dict)
    soft: dict[str, dict[str, float]] = msgspec.field(default_factory=dict)


class Description(Message, frozen=True):
    """N-best sentences, best first, and the evidence that produced them."""

    segment_id: int
    sentences: list[ScoredSentence]
    evidence: Evidence
    final: bool = True


class ServiceHealth(Message, frozen=True):
    """Periodic self-report of a service."""

    service: str
    uptime_s: float
    messages_in: int
    messages_out: int
    dropped: int
    malformed: int
    errors: int
    last_error: str = ""
    inputs: list[str] = msgspec.field(default_factory=list)
    outputs: list[str] = msgspec.field(default_factory=list)


class StreamEnd(Message, frozen=True):
    """A sensor source is exhausted (end of a recording or log): how much it published.

    Version 2: `last_stamps` gives, per sensor stream name (schemas.keys.STREAMS), the stamp of
    the last message published on it (a stream never published is absent). A consumer knows its
    input is complete once it has handled the message with that stamp, whatever order the end
    marker and the data arrive in."""

    VERSION: ClassVar[int] = 2

    source: str
    messages: int
    dropped: int = 0
    last_stamps: dict[str, int] = msgspec.field(default_factory=dict)


class Progress(Message, frozen=True):
    """How far a service has handled each of its sensor inputs: key -> stamp of the last message
    handled (-1: none yet). The player paces itself on it, so a replay as fast as possible never
    outruns the slowest consumer and nothing is dropped."""

    service: str
    handled: dict[str, int]
    # messages published so far per output key: a consumer that has received that many knows
    # it has everything this service derived from the inputs handled so far
    published: dict[str, int] = msgspec.field(default_factory=dict)
    received: dict[str, int] = msgspec.field(default_factory=dict)  # per input key
    # stamp of the last message published per output key: a restarted instance of the service
    # does not publish again what its predecessor already did
    published_stamps: dict[str, int] = msgspec.field(default_factory=dict)


class AffordanceQuery(Message, frozen=True):
    """An ad-hoc question to the reasoner: P(query | evidence, soft evidence, gesture evidence).
    `soft`: variable -> {value: likelihood}; `gesture`: P_HMM(A | G) by action (fused)."""

    query: list[str]
    evidence: dict[str, str] = msgspec.field(default_factory=dict)
    soft: dict[str, dict[str, float]] = msgspec.field(default_factory=dict)
    gesture: dict[str, float] = msgspec.field(default_factory=dict)


class AnswerRow(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    assignment: dict[str, str]
    p: float


class AffordanceAnswer(Message, frozen=True):
    """The reasoner's answer: the joint posterior of the queried variables, row by row."""

    variables: list[str]
    rows: list[AnswerRow]


ALL_MESSAGES: tuple[type[Message], ...] = (
    SkeletonFrame,
    CameraFrame,
    CompressedCameraFrame,
    DetectedObjects,
    ObjectEffects,
    GestureObject,
    GestureSegment,
    ActionPosterior,
    AffordancePrediction,
    WordProbabilities,
    Description,
    ServiceHealth,
    StreamEnd,
    Progress,
    AffordanceQuery,
    AffordanceAnswer,
)
