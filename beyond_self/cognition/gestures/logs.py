"""Reader for the YARP text logs of a tracked human hand (`human_data/<recording>/data.log`).

One frame per line: `<seq> <unix time> <x> <y> <z>`. Despite the nominal millimetres, the values
are already centred on the torso and normalised in amplitude by the recording pipeline
(gsaponaro/tcds-gestures `humanHandProcessor`: hand minus torso, x and z divided by 0.33 m, y by
0.23 m); multiplying by 0.001 therefore brings them into the feature space of the reference HMMs
and of every model this package trains (see `cognition.gestures.features`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from beyond_self.core.errors import InputError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class HandLog:
    """A hand trajectory as recorded: positions in the log's units (see the module docstring)."""

    path: Path
    seq: NDArray[np.int64]  # YARP envelope sequence numbers (-1 when the writer set none)
    time: FloatArray  # unix time of each frame, seconds
    xyz: FloatArray  # (T, 3) positions as written in the file

    def __len__(self) -> int:
        return int(self.xyz.shape[0])

    def frames(self, first: int | None = None, last: int | None = None) -> FloatArray:
        """Positions of frames `first`..`last`, 1-based and inclusive, as the article counts."""
        return self.xyz[frame_slice(first, last, len(self))]

    @property
    def fps(self) -> float:
        """Median frame rate; the logs are nominally 30 frames/s but YARP timestamps jitter."""
        if len(self.time) < 2:
            return 30.0
        dt = float(np.median(np.diff(self.time)))
        return 1.0 / dt if dt > 0 else 30.0


def frame_slice(first: int | None, last: int | None, n: int) -> slice:
    """Turn 1-based inclusive frame bounds into a Python slice, checking them against `n`."""
    a = 1 if first is None else first
    b = n if last is None else last
    if not 1 <= a <= b <= n:
        raise InputError(
            f"frames {a}:{b} are out of range; valid: 1-based A:B with 1 <= A <= B <= {n}"
        )
    return slice(a - 1, b)


def parse_frames(spec: str | None, n: int) -> slice:
    """Parse a `A:B` command-line frame range (1-based, inclusive; either side may be empty)."""
    if spec is None or spec.strip() in ("", ":"):
        return frame_slice(None, None, n)
    parts = spec.split(":")
    if len(parts) != 2:
        raise InputError(f"bad frame range {spec!r}; valid: A:B, A:, :B (1-based, inclusive)")
    try:
        a = int(parts[0]) if parts[0].strip() else None
        b = int(parts[1]) if parts[1].strip() else None
    except ValueError:
        raise InputError(
            f"bad frame range {spec!r}; valid: A:B with integers (1-based, inclusive)"
        ) from None
    return frame_slice(a, b, n)


def resolve_log_path(path: str | Path) -> Path:
    """A recording folder (holding data.log) or the data.log file itself."""
    p = Path(path)
    if p.is_dir():
        p = p / "data.log"
    if not p.is_file():
        raise InputError(f"hand log {p} does not exist; give a recording folder or its data.log")
    return p


def read_hand_log(path: str | Path, *, min_frames: int = 1) -> HandLog:
    """Read a YARP hand log; malformed lines, non-finite values and short logs are InputErrors."""
    p = resolve_log_path(path)
    seqs: list[int] = []
    times: list[float] = []
    rows: list[tuple[float, float, float]] = []
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(
            f"{p} is not a text file; expected lines '<seq> <time> <x> <y> <z>'"
        ) from None
    for lineno, line in enumerate(text.splitlines(), start=1):
        fields = line.split()
        if not fields:
            continue
        if len(fields) != 5:
            raise InputError(
                f"{p}:{lineno}: expected 5 fields '<seq> <time> <x> <y> <z>', got {len(fields)}"
            )
        try:
            seq = int(fields[0])
            values = [float(f) for f in fields[1:]]
        except ValueError:
            raise InputError(
                f"{p}:{lineno}: non-numeric field in {line.strip()!r}; "
                "expected '<seq> <time> <x> <y> <z>'"
            ) from None
        if not all(math.isfinite(v) for v in values):
            raise InputError(f"{p}:{lineno}: non-finite value (NaN or inf) in {line.strip()!r}")
        seqs.append(seq)
        times.append(values[0])
        rows.append((values[1], values[2], values[3]))
    if len(rows) < min_frames:
        raise InputError(f"{p} holds {len(rows)} frames; at least {min_frames} are needed")
    return HandLog(
        path=p,
        seq=np.asarray(seqs, dtype=np.int64),
        time=np.asarray(times, dtype=np.float64),
        xyz=np.asarray(rows, dtype=np.float64).reshape(-1, 3),
    )


MIN_LOG_FRAMES = 30  # one second: less cannot hold a gesture and the rest around it
# A tracked hand stays within an arm's reach of the torso: 1.5 m is 4.5 body units across and
# 6.5 up; the article's logs stay within 3.5. Beyond, a log is in other units or corrupt.
MAX_BODY_UNITS = 10.0


def check_positions(positions: FloatArray, what: str) -> FloatArray:
    """Hand positions in body units, or an InputError when some are not a hand's."""
    far = np.abs(positions).max(axis=1) if len(positions) else np.zeros(0)
    bad = np.flatnonzero(far > MAX_BODY_UNITS)
    if len(bad):
        raise InputError(
            f"{what}: frame {bad[0] + 1} is {far[bad[0]]:.3g} body units from the torso; "
            f"valid: within {MAX_BODY_UNITS:g} (hand logs are in thousandths of a body unit)"
        )
    return positions


def hand_log_stream(path: str | Path, scale: float = 0.001) -> tuple[NDArray[np.int64], FloatArray]:
    """A hand log as the pipeline plays it (`beyond up --log`, `beyond analyse`): each frame's
    stamp (ns, the log's own time) and the hand in body units (the logged values times
    `scale`), checked: at least `MIN_LOG_FRAMES` frames, finite, within `MAX_BODY_UNITS`, and
    time going forward."""
    log = read_hand_log(path, min_frames=MIN_LOG_FRAMES)
    if not (math.isfinite(scale) and scale > 0):
        raise InputError(f"log scale {scale!r} is invalid; valid: a positive finite number")
    stamps = np.rint(log.time * 1e9).astype(np.int64)
    back = np.flatnonzero(np.diff(stamps) <= 0)
    if len(back):
        raise InputError(
            f"{log.path}: frame {back[0] + 2} is not later than the frame before it; valid: "
            "times that increase from line to line"
        )
    return stamps, check_positions(log.xyz * scale, str(log.path))
