"""Every message type on the bus, one Struct each.

Field names follow the article's variables (docs/science/index.md): effect variables ObjVel,
HandVel, ObjHandVel, Contact; object features Color, Size, Shape with their cluster labels.
Distributions are `dict[value, probability]`: a reader needs no side table for the numbers.
The two camera types are field-for-field Foxglove's well-known `foxglove.RawImage` and
`foxglove.CompressedImage` (plus our header), so recordings display in Foxglove as they are.
"""

from __future__ import annotations

import math
from typing import Annotated, ClassVar, Literal

import msgspec

from beyond_self.schemas.base import (
    JS_INT_MAX,
    NAME_MAX,
    STAMP_MARK,
    STAMP_MAX,
    Header,
    Message,
    Stamp,
)

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


# ---------------------------------------------------------------- bounds
# What a payload may hold, checked for meaning as well as shape when it is decoded: a message
# outside these is malformed (a SchemaError, counted and skipped by the services), so one hostile
# message cannot make a service allocate, compute or log without bound. Checked by msgspec's C
# decoder (fast enough for 30 Hz x many joints); the few cross-field checks are __post_init__.
# NaN and infinities fail the bounds; they would not survive JSON recordings either.
FRAME_MAX = 2**40  # frame indices: 1,000 years at 30 fps
ID_MAX = 2**31 - 1  # segment, object and user ids
JOINTS_MAX = 128  # joints per skeleton frame (Kinect has 25, MediaPipe 33)
IMAGE_SIDE_MAX = 16_384  # pixels per image side
IMAGE_BYTES_MAX = 32 * 2**20  # bytes of one camera frame (4K RGBA is 31.6 MiB)
OBJECTS_MAX = 256  # objects per frame, effects per gesture
FEATURES_MAX = 64  # numbers per feature vector
VARIABLES_MAX = 64  # variables of an evidence, a query or a prediction
VALUES_MAX = 64  # values of one variable's distribution, actions of a posterior
WORDS_MAX = 4096  # words of one WordProbabilities
SENTENCES_MAX = 10_000  # sentences of one Description (beyond describe's --nbest limit)
TEXT_MAX = 4096  # characters of a sentence or an error text
ROWS_MAX = 65_536  # rows of an AffordanceAnswer (the reasoner refuses bigger joint queries)
SPEED_MAX = 1e6  # m/s or px/s
AREA_MAX = 1e12  # px^2 (or m^2)
SECONDS_MAX = 1e9  # any duration in seconds (31 years)
FINITE = 1e300

Coordinate = Annotated[float, msgspec.Meta(ge=-1e6, le=1e6)]
Probability = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
Finite = Annotated[float, msgspec.Meta(ge=-FINITE, le=FINITE)]
LogValue = Annotated[float, msgspec.Meta(le=FINITE)]  # a log-probability: -inf allowed, no NaN
NonNegative = Annotated[float, msgspec.Meta(ge=0.0, le=FINITE)]
Speed = Annotated[float, msgspec.Meta(ge=0.0, le=SPEED_MAX)]
Seconds = Annotated[float, msgspec.Meta(ge=0.0, le=SECONDS_MAX)]
FrameIndex = Annotated[int, msgspec.Meta(ge=0, le=FRAME_MAX)]
Id = Annotated[int, msgspec.Meta(ge=0, le=ID_MAX)]
Count = Annotated[int, msgspec.Meta(ge=0, le=JS_INT_MAX)]
Name = Annotated[str, msgspec.Meta(max_length=NAME_MAX)]
Text = Annotated[str, msgspec.Meta(max_length=TEXT_MAX)]
Distribution = Annotated[dict[Name, Probability], msgspec.Meta(max_length=VALUES_MAX)]
Assignment = Annotated[dict[Name, Name], msgspec.Meta(max_length=VARIABLES_MAX)]
Features = Annotated[list[Finite], msgspec.Meta(max_length=FEATURES_MAX)]
Likelihoods = Annotated[dict[Name, NonNegative], msgspec.Meta(max_length=VALUES_MAX)]
# a stamp, or -1: nothing yet (Progress); the JSON form writes -1 as null
StampOrNone = Annotated[
    int, msgspec.Meta(ge=-1, le=STAMP_MAX, extra_json_schema={STAMP_MARK: "ns, -1: none yet"})
]
# per key expression (Progress)
StampsPerKey = Annotated[dict[Text, StampOrNone], msgspec.Meta(max_length=VARIABLES_MAX)]
CountsPerKey = Annotated[dict[Text, Count], msgspec.Meta(max_length=VARIABLES_MAX)]


class Joint(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A tracked joint: position in metres in the sensor frame, and tracking confidence in [0, 1]
    (Kinect/OpenNI report 0 not tracked, 0.5 inferred, 1 tracked). Values are checked when
    decoded (not when constructed, to keep publishing cheap)."""

    position: tuple[Coordinate, Coordinate, Coordinate]
    confidence: Probability = 1.0


class SkeletonFrame(Message, frozen=True):
    """One frame of a body tracker: joint name -> position and confidence."""

    frame: FrameIndex
    # joint names are not length-checked: this decode is the hot path, and the count is capped
    joints: Annotated[dict[str, Joint], msgspec.Meta(max_length=JOINTS_MAX)]
    user: Id = 0
    frame_id: Name = "depth_camera"


class Time(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Foxglove's timestamp layout."""

    sec: Annotated[int, msgspec.Meta(ge=0, le=STAMP_MAX // 1_000_000_000)]
    nsec: Annotated[int, msgspec.Meta(ge=0, le=999_999_999)]

    @classmethod
    def from_ns(cls, ns: int) -> Time:
        return cls(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)

    def to_ns(self) -> int:
        return self.sec * 1_000_000_000 + self.nsec


class CameraFrame(Message, frozen=True):
    """An uncompressed image; the same fields as foxglove.RawImage (timestamp = header stamp)."""

    SCHEMA_NAME: ClassVar[str] = "foxglove.RawImage"

    timestamp: Time
    frame_id: Name
    width: Annotated[int, msgspec.Meta(ge=0, le=IMAGE_SIDE_MAX)]
    height: Annotated[int, msgspec.Meta(ge=0, le=IMAGE_SIDE_MAX)]
    encoding: Name
    step: Annotated[int, msgspec.Meta(ge=0, le=IMAGE_BYTES_MAX)]
    data: Annotated[bytes, msgspec.Meta(max_length=IMAGE_BYTES_MAX)]

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
    frame_id: Name
    format: Name
    data: Annotated[bytes, msgspec.Meta(max_length=IMAGE_BYTES_MAX)]
    width: Annotated[int, msgspec.Meta(ge=0, le=IMAGE_SIDE_MAX)] = 0
    height: Annotated[int, msgspec.Meta(ge=0, le=IMAGE_SIDE_MAX)] = 0

    def __post_init__(self) -> None:
        if self.timestamp.to_ns() != self.header.stamp:
            raise ValueError(f"timestamp {self.timestamp.to_ns()} differs from header stamp")
        if self.format not in COMPRESSED_FORMATS:
            raise ValueError(
                f"format {self.format!r} unknown; valid: {', '.join(COMPRESSED_FORMATS)}"
            )


class Keypoint(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A joint in an image: pixels from the image's top-left corner (x right, y down; outside
    the image for a joint the model guessed), and the model's confidence in [0, 1]."""

    position: tuple[Coordinate, Coordinate]
    confidence: Probability = 1.0


class PersonPose(Message, frozen=True):
    """Where a person's joints are in the image their skeleton was estimated from (a pose model
    on a camera, cognition.pose): the skeleton frame of the same stamp holds them in metres,
    this in that image's pixels, so a viewer draws the pose over the picture."""

    frame: FrameIndex
    width: Annotated[int, msgspec.Meta(ge=1, le=IMAGE_SIDE_MAX)]
    height: Annotated[int, msgspec.Meta(ge=1, le=IMAGE_SIDE_MAX)]
    keypoints: Annotated[dict[Name, Keypoint], msgspec.Meta(max_length=JOINTS_MAX)]
    frame_id: Name = "person_camera"


class DetectedObject(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """One segmented object: continuous features and the cluster labels they fall in
    (the network's Color, Shape and Size values)."""

    id: Id
    centroid: tuple[Coordinate, Coordinate]
    area: Annotated[float, msgspec.Meta(ge=0.0, le=AREA_MAX)]
    colour: Features
    shape: Features
    size: Features
    colour_label: Name
    shape_label: Name
    size_label: Name


class DetectedObjects(Message, frozen=True):
    """The objects of one camera frame.

    Version 2: `skipped` counts the camera frames since the previous `DetectedObjects` that were
    not described: a live camera faster than the object segmenter has its newest frame described
    and the ones it overtook skipped (they were still used for every gesture). A replay never
    skips, so a stream whose `skipped` are all 0 equals the offline analysis of its recording."""

    VERSION: ClassVar[int] = 2

    frame: FrameIndex
    objects: Annotated[list[DetectedObject], msgspec.Meta(max_length=OBJECTS_MAX)]
    skipped: Count = 0


class ObjectEffect(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Measured effect of an action on one object: velocities (metres or pixels per second,
    as `units` says), contact, and their discretisation into the network's effect values
    (labels keys: ObjVel, HandVel, ObjHandVel, Contact)."""

    object_id: Id
    object_velocity: Speed
    hand_velocity: Speed | None  # None: the hand was not seen
    object_hand_velocity: Speed | None
    contact: bool
    contact_duration: Seconds | None
    labels: Assignment = msgspec.field(default_factory=dict)
    # the acted-on object's Color, Shape, Size labels (it may not be the biggest on the table)
    object_labels: Assignment = msgspec.field(default_factory=dict)
    units: Name = "m/s"


class ObjectEffects(Message, frozen=True):
    """The effects measured over one gesture (`segment_id` of the gesture streamer).

    Version 2: the object segmenter sends exactly one per gesture, also when it could not measure
    (`measured` false, `reason` says why: no camera stream, too few frames over the gesture, the
    camera stopped), so a consumer never has to guess from a timer whether effects will come."""

    VERSION: ClassVar[int] = 2

    frame: FrameIndex
    effects: Annotated[list[ObjectEffect], msgspec.Meta(max_length=OBJECTS_MAX)]
    segment_id: Id = 0
    measured: bool = True
    reason: Text = ""


class GestureObject(Message, frozen=True):
    """The object a gesture is about, as the camera saw it when the gesture began: the biggest
    object of the last camera frame stamped at or before the gesture's first frame. One per
    gesture; `labels` is empty and `reason` says why when no frame showed an object. The
    reasoner's anticipation joins on it by `segment_id`, never on "the latest objects seen"."""

    segment_id: Id
    frame: FrameIndex  # the camera frame the labels come from (0: none)
    labels: Assignment
    reason: Text = ""


class GestureSegment(Message, frozen=True):
    """A gesture starts or ends; `end_stamp` is set on "end".

    Version 2: "cancel" withdraws a started gesture the segmenter did not keep (too short, or
    still under way when the source ended), so no consumer waits for an end that never comes.
    A cancel says why (`reason`), and `cut` when it was a gesture whose frames are gone (lost,
    not withdrawn: `beyond up` counts it and exits non-zero); both default, so older messages
    decode."""

    VERSION: ClassVar[int] = 2

    event: Literal["start", "end", "cancel"]
    segment_id: Id
    frame: FrameIndex
    start_stamp: Stamp
    end_stamp: Stamp | None = None
    event_seq: Count = 0  # 1, 2, ... over the streamer's events: a receiver knows what it has
    reason: Text = ""  # a cancel's why, one line
    cut: bool = False  # a cancel of a gesture whose frames were lost

    def __post_init__(self) -> None:
        if self.event == "end" and self.end_stamp is None:
            raise ValueError("an 'end' event needs end_stamp")
        if self.end_stamp is not None and self.end_stamp < self.start_stamp:
            raise ValueError(f"end_stamp {self.end_stamp} is before start_stamp {self.start_stamp}")


class ActionPosterior(Message, frozen=True):
    """P_HMM(A | G_1^t) at frame t of a segment, with the per-action log-likelihoods
    (cumulative, and divided by t as plotted in the article)."""

    segment_id: Id
    frame: FrameIndex
    actions: Annotated[list[Name], msgspec.Meta(max_length=VALUES_MAX)]
    posterior: Annotated[list[Probability], msgspec.Meta(max_length=VALUES_MAX)]
    log_likelihood: Annotated[list[LogValue], msgspec.Meta(max_length=VALUES_MAX)]
    normalised_log_likelihood: Annotated[list[LogValue], msgspec.Meta(max_length=VALUES_MAX)]
    final: bool = False  # over exactly the gesture's frames, published just before its "end"

    def __post_init__(self) -> None:
        n = len(self.actions)
        for name in ("posterior", "log_likelihood", "normalised_log_likelihood"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"{name} has {len(getattr(self, name))} values for {n} actions")
        _check_distribution("posterior", dict(zip(self.actions, self.posterior, strict=True)))


class AffordancePrediction(Message, frozen=True):
    """P_comb over effect variables given the observed evidence and the action belief."""

    segment_id: Id
    frame: FrameIndex
    action_belief: Distribution
    evidence: Assignment
    effects: Annotated[dict[Name, Distribution], msgspec.Meta(max_length=VARIABLES_MAX)]
    final: bool = False  # anticipation while the gesture unfolds, or the belief once complete

    def __post_init__(self) -> None:
        _check_distribution("action_belief", self.action_belief)
        for var, dist in self.effects.items():
            _check_distribution(f"effects[{var!r}]", dist)


class WordProbabilities(Message, frozen=True):
    """P(word present | evidence) per vocabulary word."""

    segment_id: Id
    words: Annotated[dict[Name, Probability], msgspec.Meta(max_length=WORDS_MAX)]
    evidence: Assignment = msgspec.field(default_factory=dict)
    action_belief: Distribution = msgspec.field(default_factory=dict)
    final: bool = True

    def __post_init__(self) -> None:
        for word, p in self.words.items():
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"P({word!r}) = {p} is not in [0, 1]")


class ScoredSentence(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    text: Text
    score: LogValue  # -inf: a sentence with an impossible word


class Evidence(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """What a description was computed from: hard values and soft distributions."""

    hard: Assignment = msgspec.field(default_factory=dict)
    soft: Annotated[dict[Name, Likelihoods], msgspec.Meta(max_length=VARIABLES_MAX)] = (
        msgspec.field(default_factory=dict)
    )


class Description(Message, frozen=True):
    """N-best sentences, best first, and the evidence that produced them."""

    segment_id: Id
    sentences: Annotated[list[ScoredSentence], msgspec.Meta(max_length=SENTENCES_MAX)]
    evidence: Evidence
    final: bool = True


class ServiceHealth(Message, frozen=True):
    """Periodic self-report of a service.

    Version 2: `skipped` counts inputs whose per-frame work was skipped to keep up with a live
    source (camera frames the object segmenter did not describe; never per-gesture work);
    `restarts`, how many times its supervisor (`beyond up`, a Deployment) restarted
    the service after it died before this instance (0: the first).

    Version 3 counts the sensor messages not taken (runtime.event_time): `stale`, not after
    the last one handled from their source; `foreign`, from a source other than the one their
    key belongs to; `refused`, refused by a handler as bad input (also among `errors`)."""

    VERSION: ClassVar[int] = 3

    service: Name
    uptime_s: Seconds
    messages_in: Count
    messages_out: Count
    dropped: Count
    malformed: Count
    errors: Count
    last_error: Text = ""
    inputs: Annotated[list[Text], msgspec.Meta(max_length=VARIABLES_MAX)] = msgspec.field(
        default_factory=list
    )
    outputs: Annotated[list[Text], msgspec.Meta(max_length=VARIABLES_MAX)] = msgspec.field(
        default_factory=list
    )
    skipped: Count = 0
    restarts: Count = 0
    stale: Count = 0
    foreign: Count = 0
    refused: Count = 0


class StreamEnd(Message, frozen=True):
    """A sensor source is exhausted (end of a recording or log): how much it published.

    Version 2: `last_stamps` gives, per sensor stream name (schemas.keys.STREAMS), the stamp of
    the last message published on it (a stream never published is absent). A consumer knows its
    input is complete once it has handled the message with that stamp, whatever order the end
    marker and the data arrive in.

    Version 3: `damage` says in one line what the source could not play (a damaged recording:
    unreadable chunks, a truncated end, frames that do not decode or go back in time; "" when
    nothing was lost), the line `beyond inspect` and `beyond analyse` print for the same file,
    so `beyond up` can say it and exit 2 as they do."""

    VERSION: ClassVar[int] = 3

    source: Name
    messages: Count
    dropped: Count = 0
    last_stamps: Annotated[dict[Name, Stamp], msgspec.Meta(max_length=VARIABLES_MAX)] = (
        msgspec.field(default_factory=dict)
    )
    damage: Text = ""


class Progress(Message, frozen=True):
    """How far a service has handled each of its sensor inputs: key -> stamp of the last message
    handled (-1: none yet). The player paces itself on it, so a replay as fast as possible never
    outruns the slowest consumer and nothing is dropped."""

    service: Name
    handled: StampsPerKey
    # messages published so far per output key: a consumer that has received that many knows
    # it has everything this service derived from the inputs handled so far
    published: CountsPerKey = msgspec.field(default_factory=dict)
    received: CountsPerKey = msgspec.field(default_factory=dict)  # per input key
    # stamp of the last message published per output key: a restarted instance of the service
    # does not publish again what its predecessor already did
    published_stamps: StampsPerKey = msgspec.field(default_factory=dict)


class StreamClock(Message, frozen=True):
    """The time of the stream being replayed (ROS's /clock): its header stamp, published by the
    player (the ingest service, `beyond replay`) as it plays. Services on the recording's clock
    (`BEYOND_CLOCK=recording`) stamp their health and progress with it, so every message of a
    replay is on one clock; while the player is paused the clock stands still."""


LEDGER_RANGES = 4096  # (segment, first, last) ranges per key and kind in a Ledger
Range = tuple[Id, Count, Count]


class InputPosition(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Where a service's next instance needs a sensor input from: the first `stamp` on `key` it
    needs again; with `gesture`, to derive that gesture again (not said yet), else from its
    newest snapshot."""

    key: Text
    stamp: Stamp
    gesture: Id | None = None


class Ledger(Message, frozen=True):
    """What one service has handled, by identity (schemas.identity), and where its next
    instance starts: how a restarted service neither stalls nor repeats (runtime.resilience.ledger).

    `handled`: input key -> kind -> (segment id, first, last) ranges of the frames handled (a
    per-gesture kind: (segment id, 0, 0)); the most recent ones, a bounded number. A producer
    that restarts does not send again what every consumer of its key has handled; a service
    whose handling is a side effect (speech) takes its predecessor's and does not act twice.
    `resume`, `resume_stamps`: the counts and stamps the service's next instance resumes from
    (the gesture streamer's checkpoint: a skeleton stamp from which its state can be rebuilt,
    and its counts there; the object segmenter's camera restart point). Stamps apart: they
    exceed 2^53, and the JSON form writes them as times.
    `positions`: per sensor key, the first stamp on it the next instance needs again (its
    snapshot's input position, `InputPosition`): a restarted source plays again from there
    (runtime.resilience.source_plan); with a gesture N, where a successor that goes back to
    gesture N (not said yet) needs it from.
    Every service publishes its own on `ledger/<service>` when it changes, keeps the last one
    of every other service of its robot, and answers for all of them on query, so a service's
    record outlives the service.
    Version 2: `instance`, which instance of the service this is (its predecessor's plus one):
    a producer withholds only what the consumer's instance alive now has handled, so a
    consumer replaced with it (a workstation taken over) gets what it needs to rebuild.
    Version 3: `positions` are typed (`InputPosition`), no longer "<key>@N" strings."""

    VERSION: ClassVar[int] = 3

    service: Name
    instance: Count = 0
    handled: Annotated[
        dict[
            Text,
            Annotated[
                dict[Name, Annotated[list[Range], msgspec.Meta(max_length=LEDGER_RANGES)]],
                msgspec.Meta(max_length=VARIABLES_MAX),
            ],
        ],
        msgspec.Meta(max_length=VARIABLES_MAX),
    ] = msgspec.field(default_factory=dict)
    resume: Annotated[dict[Name, Count], msgspec.Meta(max_length=VARIABLES_MAX)] = msgspec.field(
        default_factory=dict
    )
    resume_stamps: Annotated[dict[Name, Stamp], msgspec.Meta(max_length=VARIABLES_MAX)] = (
        msgspec.field(default_factory=dict)
    )
    positions: Annotated[list[InputPosition], msgspec.Meta(max_length=VARIABLES_MAX)] = (
        msgspec.field(default_factory=list)
    )


class AffordanceQuery(Message, frozen=True):
    """An ad-hoc question to the reasoner: P(query | evidence, soft evidence, gesture evidence).
    `soft`: variable -> {value: p}, a distribution over its values (values not named: 0);
    `gesture`: P_HMM(A | G) by action (fused). The reasoner checks them with the rules every
    command uses (`cognition.bn.evidence.build_evidence`)."""

    query: Annotated[list[Name], msgspec.Meta(max_length=VARIABLES_MAX)]
    evidence: Assignment = msgspec.field(default_factory=dict)
    soft: Annotated[dict[Name, Likelihoods], msgspec.Meta(max_length=VARIABLES_MAX)] = (
        msgspec.field(default_factory=dict)
    )
    gesture: Likelihoods = msgspec.field(default_factory=dict)


class AnswerRow(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    assignment: Assignment
    p: Annotated[float, msgspec.Meta(ge=0.0, le=1.0 + 1e-6)]  # rounding may pass 1 a little


class AffordanceAnswer(Message, frozen=True):
    """The reasoner's answer: the joint posterior of the queried variables, row by row."""

    variables: Annotated[list[Name], msgspec.Meta(max_length=VARIABLES_MAX)]
    rows: Annotated[list[AnswerRow], msgspec.Meta(max_length=ROWS_MAX)]


ALL_MESSAGES: tuple[type[Message], ...] = (
    SkeletonFrame,
    CameraFrame,
    CompressedCameraFrame,
    PersonPose,
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
    StreamClock,
    Ledger,
    AffordanceQuery,
    AffordanceAnswer,
)
