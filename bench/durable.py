"""Durable state (issue 39): what the source log and the snapshots cost, and how fast a killed
service resumes.

- Source log: `Publisher.put` of a skeleton frame (15 joints, ~1.1 kB) and a 320x240 rgb8 camera
  frame (~230 kB) on the ingest's cached publishers, alone (the reference) and with the source
  log written first (runtime.resilience.source_log, in a temporary folder), interleaved runs, the
  fastest run's time per message until the log has written it (the machine is shared: the
  minimum is the cost, the rest is other load). Goal: with the log <= 1.2x the publish alone.
  Also printed: what the log adds as a share of a core at 30 Hz.
- Snapshots: the base's snapshot logic for the gesture streamer (the tracker's snapshot offered
  after each frame, told with the ledger when it moves, stored on disk with fsync on a new
  gesture count and every 2 s) over three-actions.mcap's skeleton frames; time and bytes per
  snapshot, and its CPU share at 30 Hz (goal < 2% of a core). The object segmenter's, its
  restart point moving every camera frame (the most it takes), is timed beside it.
- Resume: a deployment playing three-actions.mcap at rate 1; the gesture streamer SIGKILLed
  mid-run; the time from the kill to the restarted streamer's first output (its first Progress
  report: it has handled a frame). Goal < 1 s.
- Whole deployment: `beyond up` on the same recording, SIGKILLed with everything it started
  while gesture 2 is under way, then the same command again: the time from its start to the
  gesture streamer's first output, next to the same time for the first, fresh start (the
  reference). Goal < 3 s.
Last line: one JSON object.
"""

from __future__ import annotations

import argparse
import asyncio
import importlib.util
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType

REPO = Path(__file__).resolve().parent.parent
RECORDING = REPO / "recordings" / "three-actions.mcap"
REPEATS = 9
SENSOR_HZ = 30  # the Kinect's skeleton and camera rate


def bus_bench() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_bus", REPO / "bench" / "bus.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def source_log_cost() -> dict[str, float]:
    import beyond_self.schemas as s
    from beyond_self.runtime.bus.config import BusConfig
    from beyond_self.runtime.bus.delivery import CAMERA, SKELETON
    from beyond_self.runtime.bus.session import Bus
    from beyond_self.runtime.resilience.source_log import DEFAULT_MAX_MB, SourceLog

    make = bus_bench().make_message
    figures: dict[str, float] = {}
    config = BusConfig(robot="benchdurable", port=17790)
    with Bus.open(config) as bus, tempfile.TemporaryDirectory() as folder:
        for kind, delivery, count in (("skeleton", SKELETON, 3000), ("camera", CAMERA, 300)):
            cls = s.SkeletonFrame if kind == "skeleton" else s.CameraFrame
            key = bus.keys.skeleton if kind == "skeleton" else bus.keys.camera
            messages = [make(kind, i, 1_000_000 + i) for i in range(count)]
            plain_us, logged_us = [], []
            for r in range(REPEATS):
                for logged in (False, True) if r % 2 else (True, False):
                    pub = bus.publisher(key, cls, delivery)
                    log = SourceLog(Path(folder) / f"{kind}{r}", round(DEFAULT_MAX_MB * 2**20))
                    if logged:
                        log.record([pub])
                    began = time.perf_counter()
                    for m in messages:
                        pub.put(m)
                    if logged:
                        log.flush()
                    took = (time.perf_counter() - began) / count * 1e6
                    (logged_us if logged else plain_us).append(took)
                    log.close()
                    pub.close()
            plain, logged_ = min(plain_us), min(logged_us)  # the cost itself, not the load
            figures[f"{kind}_publish_us"] = round(plain, 2)
            figures[f"{kind}_publish_logged_us"] = round(logged_, 2)
            figures[f"{kind}_log_ratio"] = round(logged_ / plain, 3)
            # what the log adds, as the share of a core a 30 Hz sensor of this kind takes
            share = (logged_ - plain) * SENSOR_HZ / 1e6
            figures[f"{kind}_log_core_share_30hz"] = round(share, 6)
            print(
                f"source log, {kind}: publish {plain:.1f} us, with the log {logged_:.1f} us "
                f"per message: {logged_ / plain:.2f}x (goal <= 1.2x); the log's share of a "
                f"core at {SENSOR_HZ} Hz {share * 100:.3f}%",
                flush=True,
            )
    return figures


def snapshot_cost() -> dict[str, float]:
    import beyond_self.schemas as s
    from beyond_self.cognition.episodes import GestureTracker, TrackerSnapshot, WatchSnapshot
    from beyond_self.cognition.episodes.offline import SkeletonInput
    from beyond_self.cognition.gestures import extract_features
    from beyond_self.cognition.gestures.default_models import default_models
    from beyond_self.commands.analyse import _inputs
    from beyond_self.runtime.resilience.ledger import Keeper
    from beyond_self.runtime.resilience.snapshots import Snapshots, SnapshotStore

    frames = [
        (i.stamp, i.frame, extract_features(i.hand, i.torso)[0])
        for i in _inputs(RECORDING, "right_hand", "torso")
        if isinstance(i, SkeletonInput)
    ]

    def header(cls: type[s.Message], stamp: int | None) -> s.Header:
        return s.Header(version=cls.VERSION, source="gestures", seq=0, stamp=stamp or 1)

    with tempfile.TemporaryDirectory() as folder:
        store = SnapshotStore(Path(folder))
        inputs = ["r/skeleton"]
        snapshots = Snapshots(TrackerSnapshot, Keeper("gestures", header), store, "d", inputs)
        tracker: GestureTracker[int] = GestureTracker(default_models())
        spent = 0.0
        for stamp, number, x in frames:
            tracker.push(stamp, number, x, number)
            began = time.perf_counter()
            snapshots.offer(tracker.snapshot())  # what the base does after every message
            spent += time.perf_counter() - began
        taken = snapshots.taken_count
        if snapshots.stored is not None:
            snapshots.stored.result(10)
        saves = store.number
        save_us = []
        for i in range(50):  # one stored snapshot: encode, write, fsync, rename, fsync folder
            began = time.perf_counter()
            store.save(TrackerSnapshot(i, i, i), {"r/skeleton": i})
            save_us.append((time.perf_counter() - began) * 1e6)
        size = store.bytes_written / store.number
        cameras = ["r/camera", "r/compressed"]
        watch = Snapshots(WatchSnapshot, Keeper("objects", header), None, "d", cameras)
        began = time.perf_counter()
        for i in range(len(frames)):  # the object segmenter's, its restart point moving each frame
            watch.offer(WatchSnapshot(i, i // 200))
        objects_us = (time.perf_counter() - began) / len(frames) * 1e6
    stream_s = len(frames) / 30.0
    share = spent / stream_s
    # counting the writes' wall time as CPU too (an upper bound: fsync mostly waits)
    total = (spent + saves * statistics.median(save_us) / 1e6) / stream_s
    per_us = spent / max(taken, 1) * 1e6
    print(
        f"snapshots, gesture streamer: {taken} taken over {len(frames)} frames ({saves} stored),"
        f" {per_us:.1f} us each on the event loop, {statistics.median(save_us):.0f} us each "
        f"stored (on a thread of its own, fsync included), {size:.0f} bytes; CPU share of the "
        f"event loop at 30 Hz {share * 100:.3f}% of a core "
        f"(goal < 2%); with the stored ones' wall time counted as CPU {total * 100:.3f}%",
        flush=True,
    )
    print(f"snapshots, object segmenter: {objects_us:.2f} us per camera frame (told)", flush=True)
    return {
        "gestures_snapshots_taken": taken,
        "gestures_snapshot_told_us": round(per_us, 2),
        "gestures_snapshot_stored_us": round(statistics.median(save_us), 1),
        "gestures_snapshot_bytes": round(size, 1),
        "gestures_snapshot_cpu_share": round(share, 6),
        "gestures_snapshot_share_with_writes": round(total, 6),
        "objects_checkpoint_us": round(objects_us, 2),
    }


async def resume_time() -> dict[str, float]:
    import os
    import signal

    import beyond_self.schemas as s
    from beyond_self.runtime.bus.config import BusConfig
    from beyond_self.runtime.bus.delivery import STATUS
    from beyond_self.services.deployment import Deployment

    loop = asyncio.get_running_loop()
    restarted: list[float] = []
    pipeline = Deployment(
        BusConfig(robot="benchresume", port=17791),
        ["gestures", "objects", "reasoner", "describer", "ingest"],
        options={"ingest": {"recording": str(RECORDING), "rate": 1.0}},
        clock="recording",
        on_restart=lambda name, what: restarted.append(loop.time()),
    )
    bus = await pipeline.open()
    firsts: list[float] = []
    killed_at: list[float] = []

    async def progress() -> None:
        sub = bus.subscribe(bus.keys.progress("gestures"), s.Progress, STATUS)
        async for _ in sub:
            if killed_at and restarted and not firsts and loop.time() > restarted[0]:
                firsts.append(loop.time())

    task = loop.create_task(progress())
    try:
        await pipeline.start()
        await asyncio.sleep(6.0)  # mid-gesture 1
        victim = next(p for p in pipeline.processes if p.name == "gestures")
        killed_at.append(loop.time())
        os.kill(victim.process.pid, signal.SIGKILL)
        while not firsts and loop.time() - killed_at[0] < 60:
            await asyncio.sleep(0.01)
    finally:
        task.cancel()
        await pipeline.stop()
    took = firsts[0] - killed_at[0] if firsts else float("nan")
    delay = restarted[0] - killed_at[0] if restarted else float("nan")
    print(
        f"resume, gesture streamer SIGKILLed: first output {took:.2f} s after the kill "
        f"(the supervisor's restart delay {delay:.2f} s of it; goal < 1 s)",
        flush=True,
    )
    return {"resume_single_s": round(took, 3), "restart_delay_s": round(delay, 3)}


async def whole_resume_time() -> dict[str, float]:
    """`beyond up` started fresh, SIGKILLed mid-gesture 2, started again: the time from each
    start to the gesture streamer's first output."""
    import os

    import beyond_self.schemas as s
    from beyond_self.runtime.bus.config import BusConfig
    from beyond_self.runtime.bus.delivery import STATUS
    from beyond_self.runtime.bus.session import Bus
    from beyond_self.runtime.bus.subscription import Subscription

    loop = asyncio.get_running_loop()
    config = BusConfig(robot="benchwhole", port=17793)
    with tempfile.TemporaryDirectory() as folder, Bus.open(config) as bus:
        env = {
            **os.environ,
            **config.to_env(),
            "BEYOND_OUT_DIR": folder,
            "BEYOND_LOG_FORMAT": "text",
            "PYTHONPATH": str(REPO),
        }
        command = [sys.executable, "-m", "beyond_self", "up", "--recording", str(RECORDING)]
        command += ["--rate", "1", "--no-live", "--timeout", "60"]
        skeleton = bus.keys.skeleton

        async def first_output(sub: Subscription[s.Progress], after: float) -> float:
            async for received in sub:
                if received.message.handled.get(skeleton, -1) >= 0:
                    sub.close()
                    return loop.time() - after
            raise RuntimeError("no progress")

        def progress() -> Subscription[s.Progress]:  # opened before the run it hears
            return bus.subscribe(bus.keys.progress("gestures"), s.Progress, STATUS)

        quiet = asyncio.subprocess.DEVNULL
        sub, began = progress(), loop.time()
        up = await asyncio.create_subprocess_exec(*command, env=env, stdout=quiet, stderr=quiet)
        fresh = await asyncio.wait_for(first_output(sub, began), 60)
        await asyncio.sleep(max(0.0, began + 11.0 - loop.time()))  # gesture 2 is under way
        up.kill()
        await up.wait()
        await asyncio.sleep(2.0)  # its services die with it (runtime.process.lifeline)
        sub, began = progress(), loop.time()
        again = await asyncio.create_subprocess_exec(*command, env=env, stdout=quiet, stderr=quiet)
        resumed = await asyncio.wait_for(first_output(sub, began), 60)
        code = await asyncio.wait_for(again.wait(), 120)
    print(
        f"resume, whole deployment SIGKILLed: first output {resumed:.2f} s after `beyond up` "
        f"started again, {fresh:.2f} s after its fresh start (x{resumed / fresh:.2f}; "
        f"goal < 3 s); the second run exited {code}",
        flush=True,
    )
    return {
        "resume_whole_s": round(resumed, 3),
        "fresh_start_s": round(fresh, 3),
        "resume_whole_ratio": round(resumed / fresh, 3),
        "resume_whole_exit": code,
    }


def main() -> int:
    # no options: --help says what it measures and exits
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.parse_args()
    sys.path.insert(0, str(REPO / "bench"))
    figures = source_log_cost()
    figures |= snapshot_cost()
    figures |= asyncio.run(resume_time())
    figures |= asyncio.run(whole_resume_time())
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
