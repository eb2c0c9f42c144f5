"""Time for services: one clock per run, the wall clock live, the stream's clock on replay.

A service that stamps its outputs with `time.time_ns()` makes every replay different. On replay
(`BEYOND_CLOCK=recording`, which `beyond up` sets for a recording or a log) the clock is the
stream's, like ROS's `use_sim_time`: the player publishes the stream's time on
`beyond/<robot>/clock` (`ClockTicks`), and a service's clock follows it and its own inputs'
stamps, never backwards. It stamps only what is not derived from an input (health, progress, the
end marker, answers); derived messages copy their input's stamp. It reads 0 until the stream
starts. More: docs/concepts/event-time.md, "A service's clock".
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable

from beyond_self.core.errors import InputError

CLOCK_MODES = ("wall", "recording")
TICK_NS = 100_000_000  # stream time between two clock messages (10 per stream second)


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
        """Tell the clock a time of the stream (an input's stamp, the player's clock); recording
        time never goes backwards."""
        if stamp_ns > self._latest:
            self._latest = stamp_ns

    def now_ns(self) -> int:
        """Nanoseconds since the epoch: wall time, or on replay the latest stream time seen
        (0 before the stream has started)."""
        return self._latest if self.mode == "recording" else time.time_ns()


class ClockTicks:
    """A player's side of the stream clock: `at(stamp)` before each message it sends publishes
    the stream's time (`publish(stamp)`) once it has moved on by `tick_ns` since the last tick
    (and for the first message), `last(stamp)` once more at the end, so the services' clocks
    reach it. Ticks follow the stream, never the wall clock: the same recording gives the same
    ticks at any rate, and a paused player sends none."""

    def __init__(self, publish: Callable[[int], None], tick_ns: int = TICK_NS) -> None:
        self._publish = publish
        self.tick_ns = tick_ns
        self._last: int | None = None

    def at(self, stamp: int) -> None:
        if self._last is None or stamp >= self._last + self.tick_ns:
            self._last = stamp
            self._publish(stamp)

    def last(self, stamp: int) -> None:
        if self._last is None or stamp > self._last:
            self._last = stamp
            self._publish(stamp)
