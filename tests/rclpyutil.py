"""Real rclpy for the ROS 2 tests: ROS 2 Kilted's rclpy and rmw_fastrtps_cpp from PyPI wheels,
in a side virtual environment made once and cached under ~/.cache/beyond-self (never the
project's), and a DDS domain of the test's own on loopback only: unicast discovery to
127.0.0.1, multicast off, on both sides (Cyclone's XML for ours, Fast DDS's for rclpy)."""

from __future__ import annotations

import fcntl
import hashlib
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

WHEELS = (
    "ros-kilted-rclpy",
    "ros-kilted-rmw-fastrtps-cpp",
    "ros-kilted-std-msgs",
    "ros-kilted-visualization-msgs",
    "ros-kilted-sensor-msgs",
)
NODES = Path(__file__).resolve().parent / "rclpy_nodes"
CYCLONE_LOOPBACK = (
    '<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/>'
    "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
    "<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>"
    '<Peers><Peer address="127.0.0.1"/></Peers></Discovery></Domain></CycloneDDS>'
)
FASTDDS_LOOPBACK = """<?xml version="1.0" encoding="UTF-8" ?>
<dds xmlns="http://www.eprosima.com"><profiles>
  <transport_descriptors><transport_descriptor>
    <transport_id>loopback</transport_id><type>UDPv4</type>
    <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>
  </transport_descriptor></transport_descriptors>
  <participant profile_name="loopback" is_default_profile="true"><rtps>
    <userTransports><transport_id>loopback</transport_id></userTransports>
    <useBuiltinTransports>false</useBuiltinTransports>
    <builtin>
      <metatrafficUnicastLocatorList><locator><udpv4><address>127.0.0.1</address></udpv4>
      </locator></metatrafficUnicastLocatorList>
      <initialPeersList><locator><udpv4><address>127.0.0.1</address></udpv4></locator>
      </initialPeersList>
    </builtin>
  </rtps></participant>
</profiles></dds>
"""


def side_python() -> Path:
    """The side environment's python with the wheels installed (made on first use; one
    test worker makes it while the others wait on a lock); skips when they cannot be had."""
    key = hashlib.sha256(f"{sys.version_info[:2]} {' '.join(WHEELS)}".encode()).hexdigest()[:12]
    home = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "beyond-self"
    venv = home / f"rclpy-{key}"
    python, done = venv / "bin" / "python", venv / ".complete"
    home.mkdir(parents=True, exist_ok=True)
    with (home / f"rclpy-{key}.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            made = subprocess.run(
                [sys.executable, "-m", "venv", "--clear", str(venv)], capture_output=True
            )
            if made.returncode != 0:
                pytest.skip(f"no virtual environment for rclpy: {made.stderr.decode()[-300:]}")
            installed = subprocess.run(
                [str(python), "-m", "pip", "install", "--quiet", *WHEELS],
                capture_output=True, text=True, timeout=900,
            )  # fmt: skip
            if installed.returncode != 0:
                pytest.skip(
                    f"real rclpy's wheels could not be installed: {installed.stderr[-300:]}"
                )
            done.touch()
    return python


def _free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def private_domain() -> int:
    """A DDS domain no other test uses now: its ports (7400 + 250 * domain + ...) unbound."""
    start = os.getpid() % 100
    for i in range(100):
        domain = 100 + (start + i) % 100
        base = 7400 + 250 * domain
        if all(_free(base + offset) for offset in (0, 1, 10, 11, 12, 13, 14, 15)):
            return domain
    raise AssertionError("no free DDS domain among 100..199")


def loopback_env(tmp: Path, domain: int) -> dict[str, str]:
    """The variables both sides run with: domain, loopback discovery, each DDS's own XML."""
    profile = tmp / "fastdds-loopback.xml"
    profile.write_text(FASTDDS_LOOPBACK)
    return {
        "ROS_DOMAIN_ID": str(domain),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "ROS_STATIC_PEERS": "",
        "CYCLONEDDS_URI": CYCLONE_LOOPBACK,
        "FASTDDS_DEFAULT_PROFILES_FILE": str(profile),
        "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp",
    }
