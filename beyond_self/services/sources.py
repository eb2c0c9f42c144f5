"""What the sensor ingest plays: one source and how it is played (`Source`, the ingest's options),
and the cues of a recording or a hand log (runtime.recording.replay.Cue).

The options are one value, checked once, so the ingest itself is only the playing: a recording
or a YARP hand log on its own clock, or a live source (a plug-in, a video, a camera) on the wall's.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import msgspec

from beyond_self.cognition.gestures.logs import hand_log_stream
from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.damage import Losses
from beyond_self.runtime.recording.pacing import DEFAULT_WINDOW_S
from beyond_self.runtime.recording.reader import read_recording, require_mcap, scan_recording
from beyond_self.runtime.recording.replay import Cue, recorded_cues
from beyond_self.runtime.recording.replay_control import rate_option
from beyond_self.runtime.recording.robots import recorded_robot
from beyond_self.runtime.resilience.source_log import DEFAULT_MAX_MB
from beyond_self.schemas import Header, Joint, SkeletonFrame
from beyond_self.schemas.keys import Keys, split_key, with_robot

SENSORS = ("skeleton", "camera", "camera_compressed", "person_camera", "person_pose")


class Source(msgspec.Struct, kw_only=True, frozen=True):
    """The ingest's options: exactly one of `recording`, `log`, `plugin`, `video`, `camera`,
    and how it is played (docs/how-to/recordings.md)."""

    recording: str | None = None
    log: str | None = None
    plugin: str | None = None
    video: str | None = None
    camera: int | None = None
    rate: float = 1.0  # 0: as fast as possible (runtime.recording.replay_control)
    loop: bool = False
    scale: float = 0.001  # a hand log's units to metres
    hand_joint: str = "right_hand"
    queue: int = 256  # a live source's items waiting; beyond it the oldest is dropped
    start_delay_s: float = 0.0
    wait_for: list[str] = msgspec.field(default_factory=list)  # services to wait for
    wait_timeout_s: float = 60.0
    window_s: float = DEFAULT_WINDOW_S  # how far the player may run ahead of its consumers
    log_mb: float = DEFAULT_MAX_MB  # a live source's log (runtime.resilience.source_log)
    state: str | None = None  # the state folder (default: the robot's, runtime.resilience)

    def __post_init__(self) -> None:
        sources = (("recording", self.recording), ("log", self.log), ("plugin", self.plugin),
                   ("video", self.video))  # fmt: skip
        given = [n for n, v in sources if v] + (["camera"] if self.camera is not None else [])
        if len(given) != 1:
            raise InputError(
                f"sensor ingest needs exactly one source; got {', '.join(given) or 'none'}; "
                "valid: recording=FILE.mcap, log=DIR_OR_DATA_LOG, plugin=module:function, "
                "video=FILE, camera=INDEX"
            )
        rate_option(self.rate)
        if not self.window_s > 0 or self.window_s == float("inf"):
            raise InputError(f"window_s {self.window_s} must be a positive number of seconds")
        if not 0 <= self.log_mb < float("inf"):
            raise InputError(f"log_mb {self.log_mb}; valid: 0 (no source log) or more megabytes")

    @property
    def live(self) -> bool:
        """A sensor, not a file: on the wall clock, never held back."""
        return self.plugin is not None or self.video is not None or self.camera is not None

    @property
    def name(self) -> str:
        return str(
            self.recording or self.log or self.plugin or self.video or f"camera {self.camera}"
        )

    @property
    def log_bytes(self) -> int:
        return round(self.log_mb * 2**20)


Passes = Callable[[], Iterator[Cue]]


def recording_cues(path: Path, keys: Keys, losses: Losses) -> tuple[Passes, tuple[int, int] | None]:
    """Passes over our robot's sensor streams of the recording at `path` (a fleet's recording:
    the robot's part), the damage of the first tallied in `losses`; and its span."""
    require_mcap(path)
    info = scan_recording(path)  # its channels and span: each message is decoded as sent
    source = recorded_robot(info, keys.robot)
    ours = {keys.stream(s) for s in SENSORS}

    def rename(key: str) -> str | None:  # our robot's sensor streams; nothing else
        split = split_key(key)
        if split is None or split[0] != source:
            return None
        key = with_robot(key, keys.robot)
        return key if key in ours else None

    passes = 0

    def one_pass() -> Iterator[Cue]:
        nonlocal passes
        passes += 1  # every pass finds the same damage: the first one tallies it
        tally = losses if passes == 1 else Losses(str(path))
        return recorded_cues(read_recording(path, losses=tally), rename, tally)

    span = None if info.start is None or info.end is None else (info.start, info.end)
    return one_pass, span


def log_cues(
    path: Path, source: Source, key: str, name: str
) -> tuple[Passes, tuple[int, int] | None]:
    """The skeleton frames of a YARP hand log (one joint, `source.hand_joint`), numbered by
    the log, so a restarted ingest numbers the same; and its span."""
    stamps, positions = hand_log_stream(path, source.scale)

    def cues() -> Iterator[Cue]:
        for i, (xyz, stamp) in enumerate(zip(positions, stamps, strict=True)):
            joint = Joint(position=(float(xyz[0]), float(xyz[1]), float(xyz[2])))
            header = Header(version=SkeletonFrame.VERSION, source=name, seq=i, stamp=int(stamp),
                            correlation=f"{name}/{i}")  # fmt: skip
            frame = SkeletonFrame(header=header, frame=i + 1, joints={source.hand_joint: joint})
            yield Cue(int(stamp), key, int(stamp), frame)

    return cues, (int(stamps[0]), int(stamps[-1])) if len(stamps) else None
