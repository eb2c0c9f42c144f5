"""How many robots one workstation serves: one process per service for a fleet (runtime/fleet.py)
next to one process set per robot, measured in the same run.

    .venv/bin/python bench/fleet.py [--max N] [--gestures G]

Skeleton only (no vision: the gesture streamer, the affordance reasoner and the description
generator; the reasoner told there is no object segmenter). Each round, N robots appear (this
script declares each robot's source token and publishes its 30 Hz skeleton stream live, at real
time, all N at once, phases spread over a frame), the workstation's fleet processes start a run
for each, and per gesture the clock starts when the frame that lets the segmenter decide the
gesture is over is published (found offline by the same segmenter, bench/pipeline.py) and stops
when the gesture's description is taken off Zenoh for that robot. Every gesture that ended must
be described, or the bench fails.

Two kinds of rounds: a person each (each robot its own synthetic person, a seed each: gestures
of their own lengths at their own times, as in a lab), and aligned (every robot the same stream,
so every robot's gestures end within one frame of each other and each stage gets N gestures at
once: the worst case). Rounds double N (1, 2, 4, ...) until the description's p99 reaches 33 ms
(a frame at 30 Hz) or N reaches --max, then one round halfway back; the robots of a round leave
before the next (their runs are dropped).

Costs: resident memory (VmRSS) of the processes, summed, and their CPU time over the round
(cores); next to them the same three services as one process set for one robot (`beyond up`'s
way before fleets), started and measured in the same run with one robot: N robots that way
cost N of those; and the CPU of this script itself (the robots' simulated sources and its
observers, which a real fleet would not run on the workstation: `sources_cores`). Where the
time goes: per stage, the p99 of the time from the gesture's deciding
frame to its end event leaving the gesture streamer, from there to its words leaving the
reasoner, and from there to the description (each message's arrival taken off Zenoh, wall
clock).

With a camera: the same rounds with the object segmenter in the fleet too, each robot its own
simulated scene (skeleton at 30 Hz and 15 fps JPEG frames, a seed and a gesture order each;
`beyond simulate`) published at real time; per gesture, from the last input its description
needs (the later of the skeleton frame that ends it and the first camera frame after its end,
found offline by the same tracker) to its description, next to one process set for one robot;
and how many camera frames the object segmenter described and skipped (a live source sheds
per-frame work under overload, never a gesture's). Ends with one line of JSON.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import functools
import json
import os
import sys
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))  # the pipeline bench's skeleton stream and figures

from pipeline import CAMERA, QUIET, _p, scene_gestures, stream_frames, vision_scene  # noqa: E402

import beyond_self.schemas as s  # noqa: E402
from beyond_self.runtime.bus.config import BusConfig  # noqa: E402
from beyond_self.runtime.bus.delivery import EVENTS  # noqa: E402
from beyond_self.runtime.bus.session import Bus  # noqa: E402
from beyond_self.runtime.fleet import LEAVE_ENV  # noqa: E402
from beyond_self.runtime.recording.replay import restamped  # noqa: E402
from beyond_self.schemas.keys import for_robots, split_key  # noqa: E402
from beyond_self.services.deployment import Deployment  # noqa: E402

SERVICES = ["gestures", "reasoner", "describer"]
OPTIONS = {"reasoner": {"objects": False}}
CAMERA_SERVICES = ["gestures", "objects", "reasoner", "describer"]
FRAME_NS = 33_333_333
BUDGET_MS = 1e3 / 30


def process_cost(pids: list[int]) -> tuple[float, float]:
    """(resident MB, CPU seconds so far) of processes `pids` and their children."""
    rss_kb, ticks = 0, 0
    for pid in _with_children(pids):
        with contextlib.suppress(OSError):
            status = Path(f"/proc/{pid}/status").read_text()
            rss_kb += int(next(x for x in status.splitlines() if x.startswith("VmRSS")).split()[1])
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            ticks += int(fields[11]) + int(fields[12])  # utime, stime
    return rss_kb / 1024, ticks / os.sysconf("SC_CLK_TCK")


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


@functools.cache
def robot_stream(seed: int, gestures: int) -> tuple[list[s.SkeletonFrame], list[int]]:
    return stream_frames(seed=seed, gestures=gestures)


def streams_for(
    n: int, gestures: int, aligned: bool
) -> list[tuple[list[s.SkeletonFrame], list[int]]]:
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
    try:
        for v in views:
            for name in services:
                await bus.wait_alive(v.keys.alive(name), timeout=60)
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


async def serve(
    bus: Bus, robots: list[str], streams: list[tuple[list[s.SkeletonFrame], list[int]]]
) -> dict[str, Any]:
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
        for pub in pubs:
            await pub.wait_matching(timeout=30)
        longest = max(len(frames) for frames, _ in streams)
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
                frames = streams[k][0]
                if i >= len(frames):
                    continue
                at = begin_wall + (i + k / len(robots)) * FRAME_NS / 1e9
                delay = at - loop.time()
                if delay > 0:
                    await asyncio.sleep(delay)
                stamp = begin_ns + i * FRAME_NS + k * FRAME_NS // len(robots)
                header = s.Header(version=1, source="bench", seq=i, stamp=stamp)
                frame = frames[i]
                pub.put(s.SkeletonFrame(header=header, frame=frame.frame, joints=frame.joints))
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
                end = sent[k][min(t for t in streams[k][1] if t >= last)]
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
        for pair in pubs:
            for pub in pair:
                await pub.wait_matching(timeout=30)
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
    config: BusConfig, robots: list[str], gestures: int, kind: str = "own"
) -> dict[str, Any]:
    """The services on `config` (a fleet's, or one robot's own set) serving `robots`: each
    its own person (`own`), all the same (`aligned`), or with a camera (`camera`)."""
    services, options = (CAMERA_SERVICES, {}) if kind == "camera" else (SERVICES, OPTIONS)
    side = Deployment(config, services, options=options, env={**QUIET, LEAVE_ENV: "1"})
    try:
        bus = await side.open()
        await side.start()
        pids = [sp.process.pid for sp in side.processes]
        _, cpu0 = process_cost(pids)
        bench0 = _own_cpu_s()
        if kind == "camera":
            served = await serve_camera(bus, robots)
        else:
            streams = streams_for(len(robots), gestures, kind == "aligned")
            served = await serve(bus, robots, streams)
        rss, cpu1 = process_cost(pids)
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
        "cores": round((cpu1 - cpu0) / served["stream_s"], 3),
        # the robots' simulated sources and the bench's observers, on the same 2 cores (a real
        # robot publishes from its own machine)
        "sources_cores": round(bench_s / served["stream_s"], 3),
    }
    if "stages_ms" in served:
        result["stage_p99_ms"] = {k: round(_p(v, 99), 2) for k, v in served["stages_ms"].items()}
    if "camera_frames" in served:
        result["camera_frames_described"] = served["camera_frames"]["described"]
        result["camera_frames_skipped"] = served["camera_frames"]["skipped"]
    return result


KINDS = {
    "own": "a person each",
    "aligned": "the same stream, aligned",
    "camera": "a person each, with a 15 fps camera",
}


async def rounds_of(args: argparse.Namespace, port: int, kind: str) -> list[dict[str, Any]]:
    """Fleet rounds of 1, 2, 4, ... robots until the description's p99 reaches a frame or N
    reaches --max; after the first round over the budget, one round halfway back."""
    rounds: list[dict[str, Any]] = []
    tag = kind[0]
    n, over = 1, None
    while n <= args.max:
        print(f"fleet: {n} robot(s), {KINDS[kind]} ...", file=sys.stderr, flush=True)
        fleet = BusConfig(robot="ws", robots=f"{tag}{n}-*", port=port)
        robots = [f"{tag}{n}-{k}" for k in range(n)]
        result = await measure(fleet, robots, args.gestures, kind) | {"kind": kind}
        rounds.append(result)
        print(json.dumps(result), file=sys.stderr, flush=True)
        if over is not None:
            break
        if result["description_p99_ms"] >= BUDGET_MS:
            over = n
            if n < 4:
                break
            n = 3 * n // 4  # halfway back from the round over the budget
            continue
        n *= 2
    return sorted(rounds, key=lambda r: r["robots"])


def within_budget(rounds: list[dict[str, Any]]) -> int:
    """Most robots of a round under the budget with no smaller round over it."""
    best = 0
    for r in rounds:
        if r["description_p99_ms"] >= BUDGET_MS:
            break
        best = r["robots"]
    return best


async def main_async(args: argparse.Namespace) -> dict[str, Any]:
    port = 17900 + os.getpid() % 1000
    print("one process set for one robot ...", file=sys.stderr, flush=True)
    reference = await measure(BusConfig(robot="solo", port=port), ["solo"], args.gestures)
    own = await rounds_of(args, port, "own")
    aligned = await rounds_of(args, port, "aligned")
    print("one process set for one robot, with a camera ...", file=sys.stderr, flush=True)
    solo = BusConfig(robot="solo", port=port)
    camera_reference = await measure(solo, ["solo"], args.gestures, "camera")
    camera = await rounds_of(args, port, "camera")
    return {
        "single": reference,
        "fleet": own,
        "fleet_aligned": aligned,
        "single_camera": camera_reference,
        "fleet_camera": camera,
        "robots_within_33ms": within_budget(own),
        "robots_within_33ms_aligned": within_budget(aligned),
        "robots_within_33ms_camera": within_budget(camera),
    }


def print_table(result: dict[str, Any]) -> None:
    rows = [("one set, 1 robot", result["single"])]
    rows += [(f"fleet, {r['robots']} robot(s)", r) for r in result["fleet"]]
    rows += [(f"fleet, {r['robots']} aligned", r) for r in result["fleet_aligned"]]
    rows += [("one set, 1 robot, camera", result["single_camera"])]
    rows += [(f"fleet, {r['robots']} with camera", r) for r in result["fleet_camera"]]
    print(
        f"{'':26} {'gestures':>8} {'p50 ms':>8} {'p99 ms':>8} {'RSS MB':>8} {'cores':>6}"
        f" {'sources':>7}   p99 ms per stage: gestures reasoner describer"
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
            f"{r['description_p99_ms']:>8.1f} {r['rss_mb']:>8.0f} {r['cores']:>6.2f} "
            f"{r['sources_cores']:>7.2f}{tail}"
        )
    single = result["single"]
    best = max(result["fleet"], key=lambda r: r["robots"])
    if best["robots"] > 1:
        base = result["fleet"][0]
        per_robot_mb = (best["rss_mb"] - base["rss_mb"]) / (best["robots"] - 1)
        per_robot_cores = (best["cores"] - base["cores"]) / (best["robots"] - 1)
        print(
            f"each robot more: {per_robot_mb:.1f} MB and {per_robot_cores:.3f} cores in the "
            f"fleet's processes, against {single['rss_mb']:.0f} MB and {single['cores']:.3f} "
            "cores for a process set of its own"
        )
    print(
        f"robots served with description p99 < {BUDGET_MS:.0f} ms: "
        f"{result['robots_within_33ms']} (a person each), "
        f"{result['robots_within_33ms_aligned']} (all gestures ending within one frame), "
        f"{result['robots_within_33ms_camera']} (a person each, with a 15 fps camera)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--max", type=int, default=64, help="most robots tried (default 64)")
    parser.add_argument("--gestures", type=int, default=6, help="gestures per robot (default 6)")
    args = parser.parse_args()
    result = asyncio.run(main_async(args))
    print_table(result)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
