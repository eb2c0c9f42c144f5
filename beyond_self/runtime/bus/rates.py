"""Message rate and bandwidth of one stream over a sliding window (`beyond hz`, `bw`, `topics`).

Two rates, because they answer different questions: from the message stamps (the rate the source
produced at; exact on a replay, however loaded the machine) and from arrival times (what this
subscriber actually gets). Both are (n - 1) / span over the samples of the window, never count /
listening time: the latter reports 18 Hz for a 30 Hz stream heard for the last 60% of a window.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass


@dataclass(slots=True, frozen=True)
class RateStats:
    count: int  # samples in the window
    arrival_hz: float | None  # None: fewer than two samples
    stamp_hz: float | None  # None: fewer than two stamped samples or no stamp progress
    bytes_per_s: float | None
    mean_bytes: float
    min_bytes: int
    max_bytes: int
    min_interval_s: float | None  # between arrivals
    max_interval_s: float | None
    std_interval_s: float | None

    def as_dict(self) -> dict[str, float | int | None]:
        return {name: getattr(self, name) for name in self.__slots__}


class RateWindow:
    """The last `window` seconds of arrivals of one stream (None: everything seen)."""

    def __init__(self, window: float | None = 5.0) -> None:
        if window is not None and window <= 0:
            raise ValueError(f"window {window} must be positive")
        self._window_ns = None if window is None else int(window * 1e9)
        self._samples: deque[tuple[int, int, int]] = deque()  # arrival ns, stamp ns, bytes

    def add(self, arrival_ns: int, size: int, stamp_ns: int = 0) -> None:
        """One sample; stamp 0 means unstamped (not ours, or a clock not started yet)."""
        self._samples.append((arrival_ns, stamp_ns, size))
        self.trim(arrival_ns)

    def trim(self, now_ns: int) -> None:
        """Forget samples older than the window before `now_ns` (call when idle too, so a
        stream that stopped shows as stopped)."""
        if self._window_ns is None:
            return
        while self._samples and self._samples[0][0] < now_ns - self._window_ns:
            self._samples.popleft()

    def __len__(self) -> int:
        return len(self._samples)

    def stats(self) -> RateStats:
        samples = self._samples
        n = len(samples)
        sizes = [s[2] for s in samples]
        arrival_hz = bytes_per_s = None
        lo = hi = std = None
        if n >= 2:
            span = (samples[-1][0] - samples[0][0]) / 1e9
            if span > 0:
                arrival_hz = (n - 1) / span
                bytes_per_s = sum(sizes[1:]) / span
            gaps = [(b[0] - a[0]) / 1e9 for a, b in zip(samples, list(samples)[1:], strict=False)]
            lo, hi = min(gaps), max(gaps)
            mean = sum(gaps) / len(gaps)
            std = math.sqrt(sum((g - mean) ** 2 for g in gaps) / len(gaps))
        stamps = sorted(s[1] for s in samples if s[1])
        stamp_hz = None
        if len(stamps) >= 2 and stamps[-1] > stamps[0]:
            stamp_hz = (len(stamps) - 1) / ((stamps[-1] - stamps[0]) / 1e9)
        return RateStats(
            count=n,
            arrival_hz=arrival_hz,
            stamp_hz=stamp_hz,
            bytes_per_s=bytes_per_s,
            mean_bytes=sum(sizes) / n if n else 0.0,
            min_bytes=min(sizes, default=0),
            max_bytes=max(sizes, default=0),
            min_interval_s=lo,
            max_interval_s=hi,
            std_interval_s=std,
        )
