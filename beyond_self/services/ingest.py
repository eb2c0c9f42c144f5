"""Sensor ingest: puts sensor streams on the bus, from a recording, a YARP hand log or a live source
(a plug-in, a video or a camera); docs/how-to/recordings.md describes each.

A recording or log is played on its own clock (`StreamClock`, runtime.clock) and paced on its
slowest consumer (runtime.recording.pacing), so no rate drops a frame; a live source is on the wall
clock and never held back: a bounded queue drops its oldest item, counted. `StreamEnd` says what was
published, so consumers know when they have seen everything. Crash-only: a restarted ingest goes on
from where its consumers are, after playing again what their successors need to rebuild (read from
the recording again, or from runtime.resilience.source_log); see docs/concepts/recovery.md.
"""

from __future__ import annotations

import asyncio
import functools
import logging
from collections.abc import AsyncIterator, Callable, Iterator
from pathlib import Path
from typing import Any

import msgspec

from beyond_self.cognition.gestures.logs import hand_log_stream
from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.delivery import CAMERA, EVENTS, SKELETON, STATUS
from beyond_self.runtime.bus.publisher import Publisher
from beyond_self.runtime.clock import Clock, ClockTicks
from beyond_self.runtime.error_account import bounded
from beyond_self.runtime.log import event
from beyond_self.runtime.recording.damage import Losses
from beyond_self.runtime.recording.images import message_from_image
from beyond_self.runtime.recording.pacing import DEFAULT_WINDOW_S, Pacer
from beyond_self.runtime.recording.person import PersonFrame, person_messages
from beyond_self.runtime.recording.reader import read_recording, require_mcap, scan_recording
from beyond_self.runtime.recording.replay import Cue, Player, looped, recorded_cues
from beyond_self.runtime.recording.replay_control import rate_option
from beyond_self.runtime.recording.robots import recorded_robot
from beyond_self.runtime.resilience.source_log import DEFAULT_MAX_MB, SourceLog
from beyond_self.runtime.resilience.state import state_dir
from beyond_self.runtime.service import Service
from beyond_self.schemas import (
    CameraFrame,
    CompressedCameraFrame,
    Header,
    Joint,
    PersonPose,
    ServiceHealth,
    SkeletonFrame,
    StreamClock,
    StreamEnd,
)
from beyond_self.schemas.keys import split_key, with_robot
from beyond_self.services.plugins import joints_of, load_plugin
from beyond_self.services.pose_source import PoseCounts


class SensorIngest(Service):
    name = "ingest"
    subscribes = ()
    publishes = (
        "skeleton",
        "camera",
        "camera_compressed",
        "person_camera",
        "person_pose",
        "stream_end",
        "clock",
    )
    serves = ()

    def __init__(
        self,
        *,
        recording: str | None = None,
        log: str | None = None,
        plugin: str | None = None,
        video: str | None = None,
        camera: int | None = None,
        rate: float = 1.0,
        loop: bool = False,
        scale: float = 0.001,
        hand_joint: str = "right_hand",
        queue: int = 256,
        start_delay_s: float = 0.0,
        wait_for: list[str] | None = None,
        wait_timeout_s: float = 60.0,
        window_s: float = DEFAULT_WINDOW_S,
        log_mb: float = DEFAULT_MAX_MB,
        state: str | None = None,
        **base: Any,
    ) -> None:
        super().__init__(**base)
        sources = (("recording", recording), ("log", log), ("plugin", plugin), ("video", video))
        given = [n for n, v in sources if v] + (["camera"] if camera is not None else [])
        if len(given) != 1:
            raise InputError(
                f"sensor ingest needs exactly one source; got {', '.join(given) or 'none'}; "
                "valid: recording=FILE.mcap, log=DIR_OR_DATA_LOG, plugin=module:function, "
                "video=FILE, camera=INDEX"
            )
        self.recording, self.log_path, self.plugin = recording, log, plugin
        self.video, self.camera_index = video, camera
        self.live = plugin is not None or video is not None or camera is not None
        self.source_name = str(recording or log or plugin or video or f"camera {camera}")
        if not self.live and "clock" not in base:  # a replay: on the stream's clock, always
            self.clock = Clock("recording")
        self.rate = rate_option(rate)  # None: as fast as possible
        self.loop = loop
        self.scale = scale
        self.hand_joint = hand_joint
        self.queue_size = queue
        self.start_delay_s = start_delay_s
        self.wait_for = list(wait_for or [])
        self.wait_timeout_s = wait_timeout_s
        if not window_s > 0 or window_s == float("inf"):
            raise InputError(f"window_s {window_s} must be a positive number of seconds")
        self.window_s = window_s
        if not 0 <= log_mb < float("inf"):
            raise InputError(f"log_mb {log_mb}; valid: 0 (no source log) or more megabytes")
        self.log_bytes = round(log_mb * 2**20)
        self.state = state
        self.source_log: SourceLog | None = None
        self.last_stamps: dict[str, int] = {}
        self.losses = Losses(self.source_name)
        self.resume: dict[str, int] = {}
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
        self.end = self.publisher(keys.stream_end, StreamEnd, EVENTS)
        self.stream_clock = self.publisher(keys.clock, StreamClock, STATUS)
        folder = Path(self.state) if self.state else state_dir(keys.robot, self.name)
        if self.live and self.log_bytes and folder:  # a recording is read again instead
            self.source_log = SourceLog(folder, self.log_bytes)
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
        for name in self.wait_for:
            await self.bus.wait_alive(self.bus.keys.alive(name), timeout=self.wait_timeout_s)
        keys = self.bus.keys
        self.pacer = Pacer(
            self.bus,
            self.wait_for,
            [keys.skeleton, keys.camera, keys.camera_compressed],
            window_s=self.window_s,
        )
        await self.pacer.start()
        # where the consumers are: a restarted source goes on from there, not from the start,
        # but plays again what a consumer's successor needs to rebuild its state (its snapshot's
        # input position), which a consumer restarted with this source finds nowhere else
        self.resume = self.pacer.handled_by_all()
        for key, stamp in self.ledgers.book.needed(self.resume).items():
            self.resume[key] = min(self.resume[key], stamp - 1)
        if self.ledgers.instance > 0 and all(s < 0 for s in self.resume.values()):
            # every consumer starts afresh too (the deployment was killed whole): they go back
            # to the oldest gesture not said yet, and need its frames again
            self.resume.update(
                {k: s - 1 for k, s in self.ledgers.book.needed(self.resume, self._unsaid()).items()}
            )
        if self.source_log is not None and self.ledgers.instance > 0:
            again = self.source_log.play_again({k: s + 1 for k, s in self.resume.items()})
            event(self.log, logging.INFO, "played again from the source log", messages=again)
        ticks = None if self.live else ClockTicks(self._tick)  # live: the wall's
        self.player = Player(rate=self.rate, pacer=self.pacer, ticks=ticks)
        if self.start_delay_s:
            await asyncio.sleep(self.start_delay_s)
        try:
            if self.recording:
                await self._play_recording(Path(self.recording))
            elif self.log_path:
                await self._play_log(Path(self.log_path))
            else:
                while True:  # a live source is not restamped: it has its own clock
                    await self._play_live()
                    if not self.loop:
                        break
        except InputError as exc:  # nothing playable (a file that is no recording...)
            self.report_error("source", exc)
            self.failure = str(exc)
        finally:
            self.pacer.stop()
        damage = self.failure or (self.losses.line() if self.losses.any else "")
        end = StreamEnd(
            header=self.header(StreamEnd),
            source=bounded(self.source_name, 256),
            messages=self.published,
            dropped=self.dropped_items,
            last_stamps=dict(self.last_stamps),
            damage=bounded(damage, 4000),
        )
        self.end.put(end)
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

    def _unsaid(self) -> int | None:
        """The oldest gesture a consumer saw start and not every consumer has heard said."""
        keys = self.bus.keys
        started = self.ledgers.seen_downstream(keys.gesture_segment, ("start",))
        return min(self.ledgers.unsaid(keys.description, started), default=None)

    def _sent(self, stream: str, stamp: int) -> None:
        self.published += 1
        self.last_stamps[stream] = stamp

    async def _play_cues(
        self,
        passes: Callable[[], Iterator[Cue]],
        span: tuple[int, int] | None,
        send: Callable[[Cue], None],
        stream_of: dict[str, str],
    ) -> None:
        """Play `passes` (looped, restamped, if `loop`), from where the consumers are: a cue
        they have all handled already (a restarted source) is not sent again, only noted."""
        resume = self.resume
        start = min(resume.values(), default=None)

        def fresh(cue: Cue) -> bool:
            if cue.stamp > resume.get(cue.key, -1):
                return True
            self.last_stamps[stream_of[cue.key]] = cue.stamp
            return False

        cues = looped(passes, loop=self.loop, span=span, resume_at=start)
        await self.player.play(filter(fresh, cues), send)

    async def _play_recording(self, path: Path) -> None:
        keys = self.bus.keys
        streams: dict[str, tuple[str, Publisher[Any]]] = {
            keys.skeleton: ("skeleton", self.skeleton),
            keys.camera: ("camera", self.camera),
            keys.camera_compressed: ("camera_compressed", self.compressed),
            keys.person_camera: ("person_camera", self.person_camera),
            keys.person_pose: ("person_pose", self.person_pose),
        }

        require_mcap(path)
        info = scan_recording(path)  # its channels and span: each message is decoded as sent
        source = recorded_robot(info, keys.robot)  # a fleet's recording: our robot's part

        def rename(key: str) -> str | None:  # our robot's sensor streams; nothing else
            split = split_key(key)
            if split is None or split[0] != source:
                return None
            key = with_robot(key, keys.robot)
            return key if key in streams else None

        def send(cue: Cue) -> None:
            stream, pub = streams[cue.key]
            pub.put(cue.ours())
            self._sent(stream, cue.stamp)

        passes = 0

        def one_pass() -> Iterator[Cue]:
            nonlocal passes
            passes += 1  # every pass finds the same damage: the first one tallies it
            tally = self.losses if passes == 1 else Losses(str(path))
            return recorded_cues(read_recording(path, losses=tally), rename, tally)

        span = None if info.start is None or info.end is None else (info.start, info.end)
        await self._play_cues(one_pass, span, send, {k: v[0] for k, v in streams.items()})

    async def _play_log(self, path: Path) -> None:
        stamps, positions = hand_log_stream(path, self.scale)
        key = self.bus.keys.skeleton

        def cues() -> Iterator[Cue]:
            for i, (xyz, stamp) in enumerate(zip(positions, stamps, strict=True)):
                joint = Joint(position=(float(xyz[0]), float(xyz[1]), float(xyz[2])))
                header = Header(  # numbered by the log, so a restarted ingest numbers the same
                    version=SkeletonFrame.VERSION,
                    source=self.name,
                    seq=i,
                    stamp=int(stamp),
                    correlation=f"{self.name}/{i}",
                )
                frame = SkeletonFrame(header=header, frame=i + 1, joints={self.hand_joint: joint})
                yield Cue(int(stamp), key, int(stamp), frame)

        def send(cue: Cue) -> None:
            frame = cue.ours()
            assert isinstance(frame, SkeletonFrame)  # the only kind cues() makes
            self.skeleton.put(frame)
            self._sent("skeleton", cue.stamp)

        span = (int(stamps[0]), int(stamps[-1])) if len(stamps) else None
        await self._play_cues(cues, span, send, {key: "skeleton"})

    async def _play_live(self) -> None:
        source: AsyncIterator[tuple[str, Any]]
        if self.plugin is not None:
            source = load_plugin(self.plugin)()
        else:
            from beyond_self.services.pose_source import PoseSource

            pose = PoseSource(video=self.video, camera=self.camera_index)
            self.pose_counts = pose.counts
            source = aiter(pose)
        queue: asyncio.Queue[tuple[Any, ...]] = asyncio.Queue(self.queue_size)
        done = object()

        async def pump() -> None:
            async for item in source:
                if queue.full():  # backpressure: drop the oldest, count it
                    queue.get_nowait()
                    self.dropped_items += 1
                queue.put_nowait(item)
            await queue.put(("", done))

        task = asyncio.get_running_loop().create_task(pump())
        frame = 0
        try:
            while True:
                kind, payload, *own = await queue.get()
                if payload is done:
                    break
                frame += 1
                if kind == "skeleton":
                    header = self.header(SkeletonFrame, *own)
                    joints = joints_of(payload)
                    self.skeleton.put(SkeletonFrame(header=header, frame=frame, joints=joints))
                    self._sent("skeleton", header.stamp)
                elif kind == "camera":
                    header = self.header(CameraFrame, *own)
                    self.camera.put(message_from_image(header, payload))  # type: ignore[arg-type]
                    self._sent("camera", header.stamp)
                elif kind == "person" and isinstance(payload, PersonFrame):
                    # one stamp: image, skeleton, pose in the image (the sensor's own if given)
                    stamp = int(own[0]) if own else self.clock.now_ns()
                    stamped = functools.partial(self.header, stamp=stamp)
                    for stream, msg in person_messages(stamped, payload):
                        self.person_streams[stream].put(msg)
                        self._sent(stream, stamp)
                else:
                    raise InputError(f"plug-in item kind {kind!r}; valid: skeleton, camera, person")
        finally:
            task.cancel()
