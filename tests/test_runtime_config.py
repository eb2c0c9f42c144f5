"""Bus configuration from defaults, environment, arguments and files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from core.errors import InputError
from runtime.config import DEFAULT_PORT, BusConfig, load_config, zenoh_config


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
