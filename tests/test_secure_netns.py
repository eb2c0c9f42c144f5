"""The secure bus for real, inside network namespaces (as root; skipped with the reason
otherwise): `beyond up --secure` describes the demo recording on one host and six gestures
split across two, and a secure router's rules hold against intruders and against services and
tools reaching beyond their declarations.

The namespace is the test's own (tests/netns_util.py), so the router's TLS port 7447 is private
to it and nothing else on the machine can interfere.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest
from busutil_net import skeleton_recording
from netns_util import REPO, TwoHosts, unavailable

from runtime import acl, keystore

pytestmark = [pytest.mark.slow, pytest.mark.timeout(170)]
DEMO = REPO / "recordings" / "tap-ball-grasp-box.mcap"
SIX = ["tap", "grasp", "touch", "tap", "grasp", "touch"]
VERBS = {
    "tap": r"\b(taps|tapped|tapping|pushes|pushed|pushing|pokes|poked|poking)\b",
    "grasp": r"\b(grasps|grasped|grasping|picks|picked|picking)\b",
    "touch": r"\b(touches|touched|touching|pokes|poked|poking)\b",
}


@pytest.fixture
def hosts() -> Any:
    reason = unavailable()
    if reason is not None:
        pytest.skip(reason)
    h = TwoHosts()
    try:
        yield h
    finally:
        h.close()
        assert h.namespaces_left() == [], "namespaces left behind"
        assert all(p.popen.poll() is not None for p in h.procs), "processes left behind"


@pytest.fixture
def stores(tmp_path: Path) -> tuple[Path, Path]:
    ours, theirs = tmp_path / "keys", tmp_path / "other-keys"
    keystore.init(ours, acl.identities())
    keystore.init(theirs, ["describer"])
    return ours, theirs


def clean_env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("BEYOND_")}
    return {**env, "BEYOND_LOG_FORMAT": "text", "PYTHONPATH": str(REPO)}


def wait_exit(proc: Any, timeout: float) -> int:
    try:
        code = proc.popen.wait(timeout)
    except subprocess.TimeoutExpired:
        raise AssertionError(
            f"{proc.name} still running after {timeout} s\n{proc.text()}"
        ) from None
    if proc.reader is not None:
        proc.reader.join(5)
    return int(code)


def test_secure_up_describes_the_demo_recording(hosts: TwoHosts, stores: tuple[Path, Path]) -> None:
    ours, _ = stores
    argv = [str(REPO / ".venv/bin/python"), "-m", "beyond", "up", "--secure", str(ours),
            "--recording", str(DEMO), "--no-live", "--timeout", "100"]  # fmt: skip
    up = hosts.start(hosts.ws, "up", argv, clean_env())
    code = wait_exit(up, 150)
    text = up.text()
    assert code == 0, text[-4000:]
    # as `make demo` prints them (the object's words depend on the camera path keeping up with
    # the replay on a loaded machine, as in tests/test_pipeline_up.py: the verbs do not)
    described = dict(re.findall(r'^gesture (\d+): "(.*)"$', text, re.M))
    assert set(described) == {"1", "2"}, text[-4000:]
    assert re.search(VERBS["tap"], described["1"]) and re.search(VERBS["grasp"], described["2"])
    print("secure up described:", described)
    assert "zenoh router" in text and "secure=" in text  # the services went through the router
    assert "router 0" in text  # and it stopped cleanly


def test_router_rules_hold(hosts: TwoHosts, stores: tuple[Path, Path]) -> None:
    ours, theirs = stores
    python = str(REPO / ".venv/bin/python")
    router = hosts.start(
        hosts.ws, "router", [python, "-m", "beyond", "router", "--secure", str(ours)], clean_env()
    )
    deadline = time.monotonic() + 60
    while not any("zenoh router" in line for _, line in router.lines):
        assert router.popen.poll() is None and time.monotonic() < deadline, router.text()
        time.sleep(0.1)
    argv = [python, str(REPO / "tests" / "secure_probe.py"), str(ours), str(theirs)]
    probe = hosts.start(hosts.ws, "probe", argv, clean_env())
    assert wait_exit(probe, 120) == 0, probe.text()[-3000:]
    result = json.loads(next(line for _, line in probe.lines if line.startswith("{")))
    print(json.dumps(result))
    cameras = {f"camera-{i}" for i in range(20)}
    real = {"real-skeleton", "real-description", "real-description-2", "real-words"}
    # the counting subscriber (tools) sees what the owners put, nothing anyone else put
    assert real | cameras <= set(result["counter"])
    assert not [p for p in result["counter"] if p.startswith("fake")]
    # the describer's certificate: no put on sensors/** or affordance/**, no camera frames
    assert set(result["describer"]) & cameras == set()
    assert "real-words" in result["describer"]
    # a tools certificate reads (the counter is one) and asks, but its put reached nobody
    assert result["health_reply"] == ["ok"]
    assert result["speech"] == ["real-description", "real-description-2"]
    # intruders never got a link: they heard only their own local puts
    for name, heard in result["intruders"].items():
        assert set(heard) == {f"fake-{name}"}, (name, heard)
        assert result["intruder_links"][name] == 0
    hosts.stop(router)


def test_secure_split_across_two_hosts_describes_every_gesture(
    hosts: TwoHosts, stores: tuple[Path, Path], tmp_path: Path
) -> None:
    """The workstation's `up` runs the router (TLS 7447, the rules); the robot's connects to it
    across the link. Six gestures replayed on the robot are all described on the workstation."""
    ours, _ = stores
    recording = tmp_path / "six.mcap"
    skeleton_recording(recording, SIX, seed=3, robot="robot")
    up = [str(REPO / ".venv/bin/python"), "-m", "beyond", "up", "--secure", str(ours), "--no-live",
          "--timeout", "100"]  # fmt: skip
    ws = hosts.start(hosts.ws, "ws", [*up, "--profile", "workstation", "--until-stream-end"],
                     clean_env())  # fmt: skip
    robot = hosts.start(
        hosts.robot, "robot",
        [*up, "--profile", "robot", "--connect", f"tls/{hosts.ws_ip}:7447", "--recording",
         str(recording), "--rate", "2", "--wait-for", "reasoner,describer"],
        clean_env(),
    )  # fmt: skip
    assert wait_exit(ws, 150) == 0, ws.text()[-4000:]
    assert wait_exit(robot, 60) == 0, robot.text()[-4000:]
    text = ws.text()
    assert "6 of 6 gesture(s) described" in text, text[-4000:]
    for i, action in enumerate(SIX, start=1):
        line = next((x for x in text.splitlines() if x.startswith(f'gesture {i}: "')), "")
        assert re.search(VERBS[action], line), (action, line, text[-3000:])


def test_tools_read_and_ask_a_secure_pipeline(hosts: TwoHosts, stores: tuple[Path, Path]) -> None:
    """`echo`, `topics`, `ask` and `record` with the tools' certificate against a running secure
    pipeline (no source: it runs until stopped)."""
    ours, _ = stores
    python = str(REPO / ".venv/bin/python")
    up = hosts.start(
        hosts.ws, "up",
        [python, "-m", "beyond", "up", "--secure", str(ours), "--skip", "ingest", "--no-live"],
        clean_env(),
    )  # fmt: skip
    deadline = time.monotonic() + 90
    while not any(line.startswith("pipeline up:") for _, line in up.lines):
        assert up.popen.poll() is None and time.monotonic() < deadline, up.text()[-3000:]
        time.sleep(0.2)
    secure = ["--secure", str(ours)]
    mcap = str(ours.parent / "health.mcap")
    commands = {  # all at once: they are independent readers
        "echo": ["echo", "beyond/robot/health/describer", "--count", "1", "--json"],
        "topics": ["topics", "--duration", "2"],
        "ask": ["ask", "--query", "Action", "--evidence", "Shape=circle", "--json"],
        "record": ["record", "-o", mcap, "--count", "3", "beyond/robot/health/*"],
    }
    procs = {
        name: hosts.start(hosts.ws, name, [python, "-m", "beyond", *argv, *secure], clean_env())
        for name, argv in commands.items()
    }
    out = {}
    for name, proc in procs.items():
        assert wait_exit(proc, 60) == 0, proc.text()[-2000:]
        out[name] = proc.text()
    assert '"service":"describer"' in out["echo"].replace(" ", ""), out["echo"]
    topics = out["topics"]  # a wildcard reader hears every publisher
    assert "beyond/robot/health/reasoner" in topics, topics
    assert "alive: beyond/robot/alive/reasoner" in topics, topics
    assert "tap" in out["ask"] and "grasp" in out["ask"], out["ask"]
    assert "wrote 3 messages" in out["record"], out["record"]
    assert hosts.stop(up) == 0, up.text()[-3000:]
