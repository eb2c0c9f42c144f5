"""Bus configuration from defaults, environment, arguments and files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.config import (
    DEFAULT_PORT,
    ENV_VARS,
    BusConfig,
    load_config,
    zenoh_config,
)


def get(zc: object, key: str) -> object:
    return json.loads(zc.get_json(key))  # type: ignore[attr-defined]


def test_default_is_loopback_peer_with_rendezvous_port() -> None:
    config = load_config({})
    assert (config.mode, config.robot, config.port) == ("peer", "robot", DEFAULT_PORT)
    listen, connect = config.endpoints()
    assert listen == [f"tcp/127.0.0.1:{DEFAULT_PORT}", "tcp/127.0.0.1:0"]
    assert connect == [f"tcp/127.0.0.1:{DEFAULT_PORT}"]
    zc = zenoh_config(config)
    assert get(zc, "scouting/multicast/enabled") is False
    assert get(zc, "mode") == "peer"
    assert get(zc, "connect/endpoints") == connect


def test_environment_then_arguments() -> None:
    env = {
        "BEYOND_ROBOT": "icub",
        "BEYOND_ZENOH_MODE": "client",
        "BEYOND_ZENOH_CONNECT": "tcp/10.0.0.2:7447, tcp/10.0.0.3:7447",
        "BEYOND_ZENOH_PORT": "7600",
    }
    config = load_config(env)
    assert config.robot == "icub" and config.mode == "client" and config.port == 7600
    assert config.endpoints() == ([], ["tcp/10.0.0.2:7447", "tcp/10.0.0.3:7447"])
    override = load_config(env, robot="nao", connect=["tcp/1.2.3.4:7447"])
    assert override.robot == "nao"
    assert override.endpoints()[1] == ["tcp/1.2.3.4:7447"]


def test_router_mode_listens_on_all_interfaces() -> None:
    config = BusConfig(mode="router")
    assert config.endpoints() == (["tcp/[::]:7447"], [])


def test_config_file_is_the_base(tmp_path: Path) -> None:
    file = tmp_path / "zenoh.json5"
    file.write_text(
        json.dumps({"mode": "client", "connect": {"endpoints": ["tcp/192.168.1.9:7447"]}})
    )
    config = load_config({"BEYOND_ZENOH_CONFIG": str(file)})
    zc = zenoh_config(config.with_(mode="client"))
    assert get(zc, "connect/endpoints") == ["tcp/192.168.1.9:7447"]
    assert get(zc, "mode") == "client"


@pytest.mark.parametrize(
    ("env", "message"),
    [
        ({"BEYOND_ZENOH_MODE": "hub"}, "unknown Zenoh mode 'hub'"),
        ({"BEYOND_ZENOH_PORT": "seven"}, "not a port number"),
        ({"BEYOND_ZENOH_PORT": "70000"}, "out of range"),
        ({"BEYOND_ROBOT": "a/b"}, "invalid robot name"),
        ({"BEYOND_ZENOH_CONFIG": "/nonexistent/z.json5"}, "does not exist"),
    ],
)
def test_bad_settings_are_input_errors(env: dict[str, str], message: str) -> None:
    with pytest.raises(InputError, match=message):
        load_config(env)


def test_bad_endpoint_is_reported() -> None:
    with pytest.raises(InputError, match="bad Zenoh setting"):
        zenoh_config(BusConfig(connect=("not an endpoint",)))


ENDPOINT = st.builds(
    "{}/{}:{}".format,
    st.sampled_from(["tcp", "udp", "tls"]),
    st.sampled_from(["127.0.0.1", "10.0.0.2", "[::]", "router"]),
    st.integers(1, 65535),
)
ENDPOINTS = st.lists(ENDPOINT, min_size=1, max_size=3).map(tuple)
NAME = st.from_regex(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,15}", fullmatch=True)


@st.composite
def bus_configs(draw: st.DrawFn) -> BusConfig:
    secure = draw(st.sampled_from([None, Path("keys"), Path("/etc/beyond/keys")]))
    modes = ("client", "router") if secure is not None else ("peer", "client", "router")
    return BusConfig(
        robot=draw(NAME),
        mode=draw(st.sampled_from(modes)),
        connect=draw(st.none() | ENDPOINTS),
        listen=draw(st.none() | ENDPOINTS),
        port=draw(st.integers(1, 65535)),
        config_file=draw(st.sampled_from([None, Path(__file__)])),  # load_config checks it exists
        routers=draw(st.just(()) | ENDPOINTS),
        secure=secure,
        identity=draw(st.none() | NAME),
    )


@given(bus_configs())
@settings(max_examples=300, deadline=None)
def test_the_environment_written_for_a_config_reads_back_as_the_same_config(
    config: BusConfig,
) -> None:
    env = config.to_env()
    assert set(env) <= set(ENV_VARS)  # only the variables load_config reads (and documents)
    assert load_config(env) == config


def test_what_the_environment_cannot_carry_is_refused_not_lost() -> None:
    with pytest.raises(ValueError, match="BEYOND_ZENOH_LISTEN"):
        BusConfig(listen=()).to_env()  # an empty variable would mean the mode's default
    with pytest.raises(ValueError, match="BEYOND_ZENOH_CONNECT"):
        BusConfig(connect=("tcp/a:1,tcp/b:2",)).to_env()
    with pytest.raises(ValueError, match="connect_timeout_ms"):
        BusConfig(connect_timeout_ms=500).to_env()


def test_a_connect_timeout_bounds_the_first_link_whatever_the_mode_or_file() -> None:
    assert get(zenoh_config(BusConfig(mode="client")), "connect/timeout_ms") == 30_000
    assert get(zenoh_config(BusConfig(connect_timeout_ms=1500)), "connect/timeout_ms") == 1500
    robot = Path(__file__).resolve().parent.parent / "deploy/zenoh/robot.json5"
    from_file = BusConfig(config_file=robot, connect_timeout_ms=1500)
    assert get(zenoh_config(from_file), "connect/timeout_ms") == 1500


@pytest.mark.parametrize("mode", ["peer", "client", "router"])
def test_a_blocking_message_gives_up_on_a_full_queue_before_the_lease_does(mode: str) -> None:
    """Zenoh's default wait (5 s) outlasts our lease (4 s): a router forwarding a blocking
    message onto a dead link would hold the thread that routes every other stream past the
    lease of its local sessions (runtime/bus/config.py, BLOCK_CLOSE_MS)."""
    zc = zenoh_config(BusConfig(mode=mode))
    wait_us = get(zc, "transport/link/tx/queue/congestion_control/block/wait_before_close")
    lease_ms = get(zc, "transport/link/tx/lease")
    assert isinstance(wait_us, int) and isinstance(lease_ms, int)
    assert 0 < wait_us < lease_ms * 1000


@pytest.mark.parametrize("port", [None, 17903])
def test_the_port_holds_with_the_shipped_robot_file(port: int | None) -> None:
    """deploy/zenoh/robot.json5 names no rendezvous of its own: its peers meet on the bus's
    port (--port, BEYOND_ZENOH_PORT, else 7448), as they do without a file."""
    robot = Path(__file__).resolve().parent.parent / "deploy/zenoh/robot.json5"
    env = {"BEYOND_ZENOH_CONFIG": str(robot)}
    if port is not None:
        env["BEYOND_ZENOH_PORT"] = str(port)
    zc = zenoh_config(load_config(env))
    rendezvous = f"tcp/127.0.0.1:{port or DEFAULT_PORT}"
    assert get(zc, "listen/endpoints") == [rendezvous, "tcp/127.0.0.1:0"]
    assert get(zc, "connect/endpoints") == [rendezvous]
    assert get(zc, "connect/timeout_ms") == 100  # the file's own settings stay
    given = zenoh_config(load_config(env, listen=["tcp/127.0.0.1:17999"]))
    assert get(given, "listen/endpoints") == ["tcp/127.0.0.1:17999"]
