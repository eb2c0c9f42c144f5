"""A fleet's recording: whose sensor streams play as which robot.

`beyond record` of a fleet holds every robot's keys; replaying it, each robot's source plays its
own part (Copper's distributed replay: each node replays its own log), and `beyond analyse
--robot` reads the same part, so a robot's outputs from the fleet's recording equal those of its
own. Kept apart from runtime.fleet so an offline command needs no bus.
"""

from __future__ import annotations

from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.reader import RecordingInfo
from beyond_self.schemas.keys import forward_only, split_key


def recorded_robots(info: RecordingInfo) -> list[str]:
    """The robots whose sensor streams a recording holds."""
    sensors = [split_key(c.topic) for c in info.channels if forward_only(c.topic)]
    return sorted({split[0] for split in sensors if split is not None})


def recorded_robot(info: RecordingInfo, robot: str | None) -> str | None:
    """Whose sensor streams of a recording play as robot `robot` (None: no sensor streams). A
    recording of one robot is played as any robot, as always; a fleet's recording (several
    robots) gives each robot its own streams, so every robot's source replays its part of it
    (Copper's distributed replay) and `beyond analyse --robot` reads the same part."""
    robots = recorded_robots(info)
    if len(robots) <= 1:
        return robots[0] if robots else None
    if robot in robots:
        return robot
    what = f"robot {robot!r} is not one of them" if robot else "choose one with --robot"
    raise InputError(f"{info.path} is a fleet's recording (robots {', '.join(robots)}); {what}")
