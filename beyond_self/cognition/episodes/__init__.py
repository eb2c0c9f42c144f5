"""Per-gesture logic of the pipeline, as plain classes that take time as an argument.

Each class is what one service runs, with no bus in it: `GestureTracker` (gesture streamer),
`ObjectWatch` (object segmenter), `FusionJoin` (affordance reasoner), `GestureReport` (the lines
`beyond up` prints). Their outputs depend only on their inputs' stamps and contents, never on
arrival order across streams or on a wall clock: joins are by stamp and segment id, and
completeness comes from messages (a later frame, an explicit "not measured", the end of the
stream) or from a deadline in stream time. `analyse_recording` runs them offline over a
recording, which is the specification a run on the bus must equal.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from beyond_self.cognition.episodes.join import Anticipation, FusionJoin, Lost, Outcome
    from beyond_self.cognition.episodes.objects import (
        FrameObjects,
        GestureEffects,
        ObjectAtStart,
        ObjectWatch,
        WatchSnapshot,
    )
    from beyond_self.cognition.episodes.report import GestureReport
    from beyond_self.cognition.episodes.tracker import (
        Belief,
        Cancelled,
        Ended,
        GestureTracker,
        Started,
        TrackerSnapshot,
    )

# name -> the module holding it, imported on first use: the object watch pulls in SciPy's
# image and clustering modules (about a CPU-second per process), which the gesture streamer
# and the reasoner never use
_HOMES = {
    **dict.fromkeys(("Anticipation", "FusionJoin", "Lost", "Outcome"), "join"),
    **dict.fromkeys(
        ("FrameObjects", "GestureEffects", "ObjectAtStart", "ObjectWatch", "WatchSnapshot"),
        "objects",
    ),
    "GestureReport": "report",
    **dict.fromkeys(
        ("Belief", "Cancelled", "Ended", "GestureTracker", "Started", "TrackerSnapshot"), "tracker"
    ),
}


def __getattr__(name: str) -> Any:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{home}"), name)


__all__ = [
    "Anticipation",
    "Belief",
    "Cancelled",
    "Ended",
    "FrameObjects",
    "FusionJoin",
    "GestureEffects",
    "GestureReport",
    "GestureTracker",
    "Lost",
    "ObjectAtStart",
    "ObjectWatch",
    "Outcome",
    "Started",
    "TrackerSnapshot",
    "WatchSnapshot",
]
