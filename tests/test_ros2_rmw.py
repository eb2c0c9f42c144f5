"""The ROS 2 middleware is chosen and configured by ROS 2's own variables, and DDS samples are
rosbags' CDR with the padding XTypes counts (runtime.ros2.rmw, runtime.ros2.dds)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest
from ros2util import STORE

from beyond_self.core.errors import InputError
from beyond_self.runtime.ros2 import rmw
from beyond_self.runtime.ros2.dds import padded, topic_name, unpadded
from beyond_self.schemas import ros2 as r

VARIABLES = (
    "RMW_IMPLEMENTATION", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOCALHOST_ONLY",
    "ROS_STATIC_PEERS", "CYCLONEDDS_URI",
)  # fmt: skip


@pytest.fixture(autouse=True)
def clean(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in VARIABLES:
        monkeypatch.delenv(name, raising=False)


@pytest.mark.parametrize(
    ("implementation", "flag", "chosen"),
    [
        (None, None, "dds"),  # ROS 2's default
        ("rmw_fastrtps_cpp", None, "dds"),
        ("rmw_cyclonedds_cpp", None, "dds"),
        ("rmw_zenoh_cpp", None, "zenoh"),
        ("rmw_zenoh_cpp", "dds", "dds"),  # the flag overrides
        ("rmw_fastrtps_cpp", "zenoh", "zenoh"),
    ],
)
def test_the_middleware_follows_rmw_implementation(
    monkeypatch: pytest.MonkeyPatch, implementation: str | None, flag: str | None, chosen: str
) -> None:
    if implementation is not None:
        monkeypatch.setenv("RMW_IMPLEMENTATION", implementation)
    assert rmw.choose(flag) == chosen


def test_an_unknown_rmw_is_refused_on_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("RMW_IMPLEMENTATION", "rmw_carrier_pigeon")
    with pytest.raises(InputError, match=r"rmw_carrier_pigeon.*valid: .*rmw_zenoh_cpp"):
        rmw.choose()
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "GALAXY")
    with pytest.raises(InputError, match=r"GALAXY.*valid: SUBNET, LOCALHOST, OFF"):
        rmw.cyclone_config()


def parsed(monkeypatch: pytest.MonkeyPatch, **variables: str) -> ET.Element:
    for name, value in variables.items():
        monkeypatch.setenv(name, value)
    text = rmw.cyclone_config()
    assert text is not None
    return ET.fromstring(text)


def test_localhost_discovery_stays_on_loopback(monkeypatch: pytest.MonkeyPatch) -> None:
    root = parsed(monkeypatch, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    assert [i.get("address") for i in root.iter("NetworkInterface")] == ["127.0.0.1"]
    assert root.findtext(".//AllowMulticast") == "false"
    assert [p.get("address") for p in root.iter("Peer")] == ["127.0.0.1"]
    # ROS_LOCALHOST_ONLY=1, the older spelling, means the same
    monkeypatch.delenv("ROS_AUTOMATIC_DISCOVERY_RANGE")
    old = parsed(monkeypatch, ROS_LOCALHOST_ONLY="1")
    assert ET.tostring(old) == ET.tostring(root)


def test_static_peers_are_added_and_subnet_keeps_multicast(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    root = parsed(monkeypatch, ROS_STATIC_PEERS="192.168.0.7; robot.local")
    assert [p.get("address") for p in root.iter("Peer")] == ["192.168.0.7", "robot.local"]
    assert root.find(".//AllowMulticast") is None and root.find(".//NetworkInterface") is None
    off = parsed(monkeypatch, ROS_AUTOMATIC_DISCOVERY_RANGE="OFF", ROS_STATIC_PEERS="")
    assert off.findtext(".//AllowMulticast") == "false" and off.find(".//Peer") is None


def test_cyclones_own_configuration_wins(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("CYCLONEDDS_URI", "file:///etc/cyclone.xml")
    assert rmw.cyclone_config() is None
    monkeypatch.delenv("CYCLONEDDS_URI")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "SYSTEM_DEFAULT")
    assert rmw.cyclone_config() is None


def test_topics_are_named_as_rmw_names_them() -> None:
    assert topic_name("/robot/description") == "rt/robot/description"
    assert r.dds_type(r.MARKER_ARRAY) == "visualization_msgs::msg::dds_::MarkerArray_"


@pytest.mark.parametrize("text", ["", "a", "ab", "abc", "abcd", "the robot tapped the ball"])
def test_padding_is_counted_in_the_encapsulation_options(text: str) -> None:
    cdr = bytes(STORE.serialize_cdr(STORE.types[r.STRING](data=text), r.STRING))
    sent = padded(cdr)
    assert len(sent) % 4 == 0 and sent[3] & 3 == len(sent) - len(cdr)  # XTypes 7.6.3
    assert unpadded(sent) == cdr
    assert STORE.deserialize_cdr(unpadded(sent), r.STRING).data == text
