"""Object identity across frames: nearest centroid with gating, and velocities from tracks.

Why this simple tracker is enough: on a tabletop there are few objects, far apart compared with
how far one moves between frames at 30 fps (a rolling ball at 0.6 m/s moves 6 px per frame at
320 px/m). Each track predicts its next position at constant velocity; detections are matched to
predictions by the Hungarian method on centroid distance, pairs farther apart than the gate are
not matched (a new track starts), and a track not seen for `max_missed` frames ends.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast

import numpy as np

# scipy is imported in the functions that use it: a process that only needs this module's types
# (`beyond up` checking the object segmenter's options) then does not load it (1.3 s of CPU)
from beyond_self.core.errors import InputError


@dataclass
class Track:
    """One object's history: frame indices and centroids (pixels) where it was detected."""

    id: int
    frames: list[int] = field(default_factory=list)
    positions: list[tuple[float, float]] = field(default_factory=list)
    areas: list[int] = field(default_factory=list)
    missed: int = 0

    def predict(self, frame: int) -> np.ndarray:
        p = np.asarray(self.positions[-1], dtype=np.float64)
        if len(self.positions) >= 2 and self.frames[-1] > self.frames[-2]:
            v = (p - np.asarray(self.positions[-2])) / (self.frames[-1] - self.frames[-2])
            return cast(np.ndarray, p + v * (frame - self.frames[-1]))
        return p

    def as_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(self.frames, dtype=np.int64), np.asarray(self.positions, dtype=float)


class Tracker:
    """Nearest-centroid multi-object tracker with a distance gate (pixels)."""

    def __init__(self, gate_px: float = 25.0, max_missed: int = 5) -> None:
        if gate_px <= 0 or max_missed < 0:
            raise InputError("tracker gate must be > 0 px and max_missed ≥ 0 frames")
        self.gate_px = gate_px
        self.max_missed = max_missed
        self.tracks: list[Track] = []
        self._next = 0

    @property
    def active(self) -> list[Track]:
        return [t for t in self.tracks if t.missed <= self.max_missed]

    def update(
        self, frame: int, centroids: list[tuple[float, float]], areas: list[int] | None = None
    ) -> list[int]:
        """Match this frame's detections to tracks; returns the track id of each detection."""
        from scipy.optimize import linear_sum_assignment

        sizes = areas if areas is not None else [0] * len(centroids)
        live = self.active
        ids = [-1] * len(centroids)
        if live and centroids:
            pred = np.array([t.predict(frame) for t in live])
            det = np.asarray(centroids, dtype=np.float64)
            cost = np.linalg.norm(pred[:, None, :] - det[None, :, :], axis=2)
            big = self.gate_px * 1e3
            rows, cols = linear_sum_assignment(np.where(cost > self.gate_px, big, cost))
            for r, c in zip(rows, cols, strict=True):
                if cost[r, c] <= self.gate_px:
                    ids[c] = live[r].id
                    self._append(live[r], frame, centroids[c], sizes[c])
        seen = set(ids)
        for t in live:
            if t.id not in seen:
                t.missed += 1
        for i, c in enumerate(centroids):
            if ids[i] < 0:
                t = Track(self._next)
                self._next += 1
                self._append(t, frame, c, sizes[i])
                self.tracks.append(t)
                ids[i] = t.id
        return ids

    @staticmethod
    def _append(track: Track, frame: int, c: tuple[float, float], area: int) -> None:
        track.frames.append(frame)
        track.positions.append((float(c[0]), float(c[1])))
        track.areas.append(int(area))
        track.missed = 0

    def track(self, track_id: int) -> Track:
        for t in self.tracks:
            if t.id == track_id:
                return t
        raise InputError(f"no track {track_id}")


def velocities(frames: np.ndarray, positions: np.ndarray, fps: float) -> np.ndarray:
    """Per-sample velocity (units/s) of a possibly gappy track: positions are first lightly
    smoothed ([1 2 1]/4 over evenly spaced neighbours), then differentiated centrally over real
    time."""
    f = np.asarray(frames, dtype=np.float64)
    p = np.asarray(positions, dtype=np.float64)
    n = len(p)
    if n < 2:
        return np.zeros_like(p)
    s = p.copy()
    if n >= 3:
        # smooth only where the neighbours are evenly spaced in time (keeps uniform motion exact)
        even = (f[1:-1] - f[:-2]) == (f[2:] - f[1:-1])
        s[1:-1][even] = ((p[:-2] + 2 * p[1:-1] + p[2:]) / 4.0)[even]
    t = f / fps
    v = np.empty_like(s)
    v[1:-1] = (s[2:] - s[:-2]) / (t[2:] - t[:-2])[:, None]
    v[0] = (s[1] - s[0]) / (t[1] - t[0])
    v[-1] = (s[-1] - s[-2]) / (t[-1] - t[-2])
    return v


def peak_speed(
    frames: np.ndarray,
    positions: np.ndarray,
    fps: float,
    window: tuple[int, int] | None = None,
) -> float:
    """Highest speed along a track (units/s), optionally only at frames in [start, end)."""
    v = velocities(frames, positions, fps)
    speed = np.linalg.norm(v, axis=1)
    if window is not None:
        f = np.asarray(frames)
        speed = speed[(f >= window[0]) & (f < window[1])]
    return float(speed.max()) if speed.size else 0.0
