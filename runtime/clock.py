"""Time for services: one clock per run, the wall clock live, the stream's clock on replay.

Why: a service that stamps its outputs with `time.time_ns()` makes every replay different, and a
recording of a replay that mixes the wall clock (health, progress) with the recording's (the
data) steps back years on some channels. On replay (`BEYOND_CLOCK=recording`, as `beyond up`
sets it when it replays a recording or a log) every message is on the stream's clock, like ROS's
`use_sim_time`: the player (the ingest service, `beyond replay`) publishes the stream's time on
`beyond/<robot>/clock` (`StreamClock`) as it plays, `ClockTicks` below, and a service's clock
follows it and the stamps of its own inputs, never backwards. Derived messages copy the stamp of
their input (`Service.derive`), which needs no clock at all; the clock stamps what is not derived
from an input: health, progress, the source's end marker, answers to queries.

Before the stream starts the recording clock reads 0, as ROS's does before /clock: health is
still published (it is how a service shows it is alive), stamped 0, and a recorder logs such a
message at the stream's first instant (runtime.recording_writer). While a replay is paused the
clock stands still and health repeats its stamp.
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
