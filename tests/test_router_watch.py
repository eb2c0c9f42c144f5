"""A secure side's router on loopback, restarted by its link watch when the other side is
present but silent (services.link_watch, services.deployment): the wiring from the watch's
decision to a new router that both sides' sessions reach again."""

from __future__ import annotations

import asyncio
from pathlib import Path

from busutil_net import free_port

from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.security import keystore
from beyond_self.services import registry
from beyond_self.services.deployment import Deployment


async def test_a_router_whose_link_carries_presence_but_no_data_is_restarted(
    tmp_path: Path,
) -> None:
    store = tmp_path / "keys"
    keystore.init(store, registry.identities())
    endpoint = f"tls/127.0.0.1:{free_port()}"
    told: list[tuple[str, str]] = []
    ours = BusConfig(mode="client", secure=store, identity="workstation", connect=(endpoint,))
    side = Deployment(
        ours,
        [],
        router=["router", "--secure", str(store), "--identity", "router", "--listen", endpoint],
        on_restart=lambda name, what: told.append((name, what)),
        link_silent_s=1.0,
    )
    theirs = BusConfig(mode="client", secure=store, identity="robot", connect=(endpoint,))
    try:
        await side.start()
        assert side.router is not None
        first = side.router.process.pid
        with Bus.open(theirs) as robot:  # the other side: present, and never a health report
            robot.declare_token(robot.keys.alive("gestures"))
            loop = asyncio.get_running_loop()
            deadline = loop.time() + 60
            while loop.time() < deadline and not (
                side.router is not None and side.router.running and side.router.process.pid != first
            ):
                await asyncio.sleep(0.1)
            assert side.router is not None and side.router.process.pid != first, told
            assert told[0][0] == "router" and "gestures present" in told[0][1], told
            assert "killed by SIGKILL; restart 1" in told[1][1], told
            # both sessions reach the new router: the robot's token is seen across it again
            assert side.bus is not None
            assert await side.bus.wait_alive(side.bus.keys.alive("gestures"), timeout=30)
        assert side.exited() == []
    finally:
        codes = await side.stop()
    assert codes == {"router": 0}
