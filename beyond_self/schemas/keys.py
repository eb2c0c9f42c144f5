"""Every key expression on the bus, defined here and nowhere else.

All keys live under `beyond/<robot>/` so several robots share one Zenoh network and a recording
can be replayed as another robot (swap the second chunk). `STREAMS` says which message type each
stream carries; the recorder, `beyond echo` and the typed subscribers read it from here.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from beyond_self.core.errors import InputError
from beyond_self.schemas import messages as m
from beyond_self.schemas.base import Message

PREFIX = "beyond"
DEFAULT_ROBOT = "robot"
_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")
_PATTERN = re.compile(r"^(?:\$\*|[A-Za-z0-9_])(?:\$\*|[A-Za-z0-9_.-])*$")

# stream name -> (key suffix after beyond/<robot>/, message type)
STREAMS: dict[str, tuple[str, type[Message]]] = {
    "skeleton": ("sensors/skeleton", m.SkeletonFrame),
    "camera": ("sensors/camera/raw", m.CameraFrame),
    "camera_compressed": ("sensors/camera/compressed", m.CompressedCameraFrame),
    # the images a skeleton was estimated from (a camera watching the person, cognition.pose):
    # for people to see, never the tabletop camera the object segmenter reads
    "person_camera": ("sensors/person/compressed", m.CompressedCameraFrame),
    # where the skeleton's joints are in those images (pixels), to draw the pose over them
    "person_pose": ("sensors/person/pose", m.PersonPose),
    "objects": ("vision/objects", m.DetectedObjects),
    "effects": ("vision/effects", m.ObjectEffects),
    "gesture_object": ("vision/gesture_object", m.GestureObject),
    "gesture_segment": ("gesture/segment", m.GestureSegment),
    "gesture_posterior": ("gesture/posterior", m.ActionPosterior),
    "affordance": ("affordance/prediction", m.AffordancePrediction),
    "words": ("language/words", m.WordProbabilities),
    "description": ("language/description", m.Description),
    "stream_end": ("sensors/end", m.StreamEnd),
    # the time of a replayed stream, published by the player (runtime.clock)
    "clock": ("clock", m.StreamClock),
}
ASK = "affordance/ask"  # queryable of the reasoner: AffordanceQuery in, AffordanceAnswer out
HEALTH = "health"  # beyond/<robot>/health/<service>: ServiceHealth (published and queryable)
ALIVE = "alive"  # beyond/<robot>/alive/<service>: liveliness tokens
PROGRESS = "progress"  # beyond/<robot>/progress/<service>: Progress (sensor inputs handled)
LEDGER = "ledger"  # beyond/<robot>/ledger/<service>: Ledger (identities handled; queryable)
# one key per service, beyond/<robot>/<chunk>/<service>: the type each carries
PER_SERVICE: dict[str, type[Message]] = {
    HEALTH: m.ServiceHealth,
    PROGRESS: m.Progress,
    LEDGER: m.Ledger,
}
# queries, beyond/<robot>/<suffix>: (the request's type, the reply's type)
QUERIES: dict[str, tuple[type[Message], type[Message]]] = {
    ASK: (m.AffordanceQuery, m.AffordanceAnswer),
}


def check_name(kind: str, name: str) -> str:
    """A robot or service name usable as one key chunk (no '/', '*', '$', '?', '#')."""
    if not _NAME.match(name):
        raise InputError(
            f"invalid {kind} name {name!r}; use letters, digits, '_', '-', '.' "
            "(not starting with '-' or '.')"
        )
    return name


def robot_pattern(text: str) -> str:
    """The robots `text` names, as one key-expression chunk: a robot's name, `*` (every robot),
    or a name with `*` standing for any characters (`lab-*`, written `lab-$*` in a key
    expression, which also passes). Anything else is an InputError saying what is valid."""
    chunk = text if text == "*" else re.sub(r"(?<!\$)\*", "$*", text)
    chunk = "*" if chunk == "$*" else chunk
    if chunk != "*" and (not _PATTERN.match(chunk) or "$*$*" in chunk):
        raise InputError(
            f"invalid robots pattern {text!r}; valid: a robot name, '*' (every robot), or a "
            "name with '*' for any characters (lab-*), letters, digits, '_', '-', '.'"
        )
    return chunk


def typed_pattern(pattern: str) -> str:
    """`pattern` (robot_pattern's) as a person types it: `lab-$*` is shown as `lab-*`."""
    return pattern.replace("$*", "*")


def for_robots(pattern: str, key: str) -> str:
    """`key` (of any one robot, e.g. `Keys().alive("ingest")`) for every robot `pattern`
    (robot_pattern's) names: its robot chunk replaced, the rest as `Keys` made it."""
    prefix, _robot, rest = key.split("/", 2)
    return f"{prefix}/{pattern}/{rest}"


def robot_matches(pattern: str, robot: str) -> bool:
    """Whether robot name `robot` is one of the robots `pattern` (robot_pattern's) names."""
    regex = ".*".join(re.escape(part) for part in pattern.split("$*"))
    return pattern == "*" or re.fullmatch(regex, robot) is not None


@dataclass(frozen=True)
class Keys:
    """The key expressions of one robot."""

    robot: str = DEFAULT_ROBOT

    def __post_init__(self) -> None:
        check_name("robot", self.robot)

    @property
    def root(self) -> str:
        return f"{PREFIX}/{self.robot}"

    @property
    def everything(self) -> str:
        return f"{self.root}/**"

    def stream(self, name: str) -> str:
        if name not in STREAMS:
            from beyond_self.core.errors import unknown

            raise unknown("stream", name, list(STREAMS))
        return f"{self.root}/{STREAMS[name][0]}"

    @property
    def skeleton(self) -> str:
        return self.stream("skeleton")

    @property
    def camera(self) -> str:
        return self.stream("camera")

    @property
    def camera_compressed(self) -> str:
        return self.stream("camera_compressed")

    @property
    def person_camera(self) -> str:
        return self.stream("person_camera")

    @property
    def person_pose(self) -> str:
        return self.stream("person_pose")

    @property
    def objects(self) -> str:
        return self.stream("objects")

    @property
    def effects(self) -> str:
        return self.stream("effects")

    @property
    def gesture_object(self) -> str:
        return self.stream("gesture_object")

    @property
    def gesture_segment(self) -> str:
        return self.stream("gesture_segment")

    @property
    def gesture_posterior(self) -> str:
        return self.stream("gesture_posterior")

    @property
    def affordance(self) -> str:
        return self.stream("affordance")

    @property
    def words(self) -> str:
        return self.stream("words")

    @property
    def description(self) -> str:
        return self.stream("description")

    @property
    def stream_end(self) -> str:
        return self.stream("stream_end")

    @property
    def clock(self) -> str:
        return self.stream("clock")

    @property
    def ask(self) -> str:
        return f"{self.root}/{ASK}"

    def health(self, service: str = "*") -> str:
        """Health key of one service, or of all with the default "*"."""
        return f"{self.root}/{HEALTH}/{_service_chunk(service)}"

    def progress(self, service: str = "*") -> str:
        """Progress key of one service, or of all with the default "*"."""
        return f"{self.root}/{PROGRESS}/{_service_chunk(service)}"

    def ledger(self, service: str = "*") -> str:
        """Ledger key of one service, or of all with the default "*"."""
        return f"{self.root}/{LEDGER}/{_service_chunk(service)}"

    def alive(self, service: str = "*") -> str:
        """Liveliness token key of one service, or of all with the default "*"."""
        return f"{self.root}/{ALIVE}/{_service_chunk(service)}"

    def server(self, service: str, host: str = "*") -> str:
        """Liveliness token of the fleet workstation `host` serving this robot's `service`
        (runtime.fleet), or of any with the default "*": who serves it, so that exactly one
        does. Under the service's own token (`alive/<service>/**` in the access rules)."""
        return f"{self.alive(service)}/{_service_chunk(host)}"


def _service_chunk(service: str) -> str:
    return service if service == "*" else check_name("service", service)


def robot_of(key: str) -> str:
    """The robot chunk of a concrete `beyond/<robot>/...` key (`split_key`'s first part, for
    keys known to be a robot's: a fleet's shared streams take it for every sample)."""
    return key.split("/", 2)[1]


def split_key(key: str) -> tuple[str, str] | None:
    """(robot, suffix) of a concrete `beyond/<robot>/<suffix>` key, else None."""
    parts = key.split("/", 2)
    if len(parts) < 3 or parts[0] != PREFIX:
        return None
    return parts[1], parts[2]


# streams whose stamps only move forward: a sensor frame stamped at or before the previous one
# is refused by every consumer (they pace on them). Other keys may repeat a stamp: a gesture's
# start and first belief share its frame's, health on a paused replay's clock stands still.
FORWARD_ONLY = frozenset(
    STREAMS[name][0]
    for name in ("skeleton", "camera", "camera_compressed", "person_camera", "person_pose")
)


# the tabletop camera the object segmenter reads; a person's camera (person_camera) never is
TABLETOP_CAMERA = frozenset(STREAMS[name][0] for name in ("camera", "camera_compressed"))


def forward_only(key: str) -> bool:
    """`key` carries a sensor stream whose stamps must increase (FORWARD_ONLY)."""
    split = split_key(key)
    return split is not None and split[1] in FORWARD_ONLY


def type_for_key(key: str) -> type[Message] | None:
    """The message type a concrete key carries, if it is one of ours."""
    split = split_key(key)
    if split is None:
        return None
    suffix = split[1]
    for stream_suffix, cls in STREAMS.values():
        if suffix == stream_suffix:
            return cls
    chunk, _, service = suffix.partition("/")
    if service and "/" not in service:
        return PER_SERVICE.get(chunk)
    return None


def with_robot(key: str, robot: str) -> str:
    """The same key for another robot (for replaying a recording as a different robot)."""
    split = split_key(key)
    if split is None:
        return key
    return f"{PREFIX}/{check_name('robot', robot)}/{split[1]}"
