"""The Foxglove bridge seen by clients nobody here wrote: Python `websockets` speaking the
Foxglove WebSocket protocol to `beyond up --foxglove` while it replays a recording, with every
message checked against the official Foxglove JSON Schemas (`@foxglove/schemas`, from npm); and
the npm client `@foxglove/ws-protocol` with its defaults.

The protocol has two names: foxglove.sdk.v1, the only one foxglove-sdk 0.30's server accepts,
and foxglove.websocket.v1, the only one the npm client offers; the first client offers both, as
the Foxglove app does, the npm client only its own (runtime/foxglove/front.py)."""

from __future__ import annotations

import asyncio
import json
import os
import socket
import struct
import subprocess
from pathlib import Path
from typing import Any

import jsonschema
from busutil_net import REPO, env_for, free_port, private_config
from third_party_readers import official_schemas
from websockets.asyncio.client import connect

import beyond_self.schemas as s
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.foxglove.bridge import FoxgloveBridge
from beyond_self.services.launcher import BEYOND

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
RECORDING = REPO / "recordings" / "touch-box.mcap"
NPM_CLIENT = REPO / "tests" / "js" / "foxglove_client.js"


async def connect_when_up(port: int, proc: asyncio.subprocess.Process) -> Any:
    """The server starts inside `beyond up`: try until it accepts (or `up` died)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + 60
    while True:
        try:
            return await connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS, max_size=None)
        except OSError:
            if proc.returncode is not None or loop.time() > deadline:
                raise
            await asyncio.sleep(0.1)


async def test_websocket_client_gets_valid_foxglove_messages_during_a_replay(
    node_modules: Path,
) -> None:
    official = official_schemas(node_modules)
    config = private_config()
    port = free_port()
    root = f"beyond/{config.robot}"
    wanted = {
        f"{root}/sensors/camera/compressed": "CompressedImage",
        f"{root}/foxglove/scene": "SceneUpdate",
        f"{root}/foxglove/log": "Log",
        f"{root}/foxglove/objects": "ImageAnnotations",
        f"{root}/foxglove/posterior": None,  # ours: checked against its advertised schema
    }
    proc = await asyncio.create_subprocess_exec(
        *BEYOND,
        "up",
        "--recording",
        str(RECORDING),
        "--no-live",
        "--foxglove",
        str(port),
        "--wait-for",
        "fxclient",
        env=env_for(config),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.DEVNULL,
    )
    got: dict[str, list[tuple[int, dict[str, Any]]]] = {topic: [] for topic in wanted}
    advertised: dict[int, dict[str, Any]] = {}
    by_sub: dict[int, str] = {}
    try:
        with Bus.open(config) as bus:
            ws = await connect_when_up(port, proc)
            assert ws.subprotocol in SUBPROTOCOLS
            subscribed = False
            while not got[f"{root}/foxglove/log"]:
                frame = await asyncio.wait_for(ws.recv(), 90)
                if isinstance(frame, str):
                    op = json.loads(frame)
                    if op["op"] == "advertise":
                        advertised.update({c["id"]: c for c in op["channels"]})
                    topics = {c["topic"]: c["id"] for c in advertised.values()}
                    if not subscribed and set(wanted) <= set(topics):
                        subs = [{"id": i, "channelId": topics[t]} for i, t in enumerate(wanted)]
                        by_sub = {i: t for i, t in enumerate(wanted)}
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                        subscribed = True
                        bus.declare_token(bus.keys.alive("fxclient"))  # now play
                    continue
                opcode, sub_id, log_time = struct.unpack_from("<BIQ", frame)
                assert opcode == 1
                got[by_sub[sub_id]].append((log_time, json.loads(frame[13:])))
            await ws.close()
        out, _ = await asyncio.wait_for(proc.communicate(), 90)
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()
    assert proc.returncode == 0, out.decode()[-2000:]
    schemas = {c["topic"]: c for c in advertised.values()}
    for topic, name in wanted.items():
        assert got[topic], f"nothing on {topic}"
        own = json.loads(schemas[topic]["schema"])
        checks = [jsonschema.Draft202012Validator(own)]
        if name:
            assert schemas[topic]["schemaName"] == f"foxglove.{name}"
            checks.append(jsonschema.Draft202012Validator(official[name]))
        for _, message in got[topic]:
            for check in checks:
                check.validate(message)
    for log_time, update in got[f"{root}/foxglove/scene"]:
        (entity,) = update["entities"]
        stamp = entity["timestamp"]
        assert stamp["sec"] * 10**9 + stamp["nsec"] == log_time  # on the recording's clock
        assert len(entity["spheres"]) == 9 and len(entity["lines"][0]["points"]) == 16
    for log_time, image in got[f"{root}/sensors/camera/compressed"]:
        stamp = image["timestamp"]
        assert stamp["sec"] * 10**9 + stamp["nsec"] == log_time and image["format"] == "jpeg"
    (line,) = [m for _, m in got[f"{root}/foxglove/log"]]
    assert "touched" in line["message"] and line["level"] == 2
    assert "the robot touched" in out.decode()


def test_port_in_use_is_one_line_and_exit_2() -> None:
    config = private_config()
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        done = subprocess.run(
            [*BEYOND, "foxglove", "--ws-port", str(port)],
            env=env_for(config),
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and f"127.0.0.1:{port}" in lines[0] and "--ws-port" in lines[0]


async def test_the_npm_client_connects_with_its_defaults(node_modules: Path) -> None:
    """@foxglove/ws-protocol offers only foxglove.websocket.v1: accepted under that name, it
    subscribes and reads a message exactly (stamps as Foxglove Time, log time = the stamp)."""
    stamp = 1_546_300_801_433_333_333
    header = s.Header(version=s.Description.VERSION, source="t", seq=1, stamp=stamp)
    sentence = s.ScoredSentence(text="the robot tapped the ball", score=-0.5)
    description = s.Description(
        header=header, segment_id=1, sentences=[sentence], evidence=s.Evidence()
    )
    with Bus.open(private_config()) as bus:
        bridge = FoxgloveBridge(bus, port=0)
        stop, ready = asyncio.Event(), asyncio.Event()
        serving = asyncio.create_task(bridge.run(stop, ready))
        try:
            await asyncio.wait_for(ready.wait(), 30)
            node = await asyncio.create_subprocess_exec(
                *("node", str(NPM_CLIENT), f"ws://127.0.0.1:{bridge.port}", bus.keys.description),
                env={**os.environ, "NODE_PATH": str(node_modules)},
                stdout=asyncio.subprocess.PIPE,
            )
            pub = bus.publisher(bus.keys.description, s.Description)
            output = asyncio.ensure_future(node.communicate())
            while not output.done():  # until the client has subscribed and heard one
                pub.put(description)
                await asyncio.wait([output], timeout=0.2)
            printed, _ = output.result()
        finally:
            stop.set()
            await serving
            bridge.close()
    report = json.loads(printed)
    assert node.returncode == 0, report
    assert report["offered"] == report["subprotocol"] == "foxglove.websocket.v1"
    assert report["schemaName"] == "beyond.Description"
    got = report["message"]
    assert got["header"]["stamp"] == {"sec": stamp // 10**9, "nsec": stamp % 10**9}
    assert int(report["logTime"]) == stamp
    assert got["sentences"][0]["text"] == "the robot tapped the ball"
