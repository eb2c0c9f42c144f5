"""What a stateful piece of cognition is rebuilt from after a crash (`Restorable`).

The gesture tracker and the object watch each say, as one of these, the first input stamp a fresh
copy of them needs again to go on exactly as they would, and how many gestures had started by
then. They know nothing of a bus: a service's base (runtime.resilience.snapshots) asks for one
after every message, stores it and restores it, and a notebook may do the same by hand.
"""

from __future__ import annotations

import msgspec


class Restorable(msgspec.Struct, frozen=True):
    """`stamp`: the first input stamp needed again (the input position); `gestures`: the
    gestures started before it. Subclasses add what else a successor needs (integers only, so
    that a ledger can carry it to a successor on another host)."""

    stamp: int
    gestures: int
