"""A fleet with failover across two hosts (issue 24): three robots on one network namespace,
a router and two workstations on the other, one workstation SIGKILLed mid-gesture.

Workstation ws-a serves lab-a*, ws-b serves lab-b* and stands by for lab-a* (runtime/fleet.py).
The robots lab-a1, lab-a2 and lab-b1 replay recordings of their own (six gestures each) through
`beyond up --profile fleet-robot`. Once lab-a1's second gesture has started, ws-a and every
process it started are SIGKILLed: ws-b takes over lab-a1 and lab-a2 (from the robots' ledgers,
checkpoints and caches), and every robot prints exactly the lines `beyond analyse` prints for
its recording, each gesture described and said once.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from busutil_net import skeleton_recording
from netns_util import REPO, Proc, TwoHosts

from beyond_self.services.launcher import BEYOND

pytestmark = [pytest.mark.slow, pytest.mark.timeout(240)]

ROBOTS = {  # robot -> (its gestures, the recording's seed)
    "lab-a1": (["tap", "grasp", "touch", "tap", "grasp", "touch"], 3),
    "lab-a2": (["grasp", "touch", "tap", "touch", "tap", "grasp"], 5),
    "lab-b1": (["touch", "tap", "grasp", "grasp", "touch", "tap"], 7),
}
RATE = "2"
GESTURE = re.compile(r"^gesture (\d+)", re.M)


def gesture_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if GESTURE.match(line)]


def descendants(pid: int) -> list[int]:
    """Every process started under `pid`, children before their children."""
    found, todo = [], [pid]
    while todo:
        out = subprocess.run(["pgrep", "-P", str(todo.pop())], capture_output=True, text=True)
        children = [int(p) for p in out.stdout.split()]
        found += children
        todo += children
    return found


def kill_workstation(proc: Proc) -> int:
    """SIGKILL a workstation's `up` first (so nothing restarts), then every process under it
    (its services run in sessions of their own): the machine gone at once."""
    tree = descendants(proc.popen.pid)
    for pid in [proc.popen.pid, *tree]:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    proc.popen.wait(10)
    return len(tree)


def voice(folder: Path, robot: str) -> Path:
    """A config giving the robot's speech service a folder of its own."""
    path = folder / f"{robot}-services.json"
    path.write_text(json.dumps({"services": {"speech": {"out_dir": str(folder / robot)}}}))
    return path


def wait_for(what: str, condition: object, procs: list[Proc], timeout: float = 120) -> None:
    deadline = time.monotonic() + timeout
    while not condition():  # type: ignore[operator]
        dead = [p.name for p in procs if p.popen.poll() is not None and p.popen.returncode]
        if dead or time.monotonic() > deadline:
            logs = "\n".join(f"--- {p.name}\n{p.text()[-2500:]}" for p in procs)
            raise AssertionError(f"waiting for {what}: exited {dead}\n{logs}")
        time.sleep(0.1)


def start_workstation(
    hosts: TwoHosts, env: dict[str, str], name: str, mine: str, standby: str | None
) -> Proc:
    argv = [*BEYOND, "up", "--profile", "fleet-workstation", "--robot", name, "--robots", mine]
    argv += ["--standby", standby] if standby else []
    argv += ["--connect", "tcp/127.0.0.1:7447", "--no-live"]
    return hosts.start(hosts.ws, name, argv, env)


def start_robot(
    hosts: TwoHosts, env: dict[str, str], robot: str, recording: Path, folder: Path
) -> Proc:
    argv = [*BEYOND, "up", "--profile", "fleet-robot", "--robot", robot]
    argv += ["--recording", str(recording), "--rate", RATE]
    argv += ["--connect", f"tcp/{hosts.ws_ip}:7447", "--no-live", "--timeout", "120"]
    argv += ["--wait-for", "gestures,objects,reasoner,describer"]
    argv += ["--config", str(voice(folder, robot))]
    return hosts.start(hosts.robot, robot, argv, env)


@pytest.mark.skipif(sys.platform != "linux", reason="network namespaces need Linux")
def test_a_standby_workstation_takes_over_and_every_robot_is_described_once(
    hosts: TwoHosts, tmp_path: Path
) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("BEYOND_")}
    env.update(BEYOND_LOG_FORMAT="text", PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")
    recordings, expected = {}, {}
    for robot, (actions, seed) in ROBOTS.items():
        recordings[robot] = tmp_path / f"{robot}.mcap"
        skeleton_recording(recordings[robot], actions, seed=seed, robot=robot)
        analysed = subprocess.run(
            [*BEYOND, "analyse", str(recordings[robot])], capture_output=True, text=True,
            env=env, timeout=120, check=True,
        )  # fmt: skip
        expected[robot] = gesture_lines(analysed.stdout)
        assert len([ln for ln in expected[robot] if ln.endswith('"')]) == 6, analysed.stdout

    hosts.start(hosts.ws, "router", [*BEYOND, "router"], env)
    ws = {
        "ws-a": start_workstation(hosts, env, "ws-a", "lab-a*", None),
        "ws-b": start_workstation(hosts, env, "ws-b", "lab-b*", "lab-a*"),
    }
    robots = {
        robot: start_robot(hosts, env, robot, recordings[robot], tmp_path) for robot in ROBOTS
    }
    everyone = [*ws.values(), *robots.values()]
    lab_a1 = robots["lab-a1"]
    wait_for(
        "lab-a1's second gesture under way",
        lambda: re.search(r"^gesture 2\b", lab_a1.text(), re.M), everyone,
    )  # fmt: skip
    killed = kill_workstation(ws["ws-a"])
    assert killed >= 4, "ws-a's up and its four services"
    for robot, proc in robots.items():
        code = proc.popen.wait(90)
        assert code == 0, (robot, proc.text()[-4000:], ws["ws-b"].text()[-3000:])
    for robot, proc in robots.items():
        printed = gesture_lines(proc.text())
        assert printed == expected[robot], (robot, proc.text()[-4000:])
        said = (tmp_path / robot / "speech.log").read_text().splitlines()
        assert sorted(int(line.split("\t")[1]) for line in said) == [1, 2, 3, 4, 5, 6], said
    taken = re.findall(r"serving a robot no host serves .*robot=(lab-\S+)", ws["ws-b"].text())
    assert {"lab-a1", "lab-a2"} <= set(taken), ws["ws-b"].text()[-3000:]
    # sink first, each stage once its consumers' new runs were there, none at the latest wait
    missing = re.findall(r"no host serves .*consumers_missing=(\S+)", ws["ws-b"].text())
    assert len(missing) == len(taken) and set(missing) == {"[]"}, ws["ws-b"].text()[-3000:]


@pytest.mark.skipif(sys.platform != "linux", reason="network namespaces need Linux")
def test_a_secure_fleet_describes_its_robot_through_the_rules(
    hosts: TwoHosts, tmp_path: Path
) -> None:
    """A fleet on the secure bus: the workstation ws-lab (`beyond keys add ws-lab
    --workstation 'lab-*'`) runs its router and its four services, each presenting ws-lab's
    certificate; the robot lab-a1 (`beyond keys add lab-a1 --robot`) runs its own router,
    linked to the workstation's with lab-a1's certificate, and its source and voice with the
    same. The robot prints exactly the lines `beyond analyse` prints, each gesture said once:
    the rules made from the certificates carry a fleet end to end (what they refuse is
    tests/test_fleet_identity.py's). A second workstation, ws-lab2 (lab-b*), on ws-lab's
    host links its own router to ws-lab's (loopback 7447 is taken: its router takes another
    port) and comes up beside it."""
    from beyond_self.runtime.security import keystore
    from beyond_self.services import registry

    keys = tmp_path / "keys"
    keystore.init(keys, registry.identities())
    keystore.add(keys, "lab-a1", role="robot", robots="lab-a1")
    keystore.add(keys, "ws-lab", role="workstation", robots="lab-a*")
    keystore.add(keys, "ws-lab2", role="workstation", robots="lab-b*")
    env = {k: v for k, v in os.environ.items() if not k.startswith("BEYOND_")}
    env.update(BEYOND_LOG_FORMAT="text", PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")
    actions, seed = ROBOTS["lab-a1"]
    recording = tmp_path / "lab-a1.mcap"
    skeleton_recording(recording, actions, seed=seed, robot="lab-a1")
    analysed = subprocess.run(
        [*BEYOND, "analyse", str(recording)], capture_output=True, text=True, env=env,
        timeout=120, check=True,
    )  # fmt: skip
    expected = gesture_lines(analysed.stdout)
    secure = ["--secure", str(keys), "--no-live"]
    ws = hosts.start(
        hosts.ws, "ws-lab",
        [*BEYOND, "up", *secure, "--profile", "fleet-workstation", "--robot", "ws-lab",
         "--robots", "lab-a*"],
        env,
    )  # fmt: skip
    wait_for("the workstation", lambda: "pipeline up:" in ws.text(), [ws], 90)
    ws2 = hosts.start(
        hosts.ws, "ws-lab2",
        [*BEYOND, "up", *secure, "--profile", "fleet-workstation", "--robot", "ws-lab2",
         "--robots", "lab-b*", "--connect", "tls/127.0.0.1:7447"],
        env,
    )  # fmt: skip
    wait_for("the second workstation", lambda: "pipeline up:" in ws2.text(), [ws, ws2], 90)
    robot = hosts.start(
        hosts.robot, "lab-a1",
        [*BEYOND, "up", *secure, "--profile", "fleet-robot", "--robot", "lab-a1",
         "--connect", f"tls/{hosts.ws_ip}:7447", "--recording", str(recording), "--rate", RATE,
         "--timeout", "120", "--wait-for", "gestures,objects,reasoner,describer",
         "--config", str(voice(tmp_path, "lab-a1"))],
        env,
    )  # fmt: skip
    try:
        code = robot.popen.wait(150)
    finally:
        ws.popen.terminate()
        ws2.popen.terminate()
    assert code == 0, (robot.text()[-4000:], ws.text()[-3000:])
    assert gesture_lines(robot.text()) == expected, (robot.text()[-4000:], ws.text()[-3000:])
    said = (tmp_path / "lab-a1" / "speech.log").read_text().splitlines()
    assert sorted(int(line.split("\t")[1]) for line in said) == [1, 2, 3, 4, 5, 6], said
    assert ws.popen.wait(30) == 0, ws.text()[-3000:]
    assert "secure=" in ws.text() and "identity=ws-lab" in ws.text(), ws.text()[-3000:]
    assert ws2.popen.wait(30) == 0, ws2.text()[-3000:]
    assert "identity=ws-lab2" in ws2.text(), ws2.text()[-3000:]
