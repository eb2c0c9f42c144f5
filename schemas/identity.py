"""What a derived message is about, whoever sent it: its identity.

Every per-gesture output is identified by robot, segment id and kind: "start", "end" or
"cancel" (GestureSegment), "final belief" (the final ActionPosterior), "object"
(GestureObject), "effects" (ObjectEffects), "outcome" (the final AffordancePrediction), "words"
(WordProbabilities), "description" (Description). Per-frame outputs add the frame they are
about: "belief" (an ActionPosterior while the gesture unfolds), "anticipation" (an
AffordancePrediction before its end), "objects" (DetectedObjects, segment 0: a camera frame is
about no gesture), and the drafts a describer with `unfolding` makes ("draft words",
"draft description", numbered by stamp).

The identity is what exactly-once is built on (runtime.ledger): a consumer acts on each identity
once, whether it came from the service that made it, from a restarted instance of that service
re-deriving it from its inputs, or from a publisher's cache after a cut link. It depends only on
the key (the robot is its second chunk) and on what the message says, never on who sent it or
when, so two services, or two robots' pipelines, agree on it. Sensor streams, health and
progress have none: they are not per-gesture results.
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
