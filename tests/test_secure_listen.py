"""The secure router listens where it is told (issue 42): `$BEYOND_ZENOH_PORT` moves an
all-in-one `beyond up --secure` to that port, on loopback only (7447 stays free), and
`beyond router --secure DIR --listen tls/HOST:PORT` takes the keystore's certificate and key
for that listener, so a secure client reaches it."""

from __future__ import annotations

import asyncio
import os
import subprocess
from pathlib import Path

import pytest
from busutil_net import env_for, free_port, private_config

import beyond_self.schemas as s
from beyond_self.runtime.bus.config import load_config
from beyond_self.runtime.bus.delivery import RELIABLE
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.security import keystore
from beyond_self.services import registry
from beyond_self.services.launcher import BEYOND

RECORDING = Path(__file__).resolve().parent.parent / "recordings" / "touch-box.mcap"
LOOPBACK = {"127.0.0.1", "::1", "::ffff:127.0.0.1"}


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("keys") / "store"
    keystore.init(directory, registry.identities())
    return directory


def descendants(pid: int) -> list[int]:
    """`pid` and every process under it (Linux /proc)."""
    found, todo = [], [pid]
    while todo:
        p = todo.pop()
        found.append(p)
        try:
            for task in os.listdir(f"/proc/{p}/task"):
                todo += [
                    int(c) for c in Path(f"/proc/{p}/task/{task}/children").read_text().split()
                ]
        except OSError:
            continue
    return found


def listening(pids: list[int]) -> list[tuple[str, int]]:
    """(address, port) of every TCP socket in LISTEN state those processes hold."""
    inodes: set[str] = set()
    for pid in pids:
        try:
            fds = os.listdir(f"/proc/{pid}/fd")
        except OSError:
            continue
        for fd in fds:
            try:
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    found = []
    for table, width in (("/proc/net/tcp", 8), ("/proc/net/tcp6", 32)):
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] != "0A" or fields[9] not in inodes:  # 0A: LISTEN
                continue
            hex_addr, hex_port = fields[1].split(":")
            found.append((_address(hex_addr, width), int(hex_port, 16)))
    return found


def _address(hex_addr: str, width: int) -> str:
    import ipaddress

    raw = bytes.fromhex(hex_addr)
    # /proc prints each 32-bit word in host (little-endian) order
    words = b"".join(raw[i : i + 4][::-1] for i in range(0, len(raw), 4))
    addr = ipaddress.ip_address(words) if width == 8 else ipaddress.IPv6Address(words)
    if isinstance(addr, ipaddress.IPv6Address) and addr.ipv4_mapped is not None:
        return f"::ffff:{addr.ipv4_mapped}"
    return str(addr)


@pytest.mark.slow
async def test_secure_up_listens_on_the_given_port_on_loopback_only(
    store: Path, tmp_path: Path
) -> None:
    config = private_config()
    env = {k: v for k, v in env_for(config).items() if k != "BEYOND_ZENOH_MODE"}
    # the keystore's certificates are bound to robot "robot"; the private port keeps it apart
    env.update(BEYOND_LOG_FORMAT="text", BEYOND_ROBOT="robot")
    up = await asyncio.create_subprocess_exec(
        *BEYOND, "up", "--secure", str(store), "--recording", str(RECORDING), "--rate", "1",
        "--no-live", "--timeout", "90", env=env, cwd=tmp_path,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    assert up.stdout is not None and up.stderr is not None
    try:
        async with asyncio.timeout(120):
            first = (await up.stdout.readline()).decode()
            assert first.startswith("pipeline up"), first + (await up.stderr.read()).decode()
            sockets = listening(descendants(up.pid))
            out, err = await up.communicate()
    finally:
        if up.returncode is None:
            up.kill()
            await up.wait()
    assert up.returncode == 0, out.decode() + err.decode()[-3000:]
    assert [a for a, p in sockets if p == config.port], sockets  # the router, on the port
    assert all(p != 7447 for _, p in sockets), sockets
    assert {a for a, _ in sockets} <= LOOPBACK, sockets  # nothing on another interface
    assert f"listen=tls/127.0.0.1:{config.port}" in err.decode()


async def test_secure_router_listens_on_a_given_tls_endpoint(store: Path, tmp_path: Path) -> None:
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("BEYOND_")}
    router = subprocess.Popen(
        [*BEYOND, "router", "--secure", str(store), "--listen", f"tls/127.0.0.1:{port}"],
        env=env, cwd=tmp_path, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert router.stderr is not None
        line = await asyncio.wait_for(asyncio.to_thread(router.stderr.readline), 60)
        assert "zenoh router" in line and f"listen=tls/127.0.0.1:{port}" in line, line
        endpoint = [f"tls/127.0.0.1:{port}"]

        def secure(identity: str) -> Bus:
            return Bus.open(load_config({}, secure=store, identity=identity, connect=endpoint))

        with secure("ingest") as source, secure(keystore.TOOLS) as tool:
            got = tool.subscribe(tool.keys.skeleton, s.SkeletonFrame, RELIABLE)
            pub = source.publisher(source.keys.skeleton, s.SkeletonFrame, RELIABLE)
            header = s.Header(version=s.SkeletonFrame.VERSION, source="ingest", seq=0, stamp=1)
            frame = s.SkeletonFrame(header=header, frame=1, joints={})

            async def through() -> s.SkeletonFrame:
                await pub.wait_matching(timeout=30)
                pub.put(frame)
                async for received in got:
                    return received.message
                raise AssertionError("subscription closed")

            assert await asyncio.wait_for(through(), 30) == frame
    finally:
        router.terminate()
        await asyncio.to_thread(router.wait, 30)
