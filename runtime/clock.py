"""Time for services: wall time live, recording time on replay.

Why: a service that stamps its outputs with `time.time_ns()` makes every replay different. On
replay (`BEYOND_CLOCK=recording`) the clock instead follows the stamps of the inputs the service
has seen, so everything a service derives (and its health reports) is a function of the
recording alone. Derived messages should in any case copy the stamp of their input
(`Service.derive`), which needs no clock at all.
"""

from __future__ import annotations

import os
import time

from beyond_self.core.errors import InputError

CLOCK_MODES = ("wall", "recording")


class Clock:
    def __init__(self, mode: str = "wall") -> None:
        if mode not in CLOCK_MODES:
            raise InputError(f"unknown clock {mode!r}; valid: {', '.join(CLOCK_MODES)}")
        self.mode = mode
        self._latest = 0

    @classmethod
    def from_env(cls) -> Clock:
        """The clock named by $BEYOND_CLOCK (default wall)."""
        return cls(os.environ.get("BEYOND_CLOCK", "wall") or "wall")

    @property
    def is_recording(self) -> bool:
        return self.mode == "recording"

    def observe(self, stamp_ns: int) -> None:
        """Tell the clock the stamp of an input; recording time never goes backwards."""
        if stamp_ns > self._latest:
            self._latest = stamp_ns

    def now_ns(self) -> int:
        """Nanoseconds since the epoch: wall time, or the latest input stamp on replay."""
        return self._latest if self.mode == "recording" else time.time_ns()
