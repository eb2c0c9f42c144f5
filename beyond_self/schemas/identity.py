"""What a derived message is about, whoever sent it: its identity.

A per-gesture output is identified by robot, segment id and kind ("start", "end", "cancel",
"final belief", "object", "effects", "outcome", "words", "description"); a per-frame one adds its
frame ("belief", "anticipation", "objects", a describer's drafts). Exactly-once is built on it
(runtime.resilience.ledger): a consumer acts on each identity once, whether it came from its maker,
a
restarted maker re-deriving it, or a cache after a cut link. It depends only on the key and the
message's contents, never on who sent it or when, so every service agrees on it. Sensor streams,
health and progress have none.
"""

from __future__ import annotations

from dataclasses import dataclass

from beyond_self.schemas.base import Message
from beyond_self.schemas.keys import split_key
from beyond_self.schemas.messages import (
    ActionPosterior,
    AffordancePrediction,
    Description,
    DetectedObjects,
    GestureObject,
    GestureSegment,
    ObjectEffects,
    WordProbabilities,
)

PER_GESTURE = 0  # the `frame` of an identity that is one per gesture
TYPES = (
    GestureSegment,
    ActionPosterior,
    AffordancePrediction,
    GestureObject,
    ObjectEffects,
    WordProbabilities,
    Description,
    DetectedObjects,
)  # the messages that have an identity

# kinds made once per gesture (the others are one per frame)
GESTURE_KINDS = frozenset(
    ("start", "end", "cancel", "final belief", "object", "effects", "outcome", "words",
     "description")
)  # fmt: skip


@dataclass(frozen=True, slots=True, order=True)
class Identity:
    robot: str
    segment_id: int
    kind: str
    frame: int = PER_GESTURE  # the frame (or stamp) a per-frame kind is about

    @property
    def per_gesture(self) -> bool:
        return self.kind in GESTURE_KINDS

    def __str__(self) -> str:
        at = "" if self.per_gesture else f" at {self.frame}"
        return f"{self.robot}: gesture {self.segment_id} {self.kind}{at}"


def identify(key: str, message: Message) -> Identity | None:
    """The identity of `message` received on (concrete) `key`; None for a message that is not
    a per-gesture or per-frame result (sensors, health, progress, queries)."""
    split = split_key(key)
    if split is None:
        return None
    robot = split[0]
    match message:
        case GestureSegment():
            return Identity(robot, message.segment_id, message.event)
        case ActionPosterior(final=True):
            return Identity(robot, message.segment_id, "final belief")
        case ActionPosterior():
            return Identity(robot, message.segment_id, "belief", message.frame)
        case AffordancePrediction(final=True):
            return Identity(robot, message.segment_id, "outcome")
        case AffordancePrediction():
            return Identity(robot, message.segment_id, "anticipation", message.frame)
        case GestureObject():
            return Identity(robot, message.segment_id, "object")
        case ObjectEffects():
            return Identity(robot, message.segment_id, "effects")
        case WordProbabilities(final=True):
            return Identity(robot, message.segment_id, "words")
        case WordProbabilities():
            return Identity(robot, message.segment_id, "draft words", message.header.stamp)
        case Description(final=True):
            return Identity(robot, message.segment_id, "description")
        case Description():
            return Identity(robot, message.segment_id, "draft description", message.header.stamp)
        case DetectedObjects():
            return Identity(robot, 0, "objects", message.frame)
    return None
