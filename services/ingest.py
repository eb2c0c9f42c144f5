"""Sensor ingest: puts sensor streams on the bus, from a recording, a YARP hand log or a live
source plug-in.

- recording (MCAP): every skeleton and camera message is published as recorded (same headers and
  stamps, so a replay is byte-identical), with the original timing scaled by `rate`
  (0 = as fast as possible).
- YARP hand log (the article's `data.log`): converted on the fly into skeleton frames holding one
  joint, the hand, in metres (`scale`), stamped with the log's own times.
- plug-in (`module:function`): the function returns an async iterator of `("skeleton", {joint:
  (x, y, z)})` or `("camera", rgb_uint8_array)` items; ingest stamps them with the clock and
  numbers them. A bounded queue sits between the plug-in and the bus: when the bus cannot keep up
  the oldest item is dropped and counted, never silently.
When the source is exhausted a `StreamEnd` message says how many messages were published and
the last stamp of each stream, so consumers know when they have seen everything.

Replays never outrun their consumers: the services this ingest waits for report how far they
have handled each sensor stream, and publishing waits while the slowest is more than
`window_s` of stream time behind (runtime.pacing), so no rate, however fast, and no load drops a
frame. Live sources are not held back (a sensor does not wait): their bounded queue drops the
oldest item and counts it.
"""

from __future__ import annotations

import asyncio
import importlib
import logging
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any, cast

import numpy as np

from cognition.gestures.logs import read_hand_log
from core.errors import InputError
from runtime.delivery import CAMERA, EVENTS
from runtime.images import message_from_image
from runtime.log import event
from runtime.pacing import DEFAULT_WINDOW_S, Pacer
from runtime.publisher import Publisher
from runtime.recording import read_recording
from runtime.service import Service
from schemas import CameraFrame, CompressedCameraFrame, Joint, SkeletonFrame, StreamEnd
from schemas.keys import with_robot


class SensorIngest(Service):
    name = "ingest"
    subscribes = ()
    publishes = ("skeleton", "camera", "camera_compressed", "stream_end")
    serves = ("progress",)  # the pacer answers restarted consumers

    def __init__(
        self,
        *,
        recording: str | None = None,
        log: str | None = None,
        plugin: str | None = None,
        rate: float = 1.0,
        loop: bool = False,
        scale: float = 0.001,
        hand_joint: str = "right_hand",
        queue: int = 256,
        start_delay_s: float = 0.0,
        wait_for: list[str] | None = None,
        wait_timeout_s: float = 60.0,
        window_s: float = DEFAULT_WINDOW_S,
        **base: Any,
    ) -> None:
        super().__init__(**base)
        given = [n for n, v in (("recording", recording), ("log", log), ("plugin", plugin)) if v]
        if len(given) != 1:
            raise InputError(
                f"sensor ingest needs exactly one source; got {', '.join(given) or 'none'}; "
                "valid: recording=FILE.mcap, log=DIR_OR_DATA_LOG, plugin=module:function"
            )
        if rate < 0:
            raise InputError(f"rate {rate} must be >= 0 (0: as fast as possible)")
        self.recording, self.log_path, self.plugin = recording, log, plugin
        self.rate = rate
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
        self.last_stamps: dict[str, int] = {}
        self.published = 0
        self.dropped_items = 0
        self.finished = asyncio.Event()

    async def setup(self) -> None:
        keys = self.bus.keys
        self.skeleton = self.publisher(keys.skeleton, SkeletonFrame)
        # camera frames are cached (never leaving the robot): an object segmenter restarted
        # mid-gesture gets back the frames of the gesture it was analysing
        self.camera = self.publisher(keys.camera, CameraFrame, CAMERA)
        self.compressed = self.publisher(keys.camera_compressed, CompressedCameraFrame, CAMERA)
        self.end = self.publisher(keys.stream_end, StreamEnd, EVENTS)
        self.spawn(self._play(), "source")

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
        if self.start_delay_s:
            await asyncio.sleep(self.start_delay_s)
        try:
            while True:
                if self.recording:
                    await self._play_recording(Path(self.recording))
                elif self.log_path:
                    await self._play_log(Path(self.log_path))
                else:
                    await self._play_plugin(str(self.plugin))
                if not self.loop:
                    break
        except InputError as exc:
            self.report_error("source", exc)
        finally:
            self.pacer.stop()
        end = StreamEnd(
            header=self.header(StreamEnd),
            source=str(self.recording or self.log_path or self.plugin),
            messages=self.published,
            dropped=self.dropped_items,
            last_stamps=dict(self.last_stamps),
        )
        self.end.put(end)
        self.finished.set()
        event(
            self.log,
            logging.INFO,
            "source finished",
            messages=self.published,
            dropped=self.dropped_items,
            held_back_s=round(self.pacer.waited_s, 3),
        )

    def _sent(self, stream: str, key: str, stamp: int) -> None:
        self.published += 1
        self.last_stamps[stream] = stamp
        self.pacer.after(key, stamp)

    async def _pace(self, t0: int | None, stamp: int, wall0: float) -> None:
        loop = asyncio.get_running_loop()
        if self.rate > 0 and t0 is not None:
            delay = wall0 + (stamp - t0) / 1e9 / self.rate - loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
        elif self.published % 32 == 0:
            await asyncio.sleep(0)

    async def _play_recording(self, path: Path) -> None:
        keys = self.bus.keys
        streams: dict[str, tuple[str, Publisher[Any]]] = {
            keys.skeleton: ("skeleton", self.skeleton),
            keys.camera: ("camera", self.camera),
            keys.camera_compressed: ("camera_compressed", self.compressed),
        }
        wall0 = asyncio.get_running_loop().time()
        t0: int | None = None
        for item in read_recording(path):
            key = with_robot(item.key, keys.robot)
            target = streams.get(key)
            if target is None:
                continue
            stream, pub = target
            message = item.message()
            stamp = message.header.stamp
            t0 = item.publish_time if t0 is None else t0
            await self._pace(t0, item.publish_time, wall0)
            await self.pacer.before(key, stamp)
            pub.put(message)
            self._sent(stream, key, stamp)

    async def _play_log(self, path: Path) -> None:
        log = read_hand_log(path)
        wall0 = asyncio.get_running_loop().time()
        stamps = np.rint(log.time * 1e9).astype(np.int64)
        for i, (xyz, stamp) in enumerate(zip(log.xyz * self.scale, stamps, strict=True)):
            await self._pace(int(stamps[0]), int(stamp), wall0)
            await self.pacer.before(self.bus.keys.skeleton, int(stamp))
            joint = Joint(position=(float(xyz[0]), float(xyz[1]), float(xyz[2])))
            self.skeleton.put(
                SkeletonFrame(
                    header=self.header(SkeletonFrame, int(stamp)),
                    frame=i + 1,
                    joints={self.hand_joint: joint},
                )
            )
            self._sent("skeleton", self.bus.keys.skeleton, int(stamp))

    async def _play_plugin(self, spec: str) -> None:
        source = load_plugin(spec)()
        queue: asyncio.Queue[tuple[str, Any]] = asyncio.Queue(self.queue_size)
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
                kind, payload = await queue.get()
                if payload is done:
                    break
                frame += 1
                keys = self.bus.keys
                if kind == "skeleton":
                    joints = {n: Joint(position=tuple(map(float, p))) for n, p in payload.items()}  # type: ignore[arg-type]
                    header = self.header(SkeletonFrame)
                    self.skeleton.put(SkeletonFrame(header=header, frame=frame, joints=joints))
                    self._sent("skeleton", keys.skeleton, header.stamp)
                elif kind == "camera":
                    header = self.header(CameraFrame)
                    self.camera.put(message_from_image(header, payload))  # type: ignore[arg-type]
                    self._sent("camera", keys.camera, header.stamp)
                else:
                    raise InputError(f"plug-in item kind {kind!r}; valid: skeleton, camera")
        finally:
            task.cancel()


def load_plugin(spec: str) -> Callable[[], AsyncIterator[tuple[str, Any]]]:
    module_name, sep, attr = spec.partition(":")
    if not sep:
        raise InputError(f"plug-in {spec!r}; valid: module:function")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise InputError(f"plug-in module {module_name!r} cannot be imported: {exc}") from None
    fn = getattr(module, attr, None)
    if not callable(fn):
        raise InputError(f"plug-in {spec!r}: {module_name} has no function {attr!r}")
    return cast("Callable[[], AsyncIterator[tuple[str, Any]]]", fn)
