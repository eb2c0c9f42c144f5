"""Foxglove bridge cost: what watching the demo live in Foxglove adds to the bus.

The demo's sensor streams (the skeleton at 30 Hz and the JPEG camera at 15 Hz of
recordings/tap-ball-grasp-box.mcap) are published at SPEED x real time by a child process that
plays the part of the pipeline's sensor service: each message restamped with the wall clock just
before `Publisher.put`. Two setups, REPEATS runs each, interleaved, medians reported:

- bus (the reference): a typed subscriber in another process (`Bus.subscribe`, as a service
  consumes them); latency = its receive time - the stamp;
- bridge: the same subscriber, plus `beyond foxglove` (the real command, its own process) and a
  WebSocket client (Python `websockets`, this process) subscribed to the skeleton key, the
  camera key and the 3D scene view; latency = the client's receive time - the stamp (the
  frame's log time is the stamp), so it includes the bridge's decoding, JSON encoding and the
  WebSocket hop;
- sdk (the reference for the handshake front, runtime/foxglove/front.py): the same, the client
  connected straight to foxglove-sdk's own port behind the front (read from its log), so the
  difference is what the front's extra loopback hop costs in latency and in the bridge's CPU.

Figures: one-way latency (median, p99) in both setups and the bridge's added median; the rate
each receiver sustained (messages delivered / s) against the rate published, and the fraction
delivered; the CPU time of the publishing process (the services' side) per second of publishing
with and without the bridge listening (goal: under 10% extra); the bridge process's own CPU
(share of one core).

Then the same question for the whole pipeline: `beyond up --rate SPEED` on the demo with and
without `--foxglove` (a client subscribed to the sensor keys and every view, as the shipped layout
is), summing the CPU time of every service process from the source's start to the end. The goal
(under 10% extra) is judged on this one: the sensor-publisher figure above is the worst case, a
process that does nothing but send what the bridge also receives. Ends with one JSON line.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import re
import resource
import statistics
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import msgspec  # noqa: E402
from websockets.asyncio.client import connect  # noqa: E402
from websockets.exceptions import ConnectionClosed  # noqa: E402

import beyond_self.schemas as s  # noqa: E402
from bench.bus import free_port, quantile  # noqa: E402
from beyond_self.runtime.bus.config import BusConfig  # noqa: E402
from beyond_self.runtime.bus.delivery import Delivery  # noqa: E402
from beyond_self.runtime.bus.session import Bus  # noqa: E402
from beyond_self.runtime.recording.reader import inspect_recording, read_recording  # noqa: E402
from beyond_self.services.launcher import BEYOND  # noqa: E402

DEMO = REPO / "recordings" / "tap-ball-grasp-box.mcap"
SPEED = 4.0
PASSES = 2  # of the 14.3 s demo: 7 s of publishing at 4x
REPEATS = 3
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


def cpu_of(pid: int) -> float:
    """CPU seconds (user + system) a process has used so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def env(config: BusConfig) -> dict[str, str]:
    e = dict(os.environ)
    e.update(BEYOND_ROBOT=config.robot, BEYOND_ZENOH_PORT=str(config.port), PYTHONPATH=str(REPO))
    e.pop("BEYOND_ZENOH_CONNECT", None)
    return e


# --- children ---------------------------------------------------------------------------------


def publish(config: BusConfig) -> None:
    """Publish the demo's sensors at SPEED, restamped; print CPU and count as JSON."""
    items = [r for r in read_recording(DEMO) if r.cls is not None]
    t0 = items[0].publish_time

    async def go() -> dict[str, float]:
        with Bus.open(config) as bus:
            pubs: dict[str, Any] = {}
            for item in items:
                if item.key not in pubs:
                    assert item.cls is not None
                    key = f"{bus.keys.root}/{item.key.split('/', 2)[2]}"
                    pubs[item.key] = bus.publisher(key, item.cls)
            for pub in pubs.values():
                await pub.wait_matching(timeout=30)
            messages = [(r.key, (r.publish_time - t0) / 1e9 / SPEED, r.message()) for r in items]
            span = messages[-1][1] + 1 / 30 / SPEED
            loop = asyncio.get_running_loop()
            usage0 = resource.getrusage(resource.RUSAGE_SELF)
            start = loop.time()
            sent = 0
            for p in range(PASSES):
                for key, at, message in messages:
                    delay = start + p * span + at - loop.time()
                    if delay > 0:
                        await asyncio.sleep(delay)
                    stamp = time.time_ns()
                    header = msgspec.structs.replace(message.header, seq=sent, stamp=stamp)
                    if isinstance(message, s.CompressedCameraFrame):
                        out: s.Message = msgspec.structs.replace(
                            message, header=header, timestamp=s.Time.from_ns(stamp)
                        )
                    else:
                        out = msgspec.structs.replace(message, header=header)
                    pubs[key].put(out)
                    sent += 1
            wall = loop.time() - start
            usage1 = resource.getrusage(resource.RUSAGE_SELF)
            cpu = (usage1.ru_utime - usage0.ru_utime) + (usage1.ru_stime - usage0.ru_stime)
            return {"sent": sent, "wall_s": wall, "cpu_s": cpu}

    print(json.dumps(asyncio.run(go())), flush=True)


def subscribe(config: BusConfig, expected: int) -> None:
    """Typed subscriber of skeleton and camera: latencies, as JSON, after `expected` messages."""

    async def go() -> dict[str, Any]:
        with Bus.open(config) as bus:
            subs = [
                bus.subscribe(bus.keys.skeleton, s.SkeletonFrame, Delivery(queue=1 << 14)),
                bus.subscribe(
                    bus.keys.camera_compressed, s.CompressedCameraFrame, Delivery(queue=4096)
                ),
            ]
            bus.declare_token(f"{bus.keys.root}/alive/bench-subscriber")
            latencies: list[int] = []
            first = last = 0
            done = asyncio.Event()

            async def drain(sub: Any) -> None:
                nonlocal first, last
                while True:
                    got = await sub.recv()
                    now = time.time_ns()
                    first = first or now
                    last = now
                    latencies.append(now - got.message.header.stamp)
                    if len(latencies) >= expected:
                        done.set()

            tasks = [asyncio.create_task(drain(sub)) for sub in subs]
            with contextlib.suppress(TimeoutError):  # then a delivered fraction below 1
                await asyncio.wait_for(done.wait(), 120)
            for task in tasks:
                task.cancel()
            return {"latencies": latencies, "span_s": (last - first) / 1e9}

    print(json.dumps(asyncio.run(go())), flush=True)


# --- orchestration ---------------------------------------------------------------------------


def child(role: str, config: BusConfig, *extra: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, __file__, "--role", role, str(config.port), config.robot, *extra],
        stdout=subprocess.PIPE,
        text=True,
        env=env(config),
    )


async def wait_alive(bus: Bus, name: str) -> None:
    await bus.wait_alive(f"{bus.keys.root}/alive/{name}", timeout=60)


async def client(port: int, topics: list[str], ready: asyncio.Event, stop: asyncio.Event) -> Any:
    """Foxglove WebSocket client: subscribes to `topics`, records latency of every message."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + 60
    while True:
        try:
            ws = await connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS, max_size=None)
            break
        except OSError:
            if loop.time() > deadline:
                raise
            await asyncio.sleep(0.05)
    latencies: list[int] = []
    first = last = 0
    channels: dict[str, int] = {}
    async with ws:
        while not stop.is_set():
            try:
                frame = await asyncio.wait_for(ws.recv(), 0.5)
            except TimeoutError:
                continue
            except ConnectionClosed:  # the server stopped (`beyond up` is done)
                break
            if isinstance(frame, str):
                op = json.loads(frame)
                if op["op"] == "advertise":
                    channels.update({c["topic"]: c["id"] for c in op["channels"]})
                    if not ready.is_set() and set(topics) <= set(channels):
                        subs = [{"id": i, "channelId": channels[t]} for i, t in enumerate(topics)]
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                        ready.set()
                continue
            now = time.time_ns()
            _, _, stamp = struct.unpack_from("<BIQ", frame)
            json.loads(frame[13:])  # what any client does with it
            first = first or now
            last = now
            latencies.append(now - stamp)
    return {"latencies": latencies, "span_s": (last - first) / 1e9}


def expected_messages() -> int:
    return PASSES * sum(1 for r in read_recording(DEMO) if r.cls is not None)


def sdk_port(bridge: subprocess.Popen[str]) -> int:
    """foxglove-sdk's own port inside `beyond foxglove` (its DEBUG log says), then its log
    drained."""
    assert bridge.stderr is not None
    for line in bridge.stderr:
        found = re.search(r"foxglove-sdk server behind the front on 127\.0\.0\.1:(\d+)", line)
        if found:
            threading.Thread(target=bridge.stderr.read, daemon=True).start()
            return int(found.group(1))
    raise RuntimeError("beyond foxglove ended before its server started")


async def run_once(setup: str) -> dict[str, float]:
    """One run of `setup`: "bus", "bridge" (through the front) or "sdk" (straight to the SDK)."""
    with_bridge = setup != "bus"
    config = BusConfig(robot=f"fx{os.getpid()}{setup}{time.time_ns() % 10**6}")
    config = config.with_(port=free_port())
    n = expected_messages()
    procs: list[subprocess.Popen[str]] = []
    result: dict[str, float] = {}
    with Bus.open(config) as bus:
        sub = child("subscribe", config, str(n))
        procs.append(sub)
        await wait_alive(bus, "bench-subscriber")
        bridge = None
        stop, ready = asyncio.Event(), asyncio.Event()
        watcher = None
        if with_bridge:
            ws_port = free_port()
            bridge = subprocess.Popen(
                [*BEYOND, "foxglove", "--ws-port", str(ws_port)],
                env={**env(config), "BEYOND_LOG_LEVEL": "DEBUG"},
                stderr=subprocess.PIPE,
                text=True,
            )
            procs.append(bridge)
            inner = await asyncio.to_thread(sdk_port, bridge)  # and its log drained
            if setup == "sdk":
                ws_port = inner
            root = bus.keys.root
            topics = [bus.keys.skeleton, bus.keys.camera_compressed, f"{root}/foxglove/scene"]
            watcher = asyncio.create_task(client(ws_port, topics, ready, stop))
            await asyncio.wait_for(ready.wait(), 60)
            await wait_alive(bus, "foxglove")  # its bus subscriber is declared
        try:
            bridge_cpu0 = cpu_of(bridge.pid) if bridge else 0.0
            pub = child("publish", config)
            procs.append(pub)
            out, _ = await asyncio.to_thread(pub.communicate, timeout=120)
            sent = json.loads(out)
            bridge_cpu = (cpu_of(bridge.pid) - bridge_cpu0) if bridge else 0.0
            got, _ = await asyncio.to_thread(sub.communicate, timeout=60)
            received = json.loads(got)
            if watcher is not None:
                await asyncio.sleep(0.5)  # let the last WebSocket frames in (not a measurement)
                stop.set()
                seen = await watcher
        finally:
            for p in procs:
                if p.poll() is None:
                    p.terminate()
                    p.wait(timeout=20)
    lat = received["latencies"]
    result.update(
        published_per_s=sent["sent"] / sent["wall_s"],
        publisher_cpu_per_s=sent["cpu_s"] / sent["wall_s"],
        bus_delivered_fraction=len(lat) / sent["sent"],
        bus_latency_median_us=statistics.median(lat) / 1e3,
        bus_latency_p99_us=quantile(lat, 0.99) / 1e3,
    )
    if with_bridge:
        wl = seen["latencies"]
        skeletons = sum(1 for r in read_recording(DEMO) if r.key.endswith("skeleton"))
        result.update(
            bridge_cpu_share_of_core=bridge_cpu / sent["wall_s"],
            # the client gets every sensor message plus one scene per skeleton frame
            bridge_delivered_fraction=len(wl) / (sent["sent"] + PASSES * skeletons),
            bridge_delivered_per_s=len(wl) / seen["span_s"] if seen["span_s"] else 0.0,
            bridge_latency_median_us=statistics.median(wl) / 1e3 if wl else float("nan"),
            bridge_latency_p99_us=quantile(wl, 0.99) / 1e3,
        )
    return result


# --- the whole pipeline: `beyond up` at SPEED with and without --foxglove --------------------


def descendants(pid: int) -> list[int]:
    found, todo = [], [pid]
    while todo:
        current = todo.pop()
        for task in Path(f"/proc/{current}/task").glob("*"):
            with contextlib.suppress(OSError):
                kids = [int(k) for k in (task / "children").read_text().split()]
                found += kids
                todo += kids
    return found


async def pipeline_once(with_bridge: bool) -> dict[str, float]:
    """Services' CPU during one replay of the demo by `beyond up` (each service its own
    process), from when the source is about to start to the end; with the bridge, a WebSocket
    client watches the sensor keys and every view, as the shipped layout does."""
    config = BusConfig(robot=f"fp{os.getpid()}{int(with_bridge)}{time.time_ns() % 10**6}")
    config = config.with_(port=free_port())
    ws_port = free_port()
    cmd = [
        *BEYOND,
        "up",
        "--recording",
        str(DEMO),
        "--rate",
        str(SPEED),
    ]
    cmd += ["--no-live", "--wait-for", "benchclient", "--timeout", "120"]
    if with_bridge:
        cmd += ["--foxglove", str(ws_port)]
    log = tempfile.TemporaryFile("w+")  # noqa: SIM115 (closed below, after the process)
    up = subprocess.Popen(cmd, env=env(config), stdout=log, stderr=subprocess.STDOUT)
    cpu: dict[int, float] = {}
    base: dict[int, float] = {}
    stop, ready = asyncio.Event(), asyncio.Event()
    watcher = None
    try:
        with Bus.open(config) as bus:
            root = bus.keys.root
            if with_bridge:
                topics = [bus.keys.skeleton, bus.keys.camera_compressed] + [
                    f"{root}/foxglove/{v}"
                    for v in ("scene", "objects", "posterior", "affordance", "log")
                ]
                watcher = asyncio.create_task(client(ws_port, topics, ready, stop))
                await asyncio.wait_for(ready.wait(), 90)
            await bus.wait_alive(bus.keys.alive("ingest"), timeout=90)
            for pid in descendants(up.pid):
                with contextlib.suppress(OSError):
                    base[pid] = cpu_of(pid)
            descriptions = bus.subscribe(bus.keys.description, s.Description)
            gestures = len(json.loads(inspect_recording(DEMO).metadata["beyond"]["truth"]))
            described: set[int] = set()
            start = time.monotonic()
            bus.declare_token(bus.keys.alive("benchclient"))
            # until the last gesture's final description: the shutdown that follows is not
            # the pipeline's work (and a service slow to stop would blur the figure)
            while up.poll() is None and len(described) < gestures:
                for pid in descendants(up.pid):
                    with contextlib.suppress(OSError):
                        cpu[pid] = cpu_of(pid)
                with contextlib.suppress(TimeoutError):
                    got = await descriptions.recv(0.1)
                    if got.message.final:
                        described.add(got.message.segment_id)
            wall = time.monotonic() - start
            for pid in descendants(up.pid):
                with contextlib.suppress(OSError):
                    cpu[pid] = cpu_of(pid)
            await asyncio.to_thread(up.wait, 120)
            stop.set()
            seen = await watcher if watcher is not None else {"latencies": []}
    finally:
        if up.poll() is None:
            up.terminate()
            up.wait(timeout=30)
    if up.returncode != 0:
        log.seek(0)
        tail = log.read().strip().splitlines()[-3:]
        print(f"beyond up exited {up.returncode}: {' | '.join(tail)}", file=sys.stderr)
    log.close()
    services = sum(cpu[p] - base.get(p, 0.0) for p in cpu)
    return {
        "status": float(up.returncode),
        "services_cpu_s": services,
        "wall_s": wall,
        "described": float(len(described)),
        "gestures": float(gestures),
        "client_messages": float(len(seen["latencies"])),
    }


def median_of(runs: list[dict[str, float]]) -> dict[str, float]:
    return {k: statistics.median(r[k] for r in runs) for k in runs[0]}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--role", nargs="+", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role:
        role, port, robot, *extra = args.role
        config = BusConfig(robot=robot, port=int(port))
        if role == "publish":
            publish(config)
        else:
            subscribe(config, int(extra[0]))
        return 0
    runs: dict[str, list[dict[str, float]]] = {"bus": [], "bridge": [], "sdk": []}
    for _ in range(REPEATS):
        for setup in runs:
            runs[setup].append(asyncio.run(run_once(setup)))
    pipe: dict[bool, list[dict[str, float]]] = {False: [], True: []}
    for _ in range(REPEATS):
        for with_bridge in (False, True):
            pipe[with_bridge].append(asyncio.run(pipeline_once(with_bridge)))
    plain, watched = median_of(pipe[False]), median_of(pipe[True])
    pipeline_extra = watched["services_cpu_s"] / plain["services_cpu_s"] - 1
    bus, bridge, sdk = median_of(runs["bus"]), median_of(runs["bridge"]), median_of(runs["sdk"])
    extra_cpu = bridge["publisher_cpu_per_s"] / bus["publisher_cpu_per_s"] - 1
    figures = {
        "speed": SPEED,
        "published_per_s": bus["published_per_s"],
        "bus_latency_median_us": bus["bus_latency_median_us"],
        "bus_latency_p99_us": bus["bus_latency_p99_us"],
        "bus_delivered_fraction": bus["bus_delivered_fraction"],
        "bridge_latency_median_us": bridge["bridge_latency_median_us"],
        "bridge_latency_p99_us": bridge["bridge_latency_p99_us"],
        "bridge_added_latency_median_us": bridge["bridge_latency_median_us"]
        - bus["bus_latency_median_us"],
        "bridge_delivered_fraction": bridge["bridge_delivered_fraction"],
        "bridge_delivered_per_s": bridge["bridge_delivered_per_s"],
        "bus_latency_median_us_with_bridge": bridge["bus_latency_median_us"],
        "services_cpu_per_s_without_bridge": bus["publisher_cpu_per_s"],
        "services_cpu_per_s_with_bridge": bridge["publisher_cpu_per_s"],
        "services_extra_cpu_ratio": extra_cpu,
        "bridge_cpu_share_of_core": bridge["bridge_cpu_share_of_core"],
        "sdk_direct_latency_median_us": sdk["bridge_latency_median_us"],
        "sdk_direct_bridge_cpu_share_of_core": sdk["bridge_cpu_share_of_core"],
        "front_added_latency_median_us": bridge["bridge_latency_median_us"]
        - sdk["bridge_latency_median_us"],
        "front_added_cpu_share_of_core": bridge["bridge_cpu_share_of_core"]
        - sdk["bridge_cpu_share_of_core"],
        "pipeline_runs_exit_0": sum(r["status"] == 0 for r in pipe[False] + pipe[True]),
        "pipeline_runs": 2 * REPEATS,
        "pipeline_all_described": all(
            r["described"] == r["gestures"] for r in pipe[False] + pipe[True]
        ),
        "pipeline_services_cpu_s_without_bridge": plain["services_cpu_s"],
        "pipeline_services_cpu_s_with_bridge": watched["services_cpu_s"],
        "pipeline_services_extra_cpu_ratio": pipeline_extra,
        "pipeline_client_messages": watched["client_messages"],
        "goal_keeps_up_at_4x": bridge["bridge_delivered_fraction"] >= 0.999,
        "goal_extra_cpu_under_10pct": pipeline_extra < 0.10,
    }
    print(
        f"demo sensors at {SPEED:g}x ({bus['published_per_s']:.0f} msg/s), "
        f"median of {REPEATS} interleaved runs:"
    )
    print(
        f"  bus only:    latency median {bus['bus_latency_median_us']:.0f} us, "
        f"p99 {bus['bus_latency_p99_us']:.0f} us, delivered {bus['bus_delivered_fraction']:.3f}"
    )
    print(
        f"  via bridge:  latency median {bridge['bridge_latency_median_us']:.0f} us "
        f"(+{figures['bridge_added_latency_median_us']:.0f} us), "
        f"p99 {bridge['bridge_latency_p99_us']:.0f} us, "
        f"delivered {bridge['bridge_delivered_fraction']:.3f} "
        f"({bridge['bridge_delivered_per_s']:.0f} msg/s)"
    )
    print(
        f"  services' CPU: {bus['publisher_cpu_per_s'] * 100:.1f}% of a core without the bridge, "
        f"{bridge['publisher_cpu_per_s'] * 100:.1f}% with it ({extra_cpu * 100:+.1f}%); "
        f"the bridge itself {bridge['bridge_cpu_share_of_core'] * 100:.1f}%"
    )
    print(
        f"  straight to foxglove-sdk's port (no handshake front): latency median "
        f"{sdk['bridge_latency_median_us']:.0f} us, the bridge "
        f"{sdk['bridge_cpu_share_of_core'] * 100:.1f}% of a core; the front adds "
        f"{figures['front_added_latency_median_us']:+.0f} us and "
        f"{figures['front_added_cpu_share_of_core'] * 100:+.1f} points of a core"
    )
    print(
        f"  whole pipeline (beyond up at {SPEED:g}x, services' CPU during the replay): "
        f"{plain['services_cpu_s']:.2f} s without the bridge, {watched['services_cpu_s']:.2f} s "
        f"with it and a client watching every view ({pipeline_extra * 100:+.1f}%)"
    )
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
