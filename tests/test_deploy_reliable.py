"""The pieces a two-machine deployment stands on, checked fast on one machine: publisher caches
and recovering subscriptions (runtime.bus.delivery, runtime.bus.recovery), routers joined in
addition to
the local group (runtime.bus.config), and how `beyond up` hands that to the processes it starts."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import msgspec
import pytest
from busutil_net import private_config, skeleton_frames

import beyond_self.schemas as s
from beyond_self.commands.up_services import wait_list
from beyond_self.commands.up_side import local_group, monitor_name
from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.config import BusConfig, load_config, zenoh_config
from beyond_self.runtime.bus.delivery import FRAMES, Delivery
from beyond_self.runtime.bus.session import Bus
from beyond_self.services.launcher import service_env

REPO = Path(__file__).resolve().parent.parent


async def _drain(sub, n: int, timeout: float = 10.0) -> list[int]:  # type: ignore[no-untyped-def]
    return [(await sub.recv(timeout=timeout)).message.frame for _ in range(n)]


async def test_a_late_subscriber_gets_the_cached_history_in_order_and_counts_it() -> None:
    config = private_config()
    frames = skeleton_frames(30)
    with Bus.open(config) as robot, Bus.open(config) as ws:
        pub = robot.publisher(robot.keys.skeleton, s.SkeletonFrame, FRAMES.with_(cache=20))
        barrier_in = ws.subscribe(ws.keys.stream_end, s.StreamEnd)
        barrier_out = robot.publisher(robot.keys.stream_end, s.StreamEnd)
        await barrier_out.wait_matching()
        for frame in frames:  # nobody listens yet: only the cache keeps them
            pub.put(frame)
        # Samples may be on their way to `ws` already (sent before the publisher knew nobody
        # listens there): data behind them on the same link arrives after them, so once it is
        # in, they are gone, and the subscriber can only get them from the cache.
        header = msgspec.structs.replace(frames[0].header, version=s.StreamEnd.VERSION)
        barrier_out.put(s.StreamEnd(header=header, source="barrier", messages=len(frames)))
        await barrier_in.recv(timeout=10)
        sub = ws.subscribe(ws.keys.skeleton, s.SkeletonFrame, FRAMES)
        got = await _drain(sub, 20)
        assert got == [f.frame for f in frames[10:]]  # the last 20, oldest first
        for frame in skeleton_frames(5, start_ns=2_000_000_000_000_000_000):
            pub.put(frame)  # now live
        assert await _drain(sub, 5) == [0, 1, 2, 3, 4]
        with pytest.raises(TimeoutError):  # each sample once: nothing more comes
            await sub.recv(timeout=0.5)
        # the 20 came from the cache, the 5 off the wire (witnessed live)
        deadline = asyncio.get_running_loop().time() + 5
        while sub.recovered < 20 and asyncio.get_running_loop().time() < deadline:
            await asyncio.sleep(0.1)
        assert (sub.recovered, sub.received, sub.missed, sub.malformed) == (20, 25, 0, 0)
        pub.close()


async def test_malformed_payloads_on_a_recovering_key_are_counted_and_skipped() -> None:
    config = private_config()
    seen: list[str] = []
    with Bus.open(config) as a, Bus.open(config) as b:
        sub = b.subscribe(
            b.keys.skeleton, s.SkeletonFrame, FRAMES, on_malformed=lambda key, err: seen.append(key)
        )
        pub = a.publisher(a.keys.skeleton, s.SkeletonFrame, FRAMES.with_(cache=8))
        # published before discovery or after: the cache or the wire delivers both, in order
        pub.put_bytes(b"\x01not msgpack")
        pub.put(skeleton_frames(1)[0])
        assert (await sub.recv(timeout=10)).message.frame == 0
        assert sub.malformed == 1 and seen == [a.keys.skeleton]
        with pytest.raises(TypeError):
            pub.put(s.StreamEnd(header=skeleton_frames(1)[0].header, source="x", messages=0))  # type: ignore[arg-type]
        pub.close()


def test_bad_cache_or_history_sizes_are_input_errors() -> None:
    with pytest.raises(InputError, match="at least 1"):
        Delivery(history=0)
    with pytest.raises(InputError, match="> 0"):
        Delivery(max_age_s=-1)
    with pytest.raises(InputError, match="cache of -1"):
        Delivery(cache=-1)
    with pytest.raises(InputError, match="'block', 'drop'"):
        Delivery(congestion="wait")  # type: ignore[arg-type]


# -- routers joined in addition to the local group -------------------------------------------


def test_routers_are_added_to_the_local_group_not_replacing_it() -> None:
    peer = BusConfig(port=7500, routers=("tcp/10.0.0.2:7447",))
    assert peer.endpoints()[1] == ["tcp/127.0.0.1:7500", "tcp/10.0.0.2:7447"]
    client = BusConfig(mode="client", routers=("tcp/10.0.0.2:7447",))
    assert client.endpoints()[1] == ["tcp/10.0.0.2:7447"]  # instead of a local router
    env = {"BEYOND_ZENOH_ROUTER": "tcp/a:7447, tcp/b:7447", "BEYOND_ZENOH_PORT": "7501"}
    assert load_config(env).routers == ("tcp/a:7447", "tcp/b:7447")
    # with a config file: the file's endpoints, then the routers
    robot = load_config({"BEYOND_ZENOH_CONFIG": str(REPO / "deploy/zenoh/robot.json5"), **env})
    zc = zenoh_config(robot)
    assert json.loads(zc.get_json("connect/endpoints")) == [
        "tcp/127.0.0.1:7501",
        "tcp/a:7447",
        "tcp/b:7447",
    ]  # fmt: skip  (the file names no rendezvous: BEYOND_ZENOH_PORT's)
    assert json.loads(zc.get_json("mode")) == "peer"
    ws = load_config({"BEYOND_ZENOH_CONFIG": str(REPO / "deploy/zenoh/workstation.json5"), **env})
    zc = zenoh_config(ws)
    assert json.loads(zc.get_json("mode")) == "client"
    assert json.loads(zc.get_json("connect/endpoints")) == ["tcp/a:7447", "tcp/b:7447"]


def test_up_links_its_peer_group_to_the_given_router_and_children_inherit_it() -> None:
    given = load_config({}, connect=["tcp/10.0.0.2:7447"], port=7502)
    linked = local_group(given)
    assert linked.connect is None and linked.routers == ("tcp/10.0.0.2:7447",)
    assert linked.endpoints()[1] == ["tcp/127.0.0.1:7502", "tcp/10.0.0.2:7447"]
    client = load_config({}, mode="client", connect=["tcp/10.0.0.2:7447"])
    assert local_group(client) == client  # a client is no group: its endpoints stand
    env = service_env(linked)
    assert env["BEYOND_ZENOH_ROUTER"] == "tcp/10.0.0.2:7447"
    assert "BEYOND_ZENOH_CONNECT" not in env
    child = load_config(env)
    assert child.endpoints() == linked.endpoints()


def test_each_side_has_its_own_monitor_and_wait_list() -> None:
    assert {monitor_name(p) for p in ("all", "robot", "workstation")} == {
        "monitor", "monitor-robot", "monitor-workstation",
    }  # fmt: skip
    assert wait_list(["reasoner,describer", " speech "]) == ["reasoner", "describer", "speech"]
    with pytest.raises(InputError, match="invalid service name"):
        wait_list(["reasoner/x"])


def test_the_namespace_test_skips_with_a_reason_without_root_or_ip(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import netns_util

    monkeypatch.setattr(netns_util.os, "geteuid", lambda: 1000)
    assert "needs root" in (netns_util.unavailable() or "")
    monkeypatch.setattr(netns_util.os, "geteuid", lambda: 0)
    monkeypatch.setattr(netns_util.shutil, "which", lambda name: None)
    assert "iproute2" in (netns_util.unavailable() or "")
