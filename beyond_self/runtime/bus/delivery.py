"""How messages on a key travel: one description for publishers and subscribers alike.

Like a ROS 2 QoS profile, both ends of a stream are opened with the same `Delivery`, and each
reads the fields that concern it: `congestion`, `cache` and `express` (publisher); `recover`,
`history`, `max_age_s` and `queue` (subscriber). A cached publisher drops rather than blocks:
across a dead link Zenoh's queue fills within seconds, and a blocking put would stall the robot's
own pipeline until the lease ends; what was dropped comes back from the cache. A plain publisher
blocks by default, since without a cache a dropped sample is gone. The presets name this
project's stream kinds; a new stream of the same kind uses them (docs/concepts/pipeline.md).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Literal

from beyond_self.core.errors import InputError

Congestion = Literal["block", "drop"]

FRAME_CACHE = 1024  # samples: ~30 s of a per-frame stream at 30 Hz
# Derived per-frame streams cross the robot–workstation link: their caches outlast an outage
# of two minutes at 30 Hz (a lost final belief is a gesture not described). A few hundred bytes
# a sample: about 1.2 MB per publisher, once full
DERIVED_CACHE = 4096
EVENT_CACHE = 64  # samples: per-gesture streams
CAMERA_CACHE = 300  # frames: 20 s at 15 fps, longer than a gesture and its lead


@dataclass(frozen=True)
class Delivery:
    congestion: Congestion = "block"
    cache: int = 0
    recover: bool = False
    history: int = FRAME_CACHE
    max_age_s: float | None = None
    queue: int = 1024
    express: bool = False

    def __post_init__(self) -> None:
        if self.congestion not in ("block", "drop"):
            raise InputError(f"congestion {self.congestion!r}; valid: 'block', 'drop'")
        if self.cache < 0:
            raise InputError(f"publisher cache of {self.cache} samples; valid: 0 (none) or more")
        if self.history < 1:
            raise InputError(f"history of {self.history} samples; valid: at least 1")
        if self.max_age_s is not None and not self.max_age_s > 0:
            raise InputError(f"history age {self.max_age_s} s; valid: > 0 or None")
        if self.queue < 1:
            raise InputError(f"queue of {self.queue} messages; valid: at least 1")

    def with_(self, **changes: Any) -> Delivery:
        return replace(self, **changes)


# Every message reaches a live subscriber; a full queue makes the publisher wait. Commands,
# tools, replays of recordings, raw sensor streams of a live pipeline (paced by its consumers).
RELIABLE = Delivery()
# Reports that the next one repairs (health, progress): never wait for a slow or dead link.
STATUS = Delivery(congestion="drop")
# Derived per-frame streams (posteriors, objects, predictions): recovered after a cut link.
FRAMES = Delivery(congestion="drop", cache=DERIVED_CACHE, recover=True)
# Per-gesture streams (segment events, effects, words, descriptions): recovered after a cut link.
EVENTS = Delivery(congestion="drop", cache=EVENT_CACHE, recover=True)
# Camera frames (never leaving the robot): an object segmenter restarted mid-gesture gets back the
# frames of the gesture it was analysing.
CAMERA = Delivery(congestion="drop", cache=CAMERA_CACHE, recover=True)
# Skeleton frames (never leaving the robot): a gesture streamer restarted mid-gesture gets back
# the frames since its predecessor's checkpoint (about 34 s at 30 Hz).
SKELETON = Delivery(congestion="drop", cache=FRAME_CACHE, recover=True)
