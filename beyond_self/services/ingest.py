"""Sensor ingest: puts sensor streams on the bus, from a recording, a YARP hand log or a live source
(a plug-in, a video or a camera); docs/how-to/recordings.md describes each.

A recording or log is played on its own clock (`StreamClock`, runtime.clock) and paced on its
slowest consumer (runtime.recording.pacing), so no rate drops a frame; a live source is on the wall
clock and never held back: a bounded queue drops its oldest item, counted. `StreamEnd` says what was
published, so consumers know when they have seen everything. Crash-only: a restarted ingest plays
from the runtime's resume plan (`Service.resume_plan`: where its consumers are, and what their
successors need to rebuild), read from the recording again or from its source log
(runtime.resilience.source_log); see docs/concepts/recovery.md.
"""

from __future__ import annotations

import asyncio
import logging
from pathlib import Path
from typing import Any, ClassVar

import msgspec

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.delivery import CAMERA, EVENTS, SKELETON, STATUS
from beyond_self.runtime.bus.publisher import Publisher
from beyond_self.runtime.clock import Clock, ClockTicks
from beyond_self.runtime.error_account import bounded
from beyond_self.runtime.log import event
from beyond_self.runtime.recording.damage import Losses
from beyond_self.runtime.recording.pacing import Pacer
from beyond_self.runtime.recording.replay import Cue, Player, looped
from beyond_self.runtime.recording.replay_control import rate_option
from beyond_self.runtime.resilience.source_log import SourceLog
from beyond_self.runtime.resilience.state import state_dir
from beyond_self.runtime.service import BASE_OPTIONS, Service
from beyond_self.schemas import (
    CameraFrame,
    CompressedCameraFrame,
    PersonPose,
    ServiceHealth,
    SkeletonFrame,
    StreamClock,
    StreamEnd,
)
from beyond_self.services.live_source import play_live
from beyond_self.services.pose_source import PoseCounts
from beyond_self.services.sources import Passes, Source, log_cues, recording_cues


class SensorIngest(Service):
    name = "ingest"
    subscribes = ()
    publishes = ("skeleton", "camera", "camera_compressed", "person_camera", "person_pose",
                 "stream_end", "clock")  # fmt: skip
    serves = ()
    Options: ClassVar[type[Source]] = Source  # its options are one value (services.options)

    def __init__(self, source: Source | None = None, **options: Any) -> None:
        base = {k: options.pop(k) for k in BASE_OPTIONS if k in options}
        super().__init__(**base)
        self.source = source if source is not None else Source(**options)
        self.live = self.source.live
        if not self.live and "clock" not in base:  # a replay: on the stream's clock, always
            self.clock = Clock("recording")
        self.source_log: SourceLog | None = None
        self.last_stamps: dict[str, int] = {}
        self.losses = Losses(self.source.name)
        self.failure = ""
        self.pose_counts: PoseCounts | None = None  # a video or camera: what its pose model did
        self.published = 0
        self.dropped_items = 0
        self.finished = asyncio.Event()

    async def setup(self) -> None:
        keys = self.bus.keys
        # sensor frames are cached (they never leave the robot): a gesture streamer or an
        # object segmenter restarted mid-gesture gets back the frames it needs
        self.skeleton = self.publisher(keys.skeleton, SkeletonFrame, SKELETON)
        self.camera = self.publisher(keys.camera, CameraFrame, CAMERA)
        self.compressed = self.publisher(keys.camera_compressed, CompressedCameraFrame, CAMERA)
        self.person_camera = self.publisher(keys.person_camera, CompressedCameraFrame, CAMERA)
        self.person_pose = self.publisher(keys.person_pose, PersonPose, SKELETON)
        self.person_streams: dict[str, Publisher[Any]] = {
            "person_camera": self.person_camera,
            "skeleton": self.skeleton,
            "person_pose": self.person_pose,
        }
        self.streams: dict[str, tuple[str, Publisher[Any]]] = {
            keys.skeleton: ("skeleton", self.skeleton),
            keys.camera: ("camera", self.camera),
            keys.camera_compressed: ("camera_compressed", self.compressed),
            keys.person_camera: ("person_camera", self.person_camera),
            keys.person_pose: ("person_pose", self.person_pose),
        }
        self.end = self.publisher(keys.stream_end, StreamEnd, EVENTS)
        self.stream_clock = self.publisher(keys.clock, StreamClock, STATUS)
        state = self.source.state
        folder = Path(state) if state else state_dir(keys.robot, self.name)
        if self.live and self.source.log_bytes and folder:  # a recording is read again instead
            self.source_log = SourceLog(folder, self.source.log_bytes)
            self.source_log.record(self.person_streams.values(), self.camera)
        self.spawn(self._play(), "source")

    async def teardown(self) -> None:
        if self.source_log is not None:
            self.source_log.close()

    def health_report(self) -> ServiceHealth:
        """With a camera source, `skipped` counts the frames whose pose was shed to keep up."""
        report = super().health_report()
        if self.pose_counts is None:
            return report
        return msgspec.structs.replace(report, skipped=self.pose_counts.shed)

    def _tick(self, stamp: int) -> None:
        """The stream's time, for this service's own clock and everyone's (runtime.clock)."""
        self.clock.observe(stamp)
        self.stream_clock.put(StreamClock(header=self.header(StreamClock, stamp)))

    async def _play(self) -> None:
        # Publishing before the consumers' subscriptions reached this session would lose the
        # first frames: wait for their liveliness tokens (declared after their subscriptions).
        source, keys = self.source, self.bus.keys
        for name in source.wait_for:
            await self.bus.wait_alive(keys.alive(name), timeout=source.wait_timeout_s)
        sensors = [keys.skeleton, keys.camera, keys.camera_compressed]
        self.pacer = Pacer(self.bus, source.wait_for, sensors, window_s=source.window_s)
        await self.pacer.start()
        self.plan = self.resume_plan(self.pacer)  # where the consumers are, what they need
        if self.source_log is not None and self.plan.restarted:
            again = self.source_log.play_again(self.plan.play_from())
            event(self.log, logging.INFO, "played again from the source log", messages=again)
        ticks = None if self.live else ClockTicks(self._tick)  # live: the wall's
        self.player = Player(rate=rate_option(source.rate), pacer=self.pacer, ticks=ticks)
        if source.start_delay_s:
            await asyncio.sleep(source.start_delay_s)
        try:
            if source.recording:
                await self._play_cues(*recording_cues(Path(source.recording), keys, self.losses))
            elif source.log:
                await self._play_cues(*log_cues(Path(source.log), source, keys.skeleton, self.name))
            else:
                while True:  # a live source is not restamped: it has its own clock
                    await play_live(self)
                    if not source.loop:
                        break
        except InputError as exc:  # nothing playable (a file that is no recording...)
            self.report_error("source", exc)
            self.failure = str(exc)
        finally:
            self.pacer.stop()
        self._ended()

    def _ended(self) -> None:
        damage = self.failure or (self.losses.line() if self.losses.any else "")
        self.end.put(
            StreamEnd(
                header=self.header(StreamEnd),
                source=bounded(self.source.name, 256),
                messages=self.published,
                dropped=self.dropped_items,
                last_stamps=dict(self.last_stamps),
                damage=bounded(damage, 4000),
            )
        )
        self.finished.set()
        event(
            self.log,
            logging.WARNING if damage else logging.INFO,
            "source finished",
            messages=self.published,
            dropped=self.dropped_items,
            lost=self.losses.lost if damage else 0,  # the line itself is in StreamEnd.damage
            held_back_s=round(self.pacer.waited_s, 3),
        )
        if self.pose_counts is not None:  # per-frame work a live video shed is said, counted
            event(self.log, logging.INFO, "pose", **vars(self.pose_counts))

    def sent(self, stream: str, stamp: int) -> None:
        """A message of `stream` stamped `stamp` was published."""
        self.published += 1
        self.last_stamps[stream] = stamp

    async def _play_cues(self, passes: Passes, span: tuple[int, int] | None) -> None:
        """Play `passes` (looped, restamped, if `loop`) from the resume plan: a cue every
        consumer has handled already (a restarted source) is not sent again, only noted."""
        plan = self.plan

        def fresh(cue: Cue) -> bool:
            if plan.fresh(cue.key, cue.stamp):
                return True
            self.last_stamps[self.streams[cue.key][0]] = cue.stamp
            return False

        def send(cue: Cue) -> None:
            stream, pub = self.streams[cue.key]
            pub.put(cue.ours())
            self.sent(stream, cue.stamp)

        cues = looped(passes, loop=self.source.loop, span=span, resume_at=plan.start)
        await self.player.play(filter(fresh, cues), send)
