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
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest
from busutil_net import skeleton_recording
from netns_util import REPO, TwoHosts

from beyond_self.runtime.security import keystore
from beyond_self.services import registry
from beyond_self.services.launcher import BEYOND

pytestmark = [pytest.mark.slow, pytest.mark.timeout(170)]
DEMO = REPO / "recordings" / "tap-ball-grasp-box.mcap"
SIX = ["tap", "grasp", "touch", "tap", "grasp", "touch"]
VERBS = {
    "tap": r"\b(taps|tapped|tapping|pushes|pushed|pushing|pokes|poked|poking)\b",
    "grasp": r"\b(grasps|grasped|grasping|picks|picked|picking)\b",
    "touch": r"\b(touches|touched|touching|pokes|poked|poking)\b",
}


@pytest.fixture
def stores(tmp_path: Path) -> tuple[Path, Path]:
    ours, theirs = tmp_path / "keys", tmp_path / "other-keys"
    keystore.init(ours, registry.identities())
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
    argv = [*BEYOND, "up", "--secure", str(ours),
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


def router_pids(keystore: Path) -> list[int]:
    """The `beyond router` processes serving `keystore` (its path is in their command line)."""
    found = []
    for proc in Path("/proc").iterdir():
        try:
            argv = (proc / "cmdline").read_bytes().split(b"\0")
        except (OSError, ValueError):
            continue
        if b"router" in argv and str(keystore).encode() in argv and proc.name.isdigit():
            found.append(int(proc.name))
    return found


def test_a_killed_router_is_started_again_and_nothing_is_lost_or_repeated(
    hosts: TwoHosts, stores: tuple[Path, Path]
) -> None:
    """Crash-only holds for a secure side's own router too: SIGKILLed mid-gesture, `up` starts
    it again, its clients reconnect, and every gesture is described and spoken once (what
    crossed nothing during the gap comes back from the publishers' caches)."""
    ours, _ = stores
    argv = [*BEYOND, "up", "--secure", str(ours),
            "--recording", str(DEMO), "--no-live", "--timeout", "100"]  # fmt: skip
    up = hosts.start(hosts.ws, "up", argv, clean_env())
    wait_for("gesture 1 to start", lambda: "gesture 1: started" in up.text(), 90, [up])
    (pid,) = router_pids(ours)
    os.kill(pid, 9)
    code = wait_exit(up, 150)
    text = up.text()
    assert code == 0, text[-4000:]
    assert re.search(r"\[up\] router: killed by SIGKILL; restart 1", text), text[-4000:]
    assert len(router_pids(ours)) == 0  # the restarted one stopped with the rest
    described = re.findall(r'^gesture (\d+): "(.*)"$', text, re.M)
    spoken = re.findall(r"^\[speech\] (?!\d\d:\d\d:\d\d )(.*)$", text, re.M)
    assert [n for n, _ in described] == ["1", "2"], text[-4000:]
    assert re.search(VERBS["tap"], described[0][1]) and re.search(VERBS["grasp"], described[1][1])
    assert sorted(spoken) == sorted(d for _, d in described), text[-4000:]  # each said once
    print("described after the router's restart:", described)


def test_router_rules_hold(hosts: TwoHosts, stores: tuple[Path, Path]) -> None:
    ours, theirs = stores
    python = str(REPO / ".venv/bin/python")
    router = hosts.start(
        hosts.ws,
        "router",
        [*BEYOND, "router", "--secure", str(ours)],
        clean_env(),
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


def wait_for(
    what: str, condition: Any, timeout: float, procs: list[Any], shown: Sequence[Any] = ()
) -> None:
    """Wait for `condition`; fail with every process's log tail (`procs` must not exit first,
    `shown` may) so a failure says which end of the split stopped where."""
    deadline = time.monotonic() + timeout
    while not condition():
        dead = [p.name for p in procs if p.popen.poll() is not None]
        if dead or time.monotonic() > deadline:
            logs = "\n".join(f"--- {p.name}\n{tail(p)}" for p in [*shown, *procs])
            raise AssertionError(f"waiting for {what}: {dead or 'timed out'}\n{logs}")
        time.sleep(0.1)


def tail(proc: Any, chars: int = 2500) -> str:
    """A process's last lines, repeats folded ("present x57": the watcher polls) and a probe's
    events counted per kind (which gestures reached that host live, recovered, described), so
    that a CI log cut in the middle still shows each process."""
    runs: list[list[Any]] = []  # [line, times in a row]
    for _, line in list(proc.lines):
        if runs and runs[-1][0] == line:
            runs[-1][1] += 1
        else:
            runs.append([line, 1])
    text = "\n".join(line if n == 1 else f"{line} x{n}" for line, n in runs)[-chars:]
    events = [json.loads(x) for _, x in list(proc.lines) if x.startswith("{")]
    if not events:
        return text
    seen: dict[str, list[int]] = {}
    for e in events:
        if "segment" in e:
            seen.setdefault(f"{e['event']} {e.get('via', '')}".strip(), []).append(e["segment"])
    tokens = [f"{e['kind']} {e['key']}" for e in events if e.get("event") == "alive"]
    counted = "; ".join(f"{kind}: {sorted(segs)}" for kind, segs in seen.items())
    return f"{counted or 'no gesture events'}\nlast tokens: {tokens[-6:]}\n{text[-800:]}"


def test_secure_split_survives_a_cut_link(
    hosts: TwoHosts, stores: tuple[Path, Path], tmp_path: Path
) -> None:
    """Two hosts: the workstation's `up` runs its router (TLS 7447, the rules); the robot's runs
    its own, linked to it with the robot's certificate. Six gestures are replayed on the robot;
    after the first is described on the workstation the link goes down until the workstation's
    router has given up on it (the robot's tokens are gone there) and two more gestures have
    ended on the robot (its pipeline runs on through its own router). Back up, every
    gesture is described on the workstation, those of the outage recovered from the robot's
    publisher caches through the rules."""
    ours, _ = stores
    recording = tmp_path / "six.mcap"
    skeleton_recording(recording, SIX, seed=3, robot="robot")
    python = str(REPO / ".venv/bin/python")
    up = [
        *BEYOND,
        "up",
        "--secure",
        str(ours),
        "--no-live",
        "--timeout",
        "120",
    ]
    ws = hosts.start(hosts.ws, "ws", [*up, "--profile", "workstation", "--until-stream-end"],
                     clean_env())  # fmt: skip
    wait_for("the workstation", lambda: "pipeline up:" in ws.text(), 90, [ws])
    env = {**clean_env(), "BEYOND_ZENOH_SECURE": str(ours)}  # read-only: the tools' certificate
    watch = [
        python,
        str(REPO / "tests" / "secure_probe.py"),
        "watch",
        "beyond/robot/alive/gestures",
    ]
    watcher = hosts.start(hosts.ws, "watch", watch, env)
    robot = hosts.start(
        hosts.robot, "robot",
        [*up, "--profile", "robot", "--connect", f"tls/{hosts.ws_ip}:7447", "--recording",
         str(recording), "--rate", "2", "--wait-for", "reasoner,describer"],
        clean_env(),
    )  # fmt: skip
    procs = [ws, watcher, robot]
    wait_for("gesture 1 described on the workstation", lambda: 'gesture 1: "' in ws.text(), 90,
             procs)  # fmt: skip

    probe = [python, str(REPO / "tests" / "netns_util.py"), "probe"]  # through the robot's router
    seen = hosts.start(hosts.robot, "probe", probe, env)
    # and through the workstation's: what crosses the link, live and from the caches (a stall
    # after the link is back then says whether the samples stopped crossing or stopped being
    # delivered)
    across = hosts.start(hosts.ws, "ws-probe", probe, env)
    procs += [seen, across]

    def ended() -> int:  # gesture ends the robot's own pipeline published, as they happened
        events = [json.loads(x) for _, x in list(seen.lines) if x.startswith("{")]
        return sum(e.get("event") == "end" and e.get("via") == "live" for e in events)

    before = ended()
    t_down = time.monotonic()
    hosts.link(up=False)
    wait_for(
        "the workstation giving up on the link, and two more gestures ended on the robot",
        lambda: any(t > t_down and line == "absent" for t, line in list(watcher.lines))
        and ended() >= before + 2,
        60, procs,
    )  # fmt: skip
    hosts.link(up=True)
    print(f"link down {time.monotonic() - t_down:.1f} s ({before} gesture end(s) probed before)")
    probes = [watcher, seen, across]
    wait_for("both ends of the split to finish", lambda: ws.popen.poll() is not None
             and robot.popen.poll() is not None, 90, probes, [ws, robot])  # fmt: skip
    assert wait_exit(ws, 1) == 0, ws.text()[-4000:]
    assert wait_exit(robot, 1) == 0, robot.text()[-4000:]
    text = ws.text()
    assert "6 of 6 gesture(s) described" in text, text[-4000:]
    described = dict(re.findall(r'^gesture (\d+): "(.*)"$', text, re.M))
    assert sorted(described, key=int) == [str(i) for i in range(1, 7)], text[-3000:]
    for i, action in enumerate(SIX, start=1):
        assert re.search(VERBS[action], described[str(i)]), (action, described)
    recovered = [int(n) for n in re.findall(r"reasoner: stopped .* recovered=(\d+)", text)]
    print(f"reasoner recovered {recovered} message(s) from the robot's caches")
    for side in (ws, robot):  # a link found carrying presence but no data (services.link_watch)
        print(side.name, [line for line in side.text().splitlines() if "[up] router" in line])
    assert recovered and recovered[-1] > 0, text[-3000:]


def test_tools_read_and_ask_a_secure_pipeline(hosts: TwoHosts, stores: tuple[Path, Path]) -> None:
    """`echo`, `topics`, `ask` and `record` with the tools' certificate against a running secure
    pipeline (no source: it runs until stopped)."""
    ours, _ = stores
    up = hosts.start(
        hosts.ws, "up",
        [*BEYOND, "up", "--secure", str(ours), "--skip", "ingest", "--no-live"],
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
        name: hosts.start(hosts.ws, name, [*BEYOND, *argv, *secure], clean_env())
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
