"""What a person steers a replay with: its speed, pause/resume/step, and key remapping (`beyond
replay --rate R --start-paused --remap FROM:TO`, `beyond up --rate R`, the ingest service's `rate`
option). Light to import, so argument parsing and services can check a rate without the bus;
`runtime/recording/replay.py` only asks it before each message how long it was held.

One rule for speed: code passes `rate: float | None`, a factor on the recording's timing (2 = twice
as fast), None = as fast as possible. A person types a number, where 0 means as fast as possible
(there is no "None" on a command line or in a YAML file); `rate_option` is the one place that turns
that 0 into None, so both replay paths refuse and accept the same values.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Iterable

from beyond_self.core.errors import InputError

RATE_MAX = 1e6  # times real time: already "as fast as possible" for any recording; more is a typo
VALID_RATES = f"a speed factor in (0, {RATE_MAX:g}] (2: twice as fast)"


def check_rate(rate: float | None) -> float | None:
    """`rate` if the replay engine can follow it: a positive finite factor, or None."""
    if rate is None:
        return None
    if not (isinstance(rate, int | float) and math.isfinite(rate) and 0 < rate <= RATE_MAX):
        raise InputError(
            f"replay rate {rate!r}; valid: {VALID_RATES}, or None for as fast as possible"
        )
    return float(rate)


def rate_option(rate: float, name: str = "rate") -> float | None:
    """A rate as a person gives it (`--rate`, a service's `rate` option: 0 = as fast as
    possible) as the engine takes it; `name` is the option named in the error."""
    if isinstance(rate, int | float) and rate == 0:
        return None
    try:
        return check_rate(rate)
    except InputError:
        raise InputError(
            f"{name} {rate!r}; valid: {VALID_RATES}, or 0 for as fast as possible"
        ) from None


class ReplayControl:
    """Pause state shared by the replay loop and whoever drives it (a terminal, a test)."""

    def __init__(self, *, paused: bool = False) -> None:
        self._paused = paused
        self._steps = 0
        self._closed = False
        self._changed = asyncio.Event()

    @property
    def paused(self) -> bool:
        return self._paused

    def toggle(self) -> None:
        self._paused = not self._paused and not self._closed
        self._changed.set()

    def step(self) -> None:
        """Let one message through while paused (no effect while playing)."""
        if self._paused:
            self._steps += 1
            self._changed.set()

    def close(self) -> None:
        """Play on for good (the replay is being stopped: nothing may stay parked here)."""
        self._closed = True
        self._paused = False
        self._changed.set()

    async def gate(self) -> float:
        """Wait while paused, until resumed or stepped; returns the seconds held."""
        if not self._paused:
            return 0.0
        loop = asyncio.get_running_loop()
        held_from = loop.time()
        while self._paused and self._steps == 0:
            self._changed.clear()
            await self._changed.wait()
        if self._paused:
            self._steps -= 1
        return loop.time() - held_from


def remapper(rules: Iterable[str]) -> Callable[[str], str] | None:
    """A function renaming keys by `FROM:TO` rules: a key equal to FROM, or under FROM/, is
    published as TO (plus the rest); the first matching rule wins. None without rules."""
    pairs: list[tuple[str, str]] = []
    for rule in rules:
        src, sep, dst = rule.partition(":")
        src, dst = src.strip("/"), dst.strip("/")
        if not sep or not src or not dst or "*" in src + dst:
            raise InputError(
                f"bad remap {rule!r}; use FROM:TO with two keys without wildcards, "
                "e.g. beyond/robot/sensors/skeleton:beyond/robot/sensors/skeleton2"
            )
        pairs.append((src, dst))
    if not pairs:
        return None

    def remap(key: str) -> str:
        for src, dst in pairs:
            if key == src or key.startswith(src + "/"):
                return dst + key[len(src) :]
        return key

    return remap
