"""How many robots one workstation serves: one process per service for a fleet (runtime/fleet.py)
next to one process set per robot, measured in the same run; the bench searches for the limit.

    .venv/bin/python bench/fleet.py [--quick] [--minutes M] [--cases own,aligned,camera] [--save]

Skeleton only (no vision: the gesture streamer, the affordance reasoner and the description
generator; the reasoner told there is no object segmenter). Each round, N robots appear (this
script declares each robot's source token and publishes its 30 Hz skeleton stream live, at real
time, all N at once, phases spread over a frame; each frame encoded once before the round and
its stamp put in as it is sent, the bytes encoding it then would give), the workstation's fleet
processes start a run for each, and per gesture the clock starts when the frame that lets the
segmenter decide the gesture is over is published (found offline by the same segmenter,
bench/pipeline.py) and stops when the gesture's description is taken off Zenoh for that robot.
Every gesture that ended must be described, or the bench fails.

Three cases: a person each (`own`: each robot its own synthetic person, a seed each: gestures
of their own lengths at their own times, as in a lab), aligned (every robot the same stream, so
every robot's gestures end within one frame of each other and each stage gets N gestures at
once: a burst, the worst case), and a camera each (below).

The limit: per case, rounds of 1, 2, 4, ... robots (doubling; x4 with --quick) until a round's
description p99 reaches 33 ms (a frame at 30 Hz), then bisecting between the largest round under
the budget and the smallest over it until they are within an eighth of each other (a half with
--quick); the limit is that largest round under the budget. There is no cap on N below that,
only safety caps, reported when hit (the limit is then a lower bound): wall time (--minutes, the
time left shared among the cases left; a round is not started when the last one, scaled by the
robots' count, would not end in time), memory (a round is not started when its processes and
this script's, extrapolated from the rounds so far, would take more than --memory-share of the
memory available at the start), and --max if given. The robots of a round leave before the next
(their runs are dropped). A full search (6 gestures per robot) takes 30-60 minutes on a 2-core
machine; --quick (3 gestures, coarser steps, a 10-minute cap) about 10.

Costs: resident memory of the processes, summed (VmRSS, and PSS, which shares each page among
the processes that map it), and their CPU time over the round (cores); next to them the same
three services as one process set for one robot (`beyond up`'s way before fleets), started and
measured in the same run with one robot: N robots that way cost N of those; and the CPU of this
script itself (the robots' simulated sources and its observers, which a real fleet would not run
on the workstation: `sources_cores`; the streams are made before the services start, outside
it). Beside each limit: CPU per robot (cores at the limit / N),
memory per added robot (MB, the slope from the case's one-robot round to the limit), and the
ratios of the process set per robot's figures to those. Where the time goes: per stage, the p99
of the time from the gesture's deciding frame to its end event leaving the gesture streamer,
from there to its words leaving the reasoner, and from there to the description (each message's
arrival taken off Zenoh, wall clock).

With a camera: the same rounds with the object segmenter in the fleet too, each robot its own
simulated scene (skeleton at 30 Hz and 15 fps JPEG frames, a seed and a gesture order each;
`beyond simulate`) published at real time; per gesture, from the last input its description
needs (the later of the skeleton frame that ends it and the first camera frame after its end,
found offline by the same tracker) to its description, next to one process set for one robot;
and how many camera frames the object segmenter described and skipped (a live source sheds
per-frame work under overload, never a gesture's). Progress goes to stderr; ends with one line
of JSON. --save also writes it to bench/results/fleet.json as `result`, with the date, the
machine and the provenance (command, commit, duration), keeping the file's table.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import datetime
import functools
import json
import os
import sys
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))  # the pipeline bench's skeleton stream and figures

import results_file  # noqa: E402
from pipeline import CAMERA, QUIET, _p, scene_gestures, stream_frames, vision_scene  # noqa: E402

import beyond_self.schemas as s  # noqa: E402
from beyond_self.core.errors import InputError  # noqa: E402
from beyond_self.runtime.bus.config import BusConfig  # noqa: E402
from beyond_self.runtime.bus.delivery import EVENTS  # noqa: E402
from beyond_self.runtime.bus.session import Bus  # noqa: E402
from beyond_self.runtime.fleet import LEAVE_ENV  # noqa: E402
from beyond_self.runtime.recording.replay import restamped  # noqa: E402
from beyond_self.runtime.shard import shard_count  # noqa: E402
from beyond_self.schemas.codec import encode  # noqa: E402
from beyond_self.schemas.keys import Keys, for_robots, split_key  # noqa: E402
from beyond_self.services.deployment import Deployment  # noqa: E402

SERVICES = ["gestures", "reasoner", "describer"]
OPTIONS = {"reasoner": {"objects": False}}
CAMERA_SERVICES = ["gestures", "objects", "reasoner", "describer"]
FRAME_NS = 33_333_333
BUDGET_MS = 1e3 / 30


def process_cost(pids: list[int]) -> tuple[float, float, float]:
    """(resident MB, proportional MB, CPU seconds so far) of processes `pids` and their
    children. Proportional (PSS) counts a page shared by k processes as 1/k in each, so the
    fleet's shared libraries count once."""
    rss_kb, pss_kb, ticks = 0, 0, 0
    for pid in _with_children(pids):
        with contextlib.suppress(OSError, StopIteration):
            status = Path(f"/proc/{pid}/status").read_text()
            rss_kb += int(next(x for x in status.splitlines() if x.startswith("VmRSS")).split()[1])
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            ticks += int(fields[11]) + int(fields[12])  # utime, stime
            rollup = Path(f"/proc/{pid}/smaps_rollup").read_text()
            pss_kb += int(next(x for x in rollup.splitlines() if x.startswith("Pss:")).split()[1])
    return rss_kb / 1024, pss_kb / 1024, ticks / os.sysconf("SC_CLK_TCK")


def _own_rss_mb() -> float:
    """Resident MB of this script (the robots' sources and their cached streams)."""
    status = Path("/proc/self/status").read_text()
    return int(next(x for x in status.splitlines() if x.startswith("VmRSS")).split()[1]) / 1024


def _available_mb() -> float:
    meminfo = Path("/proc/meminfo").read_text()
    return (
        int(next(x for x in meminfo.splitlines() if x.startswith("MemAvailable")).split()[1]) / 1024
    )


def _own_cpu_s() -> float:
    """CPU seconds of this process alone (its threads; not the services it started)."""
    times = os.times()
    return times.user + times.system


def _with_children(pids: list[int]) -> list[int]:
    out = list(pids)
    for pid in pids:
        with contextlib.suppress(OSError):
            kids = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
            out += _with_children([int(k) for k in kids])
    return out


# a stamp no frame carries, encoded in place of each frame's own (msgpack's uint64: a stamp is
# past 2^32 ns), so that a frame's bytes are made once and its send time's stamp put in
STAMP_MARK = 0x1BAD_5EED_CAFE_F00D
_UINT64 = b"\xcf"


@dataclass(frozen=True)
class EncodedStream:
    """A robot's skeleton stream, each frame encoded once with `STAMP_MARK` as its stamp; a
    frame sent is its bytes with the send time's stamp put in (byte for byte what encoding the
    frame then gives: `encoded_stream` checks it), and `triggers`, the indices of the frames
    that end its gestures. Bytes, not messages: 0.4 MB a robot, not 1.8, and no message built
    and encoded per frame while the robots stream."""

    payloads: list[bytes]
    at: list[int]  # where each payload's 8 stamp bytes are
    triggers: list[int]

    def __len__(self) -> int:
        return len(self.payloads)

    def payload(self, i: int, stamp: int) -> bytes:
        if stamp < 2**32:  # msgpack writes it shorter: the frame's bytes would not be its own
            raise ValueError(f"stamp {stamp}; valid: a time since the epoch, at least 2^32 ns")
        data, at = self.payloads[i], self.at[i]
        return b"".join((data[:at], stamp.to_bytes(8, "big"), data[at + 8 :]))


def live_frame(frame: s.SkeletonFrame, seq: int, stamp: int) -> s.SkeletonFrame:
    """`frame` as the bench sends it, frame `seq` of its stream stamped `stamp`."""
    header = s.Header(version=1, source="bench", seq=seq, stamp=stamp)
    return s.SkeletonFrame(header=header, frame=frame.frame, joints=frame.joints)


def encoded_stream(frames: list[s.SkeletonFrame], triggers: list[int]) -> EncodedStream:
    mark = _UINT64 + STAMP_MARK.to_bytes(8, "big")
    payloads, at = [], []
    for i, frame in enumerate(frames):
        data = encode(live_frame(frame, i, STAMP_MARK))
        if data.count(mark) != 1:
            raise RuntimeError(f"frame {i}: its stamp is not found once in its bytes")
        payloads.append(data)
        at.append(data.index(mark) + 1)
    stream = EncodedStream(payloads, at, triggers)
    stamp = time.time_ns()
    if stream.payload(0, stamp) != encode(live_frame(frames[0], 0, stamp)):
        raise RuntimeError("a frame with its stamp put in is not the frame encoded")
    return stream


@functools.cache
def robot_stream(seed: int, gestures: int) -> EncodedStream:
    return encoded_stream(*stream_frames(seed=seed, gestures=gestures))


def streams_for(n: int, gestures: int, aligned: bool) -> list[EncodedStream]:
    """Each robot's skeleton stream: its own person (a seed each: gestures of their own lengths
    at their own times), or, `aligned`, all the same stream, so that every robot's gestures end
    within one frame of each other and every stage gets N at once (the worst case)."""
    return [robot_stream(7 if aligned else 7 + k, gestures) for k in range(n)]


@contextlib.asynccontextmanager
async def present(bus: Bus, robots: list[str], services: list[str]) -> AsyncIterator[list[Bus]]:
    """Each robot's view of the bus, with the robot there (its source's liveliness token) and
    its runs of `services` alive, so that its source may publish; gone again afterwards (the
    fleet drops their runs before the next round)."""
    views = [bus.for_robot(r) for r in robots]
    tokens = [v.declare_token(v.keys.alive("ingest")) for v in views]
    # every robot's runs at once: one wait per service, not one per robot and service
    pattern = bus.config.robots or robots[0]  # the fleet's robots, or the one robot's own set
    try:
        for name in services:
            key = for_robots(pattern, Keys().alive(name))
            await bus.wait_alive(key, count=len(robots), timeout=60)
        yield views
    finally:
        for undeclare in tokens:
            undeclare()
        for view in views:
            view.close()


def observe(bus: Bus, robots: list[str], key: str, cls: type[s.Message]) -> Any:
    """One subscription to `key` (any robot's) for all of `robots` (the bench's observer must
    not cost the workstation a subscription and a thread per robot); recovering, so that a
    message Zenoh dropped under load still counts."""
    pattern = bus.config.robots or robots[0]  # the fleet's pattern, or the one robot's own set
    return bus.subscribe(for_robots(pattern, key), cls, EVENTS)


def robot_of(robots: list[str]) -> Any:
    """Index of the robot a received key belongs to."""
    index = {r: k for k, r in enumerate(robots)}
    return lambda key: index[split_key(key)[0]]  # type: ignore[index]


async def serve(bus: Bus, robots: list[str], streams: list[EncodedStream]) -> dict[str, Any]:
    """The robots' live skeleton streams at once; per gesture its description latency (ms)."""
    latencies: list[float] = []
    stages: dict[str, list[float]] = {"gestures": [], "reasoner": [], "describer": []}
    async with present(bus, robots, SERVICES) as views:
        pubs = [v.publisher(v.keys.skeleton, s.SkeletonFrame) for v in views]
        outs = observe(bus, robots, bus.keys.description, s.Description)
        # where the time goes: when each gesture's end left the gesture streamer and its words
        # left the reasoner, per robot (the description's own arrival closes the last stage)
        segs = observe(bus, robots, bus.keys.gesture_segment, s.GestureSegment)
        words = observe(bus, robots, bus.keys.words, s.WordProbabilities)
        which = robot_of(robots)
        seen: dict[str, list[dict[int, int]]] = {
            "segment": [{} for _ in robots],
            "words": [{} for _ in robots],
        }
        await asyncio.gather(*(pub.wait_matching(timeout=30) for pub in pubs))
        longest = max(len(stream) for stream in streams)
        # per robot, when each frame was sent (wall ns) and each stamp's frame: a gesture's
        # description carries the stamp of its last frame (event time); the segmenter decides
        # the gesture is over a few frames later, at the first offline trigger from there on (a
        # gesture the live tracker cancels leaves its trigger unused)
        sent: list[list[int]] = [[] for _ in robots]
        index: list[dict[int, int]] = [{} for _ in robots]
        described: list[list[Any]] = [[] for _ in robots]

        async def receive() -> None:
            with contextlib.suppress(asyncio.CancelledError):
                while True:
                    got = await outs.recv(timeout=None)
                    described[which(got.key)].append(got)

        async def watch(sub: Any, into: list[dict[int, int]], ends_only: bool) -> None:
            with contextlib.suppress(asyncio.CancelledError):
                while True:
                    got = await sub.recv(timeout=None)
                    if not ends_only or got.message.event == "end":
                        into[which(got.key)].setdefault(got.message.segment_id, got.received_ns)

        loop = asyncio.get_running_loop()
        watchers = [
            loop.create_task(receive()),
            loop.create_task(watch(segs, seen["segment"], True)),
            loop.create_task(watch(words, seen["words"], False)),
        ]
        begin_wall, begin_ns = loop.time(), time.time_ns()
        for i in range(longest):
            for k, pub in enumerate(pubs):  # phases spread over the frame interval
                stream = streams[k]
                if i >= len(stream):
                    continue
                at = begin_wall + (i + k / len(robots)) * FRAME_NS / 1e9
                delay = at - loop.time()
                if delay > 0:
                    await asyncio.sleep(delay)
                stamp = begin_ns + i * FRAME_NS + k * FRAME_NS // len(robots)
                pub.put_bytes(stream.payload(i, stamp))
                sent[k].append(time.time_ns())
                index[k][stamp] = i
        # every gesture that ended is described: wait for the last descriptions, then measure
        deadline = loop.time() + 60
        while loop.time() < deadline and any(
            len(described[k]) < len(seen["segment"][k]) for k in range(len(robots))
        ):
            await asyncio.sleep(0.05)
        for k, robot in enumerate(robots):
            ends, said = len(seen["segment"][k]), len(described[k])
            if said != ends:
                raise SystemExit(f"robot {robot}: {ends} gestures ended, {said} described")
            for got in described[k]:
                # the stages on one clock: when each message was taken off Zenoh (wall, ns)
                last = index[k][got.message.header.stamp]
                end = sent[k][min(t for t in streams[k].triggers if t >= last)]
                seg = seen["segment"][k].get(got.message.segment_id, end)
                word = seen["words"][k].get(got.message.segment_id, seg)
                latencies.append((got.received_ns - end) / 1e6)
                stages["gestures"].append((seg - end) / 1e6)
                stages["reasoner"].append((word - seg) / 1e6)
                stages["describer"].append((got.received_ns - word) / 1e6)
        for task in watchers:
            task.cancel()
        for sub in (outs, segs, words):
            sub.close()
    return {"latency_ms": latencies, "stages_ms": stages, "stream_s": longest * FRAME_NS / 1e9}


@functools.cache
def camera_scene(k: int) -> tuple[list[s.Message], dict[int, tuple[int, int, int, int]]]:
    """Robot k's simulated scene (its own seed and gesture order: skeleton at 30 Hz and a 15
    fps JPEG camera, `beyond simulate`) and, per gesture, found offline by the services' own
    tracker, (index of the message announcing its start, of the one ending it, start stamp,
    end stamp)."""
    with contextlib.redirect_stdout(sys.stderr):  # the simulator's table: not this JSON's
        items = vision_scene(1, seed=3 + k, turn=k)
    return items, scene_gestures(items)


async def serve_camera(bus: Bus, robots: list[str]) -> dict[str, Any]:
    """The robots' live scenes at once (skeleton and camera, at real time, phases spread over
    a skeleton frame); per gesture, from the last input its description needs (the later of
    the skeleton frame that ends it and the first camera frame after its end) to the
    description, as bench/pipeline.py measures one robot's."""
    scenes = [camera_scene(k) for k in range(len(robots))]
    latencies: list[float] = []
    frames = {"described": 0, "skipped": 0}
    async with present(bus, robots, CAMERA_SERVICES) as views:
        pubs = [
            (v.publisher(v.keys.skeleton, s.SkeletonFrame),
             v.publisher(v.keys.stream(CAMERA), s.CompressedCameraFrame))
            for v in views
        ]  # fmt: skip
        outs = observe(bus, robots, bus.keys.description, s.Description)
        objects = observe(bus, robots, bus.keys.objects, s.DetectedObjects)
        which = robot_of(robots)
        await asyncio.gather(*(pub.wait_matching(timeout=30) for pair in pubs for pub in pair))
        described: list[dict[int, int]] = [{} for _ in robots]

        async def receive() -> None:
            with contextlib.suppress(asyncio.CancelledError):
                while True:
                    got = await outs.recv(timeout=None)
                    described[which(got.key)].setdefault(got.message.segment_id, got.received_ns)

        async def count(sub: Any) -> None:
            with contextlib.suppress(asyncio.CancelledError):
                while True:
                    got = await sub.recv(timeout=None)
                    frames["described"] += 1
                    frames["skipped"] += got.message.skipped

        loop = asyncio.get_running_loop()
        watchers = [loop.create_task(receive()), loop.create_task(count(objects))]
        # one timeline: robot k's message i at its offset in its scene, plus k/N of a frame
        timeline = sorted(
            (m.header.stamp - items[0].header.stamp + k * FRAME_NS // len(robots), k, i)
            for k, (items, _) in enumerate(scenes)
            for i, m in enumerate(items)
        )
        sent: list[dict[int, int]] = [{} for _ in robots]
        begin_wall, begin_ns = loop.time(), time.time_ns()
        for offset, k, i in timeline:
            delay = begin_wall + offset / 1e9 - loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
            msg = scenes[k][0][i]
            live = restamped(msg, begin_ns + offset - msg.header.stamp)
            skeleton, camera = pubs[k]
            if isinstance(live, s.SkeletonFrame):
                skeleton.put(live)
            else:
                camera.put(live)  # type: ignore[arg-type]
            sent[k][i] = time.time_ns()
        deadline = loop.time() + 60
        while loop.time() < deadline and any(
            len(described[k]) < len(gestures) for k, (_, gestures) in enumerate(scenes)
        ):
            await asyncio.sleep(0.05)
        for k, (robot, (items, gestures)) in enumerate(zip(robots, scenes, strict=True)):
            missing = sorted(set(gestures) - set(described[k]))
            if missing:
                raise SystemExit(f"robot {robot}: gestures {missing} were not described")
            cameras = [i for i, m in enumerate(items) if not isinstance(m, s.SkeletonFrame)]
            for segment_id, (_, trigger, _, end) in gestures.items():
                after_end = next(i for i in cameras if items[i].header.stamp > end)
                last_input = max(sent[k][trigger], sent[k][after_end])
                latencies.append((described[k][segment_id] - last_input) / 1e6)
        for task in watchers:
            task.cancel()
        for sub in (outs, objects):
            sub.close()
    stream_s = timeline[-1][0] / 1e9
    return {"latency_ms": latencies, "stream_s": stream_s, "camera_frames": frames}


async def measure(
    config: BusConfig, robots: list[str], gestures: int, kind: str = "own", shards: int = 1
) -> dict[str, Any]:
    """The services on `config` (a fleet's, or one robot's own set) serving `robots`: each
    its own person (`own`), all the same (`aligned`), or with a camera (`camera`); a fleet's
    services as `shards` processes each (`beyond up --shards`)."""
    services, options = (CAMERA_SERVICES, {}) if kind == "camera" else (SERVICES, OPTIONS)
    env = {**QUIET, LEAVE_ENV: "1"}
    side = Deployment(config, services, options=options, env=env, shards=shards)
    wall0 = time.monotonic()
    # the robots' streams made before the services start: neither the sources' CPU nor time
    # the services wait idle
    streams = [] if kind == "camera" else streams_for(len(robots), gestures, kind == "aligned")
    try:
        bus = await side.open()
        await side.start()
        pids = [sp.process.pid for sp in side.processes]
        _, _, cpu0 = process_cost(pids)
        bench0 = _own_cpu_s()
        if kind == "camera":
            served = await serve_camera(bus, robots)
        else:
            served = await serve(bus, robots, streams)
        rss, pss, cpu1 = process_cost(pids)
        bench_s = _own_cpu_s() - bench0
    finally:
        await side.stop()
    lat = served["latency_ms"]
    result: dict[str, Any] = {
        "robots": len(robots),
        "gestures": len(lat),
        "description_p50_ms": round(_p(lat, 50), 2),
        "description_p99_ms": round(_p(lat, 99), 2),
        "rss_mb": round(rss, 1),
        "pss_mb": round(pss, 1),
        "cores": round((cpu1 - cpu0) / served["stream_s"], 3),
        # the robots' simulated sources and the bench's observers, on the same 2 cores (a real
        # robot publishes from its own machine)
        "sources_cores": round(bench_s / served["stream_s"], 3),
        "sources_rss_mb": round(_own_rss_mb(), 1),
        "wall_s": round(time.monotonic() - wall0, 1),
    }
    if "stages_ms" in served:
        result["stage_p99_ms"] = {k: round(_p(v, 99), 2) for k, v in served["stages_ms"].items()}
    if "camera_frames" in served:
        result["camera_frames_described"] = served["camera_frames"]["described"]
        result["camera_frames_skipped"] = served["camera_frames"]["skipped"]
    return result


KINDS = {
    "own": "a person each",
    "aligned": "the same stream, aligned (a burst)",
    "camera": "a person each, with a 15 fps camera",
}
REFERENCE = {"own": "single", "aligned": "single", "camera": "single_camera"}
ROUNDS = {"own": "fleet", "aligned": "fleet_aligned", "camera": "fleet_camera"}


@dataclass
class Search:
    """Where the limit lies, from the rounds so far: doubling (`factor`) from one robot until a
    round is over the budget, then bisecting between the largest round under it below every
    round over it (`lo`) and the smallest round over it (`hi`) until `hi - lo` is at most
    `resolution` of `lo` (one robot at least). The limit is `lo`."""

    factor: int = 2
    resolution: float = 1 / 8
    within: dict[int, bool] = field(default_factory=dict)  # robots -> p99 under the budget

    def record(self, robots: int, p99_ms: float) -> None:
        self.within[robots] = p99_ms < BUDGET_MS

    @property
    def hi(self) -> int | None:
        over = [n for n, ok in self.within.items() if not ok]
        return min(over) if over else None

    @property
    def lo(self) -> int:
        hi = self.hi
        under = [n for n, ok in self.within.items() if ok and (hi is None or n < hi)]
        return max(under, default=0)

    def next(self) -> int | None:
        """The next round's robots, or None when the limit is found."""
        lo, hi = self.lo, self.hi
        if hi is None:
            return max(1, lo * self.factor)
        if hi - lo <= max(1, int(lo * self.resolution)):
            return None
        return (lo + hi) // 2


@dataclass
class Caps:
    """The safety caps: wall time (a deadline for the whole bench), memory (a share of what was
    available at the start) and, if given, most robots."""

    deadline: float  # time.monotonic()
    memory_mb: float
    most: int | None

    def refuse(
        self, n: int, rounds: list[dict[str, Any]], case_deadline: float
    ) -> tuple[str, int] | None:
        """Why a round of `n` robots is not started (and the robots it would have had), or
        None to go on."""
        if self.most is not None and n > self.most:
            if any(r["robots"] == self.most for r in rounds):
                return f"--max {self.most}", n
            return None
        if not rounds:
            return None
        last = max(rounds, key=lambda r: r["robots"])
        # a round's time: the processes' start and stop and the streams (fixed), their sources'
        # making (grows with the robots): scaled by the square root of the robots' ratio
        expected = last["wall_s"] * max(1.0, n / last["robots"]) ** 0.5
        if time.monotonic() + expected > case_deadline:
            left = max(0.0, case_deadline - time.monotonic())
            return f"time: about {expected:.0f} s for the next round, {left:.0f} s left", n
        expected_mb = memory_at(n, rounds)
        if expected_mb > self.memory_mb:
            return f"memory: about {expected_mb:.0f} MB, over {self.memory_mb:.0f} MB", n
        return None


def memory_at(n: int, rounds: list[dict[str, Any]]) -> float:
    """The processes' and this script's resident MB at `n` robots, extrapolated along the line
    through the smallest and the largest round so far (the processes' own memory is fixed; a
    robot adds its runs' and its source's)."""
    small, large = (min(rounds, key=lambda r: r["robots"]), max(rounds, key=lambda r: r["robots"]))
    mb = {k: float(r["rss_mb"] + r["sources_rss_mb"]) for k, r in (("s", small), ("l", large))}
    if large["robots"] == small["robots"]:
        return mb["l"]
    slope = max(0.0, (mb["l"] - mb["s"]) / float(large["robots"] - small["robots"]))
    return mb["l"] + slope * max(0, n - int(large["robots"]))


def each_robot(
    rounds: list[dict[str, Any]], search: Search, reference: dict[str, Any]
) -> dict[str, Any]:
    """The limit and, at it, what each robot costs: CPU (cores at the limit / robots, and per
    added robot), memory per added robot (RSS and PSS, from the case's one-robot round), and the
    ratio of one process set per robot (`reference`, same run) to those."""
    by = {r["robots"]: r for r in rounds}
    lo, hi = search.lo, search.hi
    # the smallest round over the budget (none when a cap stopped the search first)
    over = {
        "robots": hi,
        "description_p99_ms": None if hi is None else by[hi]["description_p99_ms"],
    }
    keys = ["description_p99_ms", "cores", "sources_cores", "rss_mb", "cores_per_robot"]
    keys += ["cores_per_added_robot", "mb_per_added_robot", "pss_mb_per_added_robot"]
    keys += ["robot_set_cores", "robot_set_mb", "robot_set_pss_mb"]
    keys += ["cpu_ratio", "memory_ratio", "pss_ratio"]
    out: dict[str, Any] = {"robots": lo, "first_over": over} | dict.fromkeys(keys)
    if lo == 0:  # the first round was over the budget: no figures at a limit
        return out
    at, one = by[lo], by[1]
    added = max(lo - 1, 1)
    mb = (at["rss_mb"] - one["rss_mb"]) / added if lo > 1 else None
    pss = (at["pss_mb"] - one["pss_mb"]) / added if lo > 1 else None
    cores = at["cores"] / lo
    out |= {
        "description_p99_ms": at["description_p99_ms"],
        "cores": at["cores"],
        "sources_cores": at["sources_cores"],
        "rss_mb": at["rss_mb"],
        "cores_per_robot": round(cores, 4),
        "cores_per_added_robot": round((at["cores"] - one["cores"]) / added, 4),
        "mb_per_added_robot": None if mb is None else round(mb, 2),
        "pss_mb_per_added_robot": None if pss is None else round(pss, 2),
        "robot_set_cores": reference["cores"],
        "robot_set_mb": reference["rss_mb"],
        "robot_set_pss_mb": reference["pss_mb"],
        "cpu_ratio": round(reference["cores"] / cores, 2) if cores > 0 else None,
        "memory_ratio": round(reference["rss_mb"] / mb, 1) if mb and mb > 0 else None,
        "pss_ratio": round(reference["pss_mb"] / pss, 1) if pss and pss > 0 else None,
    }
    return out


async def find_limit(
    args: argparse.Namespace, port: int, kind: str, caps: Caps, case_deadline: float
) -> tuple[list[dict[str, Any]], Search, str | None]:
    """A case's rounds, searched for the limit (`Search`) within the caps; the rounds by robots,
    the search, and the cap that stopped it (None when the limit was found)."""
    rounds: list[dict[str, Any]] = []
    search = Search(factor=4 if args.quick else 2, resolution=1 / 2 if args.quick else 1 / 8)
    tag = kind[0]
    stopped = None
    while (n := search.next()) is not None:
        if caps.most is not None and n > caps.most and caps.most not in search.within:
            n = caps.most
        refused = caps.refuse(n, rounds, case_deadline)
        if refused is not None:
            stopped = f"{refused[0]} (a round of {refused[1]} robots not started)"
            print(f"fleet: {KINDS[kind]}: stopped by the cap on {stopped}", file=sys.stderr)
            break
        hi = search.hi
        step = "doubling" if hi is None else f"bisecting {search.lo}..{hi}"
        print(f"fleet: {n} robot(s), {KINDS[kind]} ({step}) ...", file=sys.stderr, flush=True)
        fleet = BusConfig(robot="ws", robots=f"{tag}{n}-*", port=port)
        robots = [f"{tag}{n}-{k}" for k in range(n)]
        result = await measure(fleet, robots, args.gestures, kind, args.shards) | {"kind": kind}
        rounds.append(result)
        search.record(n, result["description_p99_ms"])
        print(json.dumps(result), file=sys.stderr, flush=True)
    return sorted(rounds, key=lambda r: r["robots"]), search, stopped


async def main_async(args: argparse.Namespace) -> dict[str, Any]:
    port = 17900 + os.getpid() % 1000
    start = time.monotonic()
    caps = Caps(
        deadline=start + args.minutes * 60,
        memory_mb=_available_mb() * args.memory_share,
        most=args.max,
    )
    result: dict[str, Any] = {"mode": "quick" if args.quick else "full", "gestures": args.gestures}
    result["shards"] = args.shards
    print("one process set for one robot ...", file=sys.stderr, flush=True)
    solo = BusConfig(robot="solo", port=port)
    result["single"] = await measure(solo, ["solo"], args.gestures)
    if "camera" in args.cases:
        print("one process set for one robot, with a camera ...", file=sys.stderr, flush=True)
        result["single_camera"] = await measure(solo, ["solo"], args.gestures, "camera")
    limits: dict[str, Any] = {}
    for left, kind in enumerate(args.cases):
        # the time left, shared among the cases left (a case that ends early leaves its share)
        share = (caps.deadline - time.monotonic()) / (len(args.cases) - left)
        rounds, search, stopped = await find_limit(args, port, kind, caps, time.monotonic() + share)
        result[ROUNDS[kind]] = rounds
        limits[kind] = each_robot(rounds, search, result[REFERENCE[kind]])
        limits[kind] |= {"stopped_by_cap": stopped, "lower_bound": stopped is not None}
        result[f"robots_within_33ms{'' if kind == 'own' else '_' + kind}"] = search.lo
    result["limits"] = limits
    result["wall_minutes"] = round((time.monotonic() - start) / 60, 1)
    return result


def print_table(result: dict[str, Any]) -> None:
    rows = [("one set, 1 robot", result["single"])]
    rows += [(f"fleet, {r['robots']} robot(s)", r) for r in result.get("fleet", [])]
    rows += [(f"fleet, {r['robots']} aligned", r) for r in result.get("fleet_aligned", [])]
    if "single_camera" in result:
        rows += [("one set, 1 robot, camera", result["single_camera"])]
    rows += [(f"fleet, {r['robots']} with camera", r) for r in result.get("fleet_camera", [])]
    print(
        f"{'':26} {'gestures':>8} {'p50 ms':>8} {'p99 ms':>8} {'RSS MB':>8} {'PSS MB':>8}"
        f" {'cores':>6} {'sources':>7}   p99 ms per stage: gestures reasoner describer"
        " | camera frames described, skipped"
    )
    for name, r in rows:
        st = r.get("stage_p99_ms")
        tail = (
            f"   {st['gestures']:>27.1f} {st['reasoner']:>8.1f} {st['describer']:>9.1f}"
            if st
            else f"   {'':>46} | {r['camera_frames_described']:>6} {r['camera_frames_skipped']:>6}"
        )
        print(
            f"{name:26} {r['gestures']:>8} {r['description_p50_ms']:>8.1f} "
            f"{r['description_p99_ms']:>8.1f} {r['rss_mb']:>8.0f} {r['pss_mb']:>8.0f} "
            f"{r['cores']:>6.2f} {r['sources_cores']:>7.2f}{tail}"
        )
    shards = result.get("shards", 1)
    each = f", {shards} shards per service" if shards > 1 else ""
    budget = f"description p99 < {BUDGET_MS:.1f} ms"
    print(f"\nthe limit: most robots with {budget} ({result['mode']}{each})")
    for kind, lim in result["limits"].items():
        over = lim["first_over"]
        line = f"  {KINDS[kind]}: {'at least ' if lim['lower_bound'] else ''}{lim['robots']}"
        if over["robots"] is not None:
            line += f" ({over['robots']}: p99 {over['description_p99_ms']:.1f} ms)"
        if lim["robots"]:
            mb, pss = lim["mb_per_added_robot"], lim["pss_mb_per_added_robot"]
            line += (
                f"; p99 {lim['description_p99_ms']:.1f} ms at {lim['cores']:.2f} cores;"
                f" each robot {lim['cores_per_robot']:.4f} cores"
                f" ({lim['cores_per_added_robot']:.4f} added),"
                f" {'-' if mb is None else f'{mb:.2f}'} MB RSS,"
                f" {'-' if pss is None else f'{pss:.2f}'} MB PSS added;"
                f" a process set per robot: {lim['robot_set_cores']:.3f} cores,"
                f" {lim['robot_set_mb']:.0f} MB RSS, {lim['robot_set_pss_mb']:.0f} MB PSS"
                f" (x{lim['cpu_ratio']} CPU, x{lim['memory_ratio']} RSS, x{lim['pss_ratio']} PSS)"
            )
        if lim["stopped_by_cap"]:
            line += f"; stopped by the cap on {lim['stopped_by_cap']}"
        print(line)
    print(f"wall time: {result['wall_minutes']} minutes")


def shards_option(text: str) -> int:
    try:
        return shard_count(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--quick", action="store_true",
        help="x4 steps, bisect to a half, 3 gestures per robot, 10-minute cap (about 10 minutes)",
    )  # fmt: skip
    parser.add_argument("--gestures", type=int, help="gestures per robot (default 6; 3 quick)")
    parser.add_argument(
        "--minutes", type=float, help="cap on wall time, all cases (default 90; 10 quick)"
    )
    parser.add_argument(
        "--memory-share", type=float, default=0.5,
        help="cap: share of the memory available at the start (default 0.5)",
    )  # fmt: skip
    parser.add_argument("--max", type=int, help="most robots tried (default: no cap)")
    parser.add_argument(
        "--shards", type=shards_option, default=1, metavar="N",
        help="each fleet service as N processes, by robot (beyond up --shards; auto: one per "
        "core this process may use; default 1); the one-robot reference stays one set",
    )  # fmt: skip
    parser.add_argument(
        "--cases", default="own,aligned,camera",
        help="cases searched, in order (default own,aligned,camera)",
    )  # fmt: skip
    parser.add_argument("--save", action="store_true", help="write bench/results/fleet.json")
    args = parser.parse_args()
    args.cases = [c for c in args.cases.split(",") if c]
    if not args.cases or set(args.cases) - set(KINDS):
        parser.error(f"--cases: {','.join(args.cases)!r}; valid: a list of {', '.join(KINDS)}")
    if args.gestures is None:
        args.gestures = 3 if args.quick else 6
    if args.minutes is None:
        args.minutes = 10 if args.quick else 90
    began, load = datetime.datetime.now(datetime.UTC), os.getloadavg()[0]
    result = asyncio.run(main_async(args))
    if args.save:
        how = (
            f" ({result['mode']} search, {result['gestures']} gestures per robot; "
            f"{result['wall_minutes']} minutes)"
        )
        results_file.save(
            "fleet", result, began, load, how=how, load_note="; it counts the fleet's own processes"
        )
    print_table(result)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
