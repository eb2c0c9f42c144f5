"""The compose deployment built and run for real, with podman (`pytest -m containers`).

The image is built from the Dockerfile on a local base (deploy/base-image.sh: Debian packages,
no registry needed); both are reused when the machine keeps them, so only a new machine pays for
the cold build. Each run happens inside a network namespace of its own (entered with nsenter, so
podman's mounts stay the host's): its loopback is the robot's "host network", and no port of the
machine is touched. `podman-compose up` starts both profiles of docker-compose.yml: the router
and the workstation services on the compose bridge network, the robot services on the host
network, replaying recordings/tap-ball-grasp-box.mcap. Two probes (tests/netns_util.py) watch
the bus: one in a container on the workstation's network, one on the robot's loopback.

One deployment is checked in stages (each compose cycle costs most of a minute):
- cut link: once the robot's first gesture has ended, the robot-to-router link is dropped
  (iptables in the namespace, on connections to the router's published port) until both ends
  have given up on it and the next gesture has ended; then it comes back;
- described: every gesture of the recording gets its final description on the workstation, with
  the verb of its action (tap, then grasp), the one that ended during the outage recovered from
  the robot's publisher caches;
- restarted: a container killed with SIGKILL is restarted by its restart policy, its service
  comes back on the bus and passes its health check;
- cleaned up: `down -v` leaves no container, network or volume.

Skipped, with the reason, where podman cannot run (not root, no podman, no runc...).
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from test_deploy_netns import VERBS, Events, gone

REPO = Path(__file__).resolve().parent.parent
COMPOSE = REPO / "docker-compose.yml"
BASE = "localhost/beyond-self-base:bookworm"
IMAGE = "beyond-self:latest"
ACTIONS = ["tap", "grasp"]  # recordings/tap-ball-grasp-box.mcap
HOST_CA = Path("/etc/ssl/certs/ca-certificates.crt")  # the host's CAs, for pip in the build
ROUTER_PORT = "7447"
LABEL = "io.github.beyond-self.test=containers"  # on the images this test builds
# failed checks in a row before podman calls a container unhealthy: the image's own number
HEALTH_RETRIES = int(re.search(r"--retries=(\d+)", (REPO / "Dockerfile").read_text())[1])
# and the time between two of them
HEALTH_INTERVAL_S = int(re.search(r"--interval=(\d+)s", (REPO / "Dockerfile").read_text())[1])

pytestmark = [pytest.mark.containers, pytest.mark.slow, pytest.mark.timeout(1500)]


def podman_env() -> dict[str, str]:
    """The environment podman runs with: deploy/podman's settings unless the caller set its
    own, and docker-format images (podman drops HEALTHCHECK from OCI ones)."""
    env = dict(os.environ)
    env.setdefault("CONTAINERS_CONF", str(REPO / "deploy/podman/containers.conf"))
    env.setdefault("BUILDAH_FORMAT", "docker")
    env.setdefault("CONTAINERS_STORAGE_CONF", storage_conf(env["CONTAINERS_CONF"]))
    return env


@functools.cache
def storage_conf(containers_conf: str) -> str:
    """overlay where it mounts (a cached build takes a second, where vfs took 111 to 241 s to
    copy every cached layer again, and a container starts without a copy of the image), else
    vfs, which works on any filesystem."""
    overlay = str(REPO / "deploy/podman/storage.conf")
    if shutil.which("podman") is None:
        return overlay
    env = {**os.environ, "CONTAINERS_CONF": containers_conf, "CONTAINERS_STORAGE_CONF": overlay}
    argv = ["podman", "info", "--format", "{{.Store.GraphDriverName}}"]
    info = subprocess.run(argv, capture_output=True, text=True, timeout=120, env=env, check=False)
    if info.returncode == 0 and info.stdout.strip() == "overlay":
        return overlay
    return str(REPO / "deploy/podman/storage-vfs.conf")


def run(
    argv: list[str], timeout: float = 120, check: bool = True, ns: str | None = None
) -> subprocess.CompletedProcess[str]:
    if ns is not None:
        argv = ["nsenter", f"--net=/run/netns/{ns}", *argv]
    proc = subprocess.run(
        argv, capture_output=True, text=True, timeout=timeout, env=podman_env(), check=False
    )
    if check and proc.returncode != 0:
        raise AssertionError(f"{' '.join(argv)} -> {proc.returncode}\n{proc.stderr[-3000:]}")
    return proc


def podman_compose() -> str | None:
    here = Path(sys.executable).parent / "podman-compose"
    return str(here) if here.exists() else shutil.which("podman-compose")


def unavailable() -> str | None:
    """Why the container test cannot run here, or None."""
    if not sys.platform.startswith("linux"):
        return "podman needs Linux"
    if os.geteuid() != 0:
        return "the container test runs rootful podman (CI runs as root)"
    for tool in ("podman", "runc", "ip", "iptables", "nsenter"):
        if shutil.which(tool) is None:
            return f"`{tool}` is not installed (.ci/run installs podman, runc, iptables)"
    compose = podman_compose()
    if compose is None:
        return "podman-compose is not installed (a dev dependency: pip install -e '.[dev]')"
    version = run([compose, "--version"], check=False).stdout
    m = re.search(r"podman-compose version (\d+)\.(\d+)", version)
    if m is None or (int(m.group(1)), int(m.group(2))) < (1, 1):
        return f"{compose} is too old for profiles and host networking ({version.strip()})"
    info = run(["podman", "info"], check=False)
    if info.returncode != 0:
        return f"`podman info` fails: {info.stderr.strip()[-300:]}"
    has_base = run(["podman", "image", "exists", BASE], check=False).returncode == 0
    if not has_base and shutil.which("debootstrap") is None:
        return f"no base image {BASE} and no debootstrap to build it"
    return None


@dataclass
class Built:
    base_s: float | None  # None: the base was there already
    build_s: float  # the first build of this run
    steps_run: int  # of its steps, how many were not from the cache (all of them: cold)
    size_mb: float
    summary: str


def build_image() -> tuple[float, int, int]:
    """(seconds, steps run, steps) of one `podman build` of the image."""
    argv = ["podman", "build", "--format", "docker", "--build-arg", f"BASE={BASE}"]
    if HOST_CA.is_file():  # a TLS-inspecting proxy's CA may be in there: pip needs it
        argv += ["-v", f"{HOST_CA}:/run/host-ca.crt:ro"]
        argv += ["--build-arg", "CA_BUNDLE=/run/host-ca.crt"]
    t0 = time.monotonic()
    out = run([*argv, "--label", LABEL, "-t", IMAGE, str(REPO)], timeout=1200).stdout
    total = re.search(r"^STEP \d+/(\d+)", out, re.M)
    steps = int(total.group(1)) if total else 0
    cached = len(re.findall(r"^--> Using cache", out, re.M))
    assert steps > 0, out[-2000:]
    return time.monotonic() - t0, steps - 1 - cached, steps  # FROM is never "from cache"


@pytest.fixture(scope="module")
def built() -> Built:
    reason = unavailable()
    if reason is not None:
        pytest.skip(reason)
    base_s = None
    # a non-root user runs Python in the base (as the image's user will), or the base is rebuilt
    probe = ["podman", "run", "--rm", "--user", "65534", BASE, "python", "-c", "print(1)"]
    exists = run(["podman", "image", "exists", BASE], check=False).returncode == 0
    ran = run(probe, check=False) if exists else None
    if ran is None or ran.returncode != 0 or ran.stdout.strip() != "1":
        t0 = time.monotonic()
        force = ["--force"] if exists else []
        run(["bash", str(REPO / "deploy/base-image.sh"), "--tag", BASE, *force], timeout=900)
        base_s = time.monotonic() - t0
        ran = run(probe, check=False)
        if ran.returncode != 0 or ran.stdout.strip() != "1":
            pytest.skip(f"podman cannot run a container here: {ran.stderr.strip()[-500:]}")
    build_s, built_steps, steps = build_image()
    # earlier builds of this test that the new image replaced (with vfs, a GB each)
    run(["podman", "image", "prune", "-f", "--filter", f"label={LABEL}"])
    size = int(run(["podman", "image", "inspect", "--format", "{{.Size}}", IMAGE]).stdout)
    inspect = json.loads(run(["podman", "image", "inspect", IMAGE]).stdout)[0]
    assert inspect["Config"].get("User") == "beyond", inspect["Config"]  # never root
    check = inspect.get("Healthcheck") or inspect["Config"].get("Healthcheck") or {}
    assert "beyond health" in " ".join(check.get("Test", [])), check
    base = f"{base_s:.0f} s (built)" if base_s is not None else "cached"
    driver = run(["podman", "info", "--format", "{{.Store.GraphDriverName}}"]).stdout.strip()
    summary = (
        f"{driver} storage; base image: {base}; image build {build_s:.0f} s "
        f"({built_steps} of {steps - 1} steps built); "
        f"image size {size / 1e6:.0f} MB"
    )
    return Built(base_s, build_s, built_steps, size / 1e6, summary)


def test_a_code_change_reuses_the_dependency_layer() -> None:
    """The dependencies are installed from pyproject.toml alone, before the code is copied in,
    so a change to the code rebuilds only the layers after it. Read from the Dockerfile: a
    second build to watch the cache at work took 303 s with podman's vfs storage, which copies
    every layer again even when it is cached."""
    text = (REPO / "Dockerfile").read_text().replace("\\\n", " ")  # one line per instruction
    steps = [
        line.split(maxsplit=1)
        for line in text.splitlines()
        if line.strip() and not line.startswith((" ", "#"))
    ]
    copies = [i for i, (op, *_rest) in enumerate(steps) if op == "COPY"]
    deps = next(
        i for i, (op, *rest) in enumerate(steps) if op == "RUN" and "requirements" in rest[0]
    )
    assert steps[copies[0]][1].split()[0] == "pyproject.toml"  # the first thing copied in
    assert copies[0] < deps < copies[1], steps  # installed before the code is copied


@dataclass
class Proc:
    name: str
    popen: subprocess.Popen[str]
    lines: list[str] = field(default_factory=list)

    def text(self) -> str:
        return "\n".join(self.lines)


class Deployment:
    """One compose project in a network namespace of its own, and the probes watching it."""

    def __init__(self, tag: str) -> None:
        self.ns = f"bxct-{os.getpid()}-{tag}"
        self.project = f"bxct{os.getpid()}{tag}"
        self.robot = f"ct{os.getpid()}{tag}"
        self.procs: list[Proc] = []
        self.ws_events, self.robot_events = Events(), Events()
        subprocess.run(["ip", "netns", "add", self.ns], check=True, timeout=20)
        subprocess.run(["ip", "-n", self.ns, "link", "set", "lo", "up"], check=True, timeout=20)
        self.compose_cmd = [str(podman_compose()), "-f", str(COMPOSE), "-p", self.project]

    def env(self) -> dict[str, str]:
        return {**podman_env(), "BEYOND_ROBOT": self.robot, "BEYOND_BASE_IMAGE": BASE}

    def compose(
        self, *args: str, profiles: tuple[str, ...] = ("workstation", "robot"), timeout: float = 300
    ) -> subprocess.CompletedProcess[str]:
        chosen = [arg for profile in profiles for arg in ("--profile", profile)]
        argv = ["nsenter", f"--net=/run/netns/{self.ns}", *self.compose_cmd, *chosen, *args]
        proc = subprocess.run(
            argv, capture_output=True, text=True, timeout=timeout, env=self.env(), check=False
        )
        assert proc.returncode == 0, f"{' '.join(args)}: {proc.stdout[-2000:]}{proc.stderr[-3000:]}"
        return proc

    def podman(self, *args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
        return run(["podman", *args], ns=self.ns, check=check)

    def container(self, service: str) -> str:
        return f"{self.project}_{service}_1"

    def healthy(self, service: str) -> bool:
        """The image's HEALTHCHECK as podman judges it: unhealthy only after its `--retries`
        checks in a row fail, `--interval` apart (one check, a Python start and a bus query
        within its 15 s, can miss on a machine running the suite beside three busy loops; in
        a CI run the reasoner's three checks back to back once all failed to reach the router,
        right after the cut link came back). A healthy container passes at the first check."""
        name = self.container(service)
        for attempt in range(HEALTH_RETRIES):
            began = time.monotonic()
            if self.podman("healthcheck", "run", name, check=False).returncode == 0:
                return True
            if attempt + 1 < HEALTH_RETRIES:
                time.sleep(max(0.0, HEALTH_INTERVAL_S - (time.monotonic() - began)))
        return False

    def health_log(self, service: str) -> str:
        """What the last health checks printed (podman keeps their output)."""
        state = json.loads(self.podman("inspect", self.container(service)).stdout)[0]["State"]
        log = (state.get("Health") or state.get("Healthcheck") or {}).get("Log") or []
        return "\n".join(f"{e.get('ExitCode')}: {e.get('Output', '').strip()}" for e in log[-3:])

    def start(self, name: str, argv: list[str], events: Events, env: dict[str, str]) -> Proc:
        popen = subprocess.Popen(
            ["nsenter", f"--net=/run/netns/{self.ns}", *argv],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
        )  # fmt: skip
        proc = Proc(name, popen)

        def read() -> None:
            assert popen.stdout is not None
            for line in popen.stdout:
                proc.lines.append(line.rstrip("\n"))
                events.add(time.monotonic(), line.strip())

        threading.Thread(target=read, daemon=True).start()
        self.procs.append(proc)
        return proc

    def start_robot_probe(self) -> None:
        """The robot's probe: a peer of the robot's group on loopback, started before the
        deployment so that it sees the replay from its first message (the robot's services
        start replaying as soon as they are up). It listens on a port of its own: the group's
        rendezvous port is the first robot service's, as without the probe."""
        env = {k: v for k, v in os.environ.items() if not k.startswith("BEYOND_")}
        env.update(
            BEYOND_ROBOT=self.robot,
            BEYOND_ZENOH_CONFIG=str(REPO / "deploy/zenoh/robot.json5"),
            BEYOND_ZENOH_LISTEN="tcp/127.0.0.1:0",
            BEYOND_ZENOH_ROUTER=f"tcp/127.0.0.1:{ROUTER_PORT}",
            PYTHONPATH=str(REPO),
            PYTHONUNBUFFERED="1",
        )
        self.start(
            "robot-probe", [sys.executable, str(REPO / "tests/netns_util.py"), "probe"],
            self.robot_events, env,
        )  # fmt: skip
        self.wait(self.robot_events, "the robot probe", lambda: self.robot_events.where(
            event="probe-ready"))  # fmt: skip

    def start_ws_probe(self) -> None:
        """The workstation's probe: a container on the compose network, a client of the router
        (what the workstation sees; what it joined too late for, it gets from the caches)."""
        probe = "/opt/beyond-self-tests/netns_util.py"
        self.start(
            "ws-probe",
            ["podman", "run", "--rm", "--name", self.container("probe"),
             "--network", f"{self.project}_beyond",
             "-v", f"{REPO / 'tests'}:/opt/beyond-self-tests:ro",
             "-e", f"BEYOND_ROBOT={self.robot}", "-e", "BEYOND_ZENOH_MODE=client",
             "-e", "BEYOND_ZENOH_ROUTER=tcp/router:7447", "-e", "BEYOND_LOG_FORMAT=text",
             "--entrypoint", "python", IMAGE, probe, "probe"],
            self.ws_events, podman_env(),
        )  # fmt: skip
        self.wait(self.ws_events, "the workstation probe", lambda: self.ws_events.where(
            event="probe-ready"))  # fmt: skip

    def wait(self, events: Events, what: str, predicate: Any, timeout: float = 240) -> Any:
        try:
            return events.wait(what, predicate, timeout, [])
        except AssertionError as exc:
            raise AssertionError(f"{exc}\n{self.logs()}") from None

    def logs(self) -> str:
        parts = [f"--- {p.name}\n{p.text()[-1500:]}" for p in self.procs]
        for service in ("router", "ingest", "gestures", "reasoner", "describer"):
            out = self.podman("logs", "--tail", "15", self.container(service), check=False)
            parts.append(f"--- {service}\n{out.stdout[-1500:]}{out.stderr[-1500:]}")
        return "\n".join(parts)

    def link(self, *, up: bool) -> None:
        """Drop (or let through again) every packet of the robot's connections to the router's
        published port: the robot/workstation link, and nothing inside either side."""
        match = ["-m", "conntrack", "--ctorigdst", "127.0.0.1", "--ctorigdstport", ROUTER_PORT]
        for chain in ("OUTPUT", "INPUT"):
            op = "-D" if up else "-I"
            run(["iptables", op, chain, *match, "-j", "DROP"], ns=self.ns)

    def described(self) -> dict[int, str]:
        return {e["segment"]: e["text"] for _, e in self.ws_events.where(event="described")}

    def all_described(self) -> dict[int, str]:
        every = set(range(1, len(ACTIONS) + 1))
        self.wait(
            self.ws_events, "every gesture described on the workstation",
            lambda: set(self.described()) >= every,
        )  # fmt: skip
        described = self.described()
        assert set(described) == every, described
        for segment, action in enumerate(ACTIONS, start=1):
            assert re.search(VERBS[action], described[segment]), (action, described[segment])
        return described

    def leftovers(self) -> list[str]:
        label = f"label=io.podman.compose.project={self.project}"
        found = []
        for kind in ("ps -a", "network ls", "volume ls"):
            out = self.podman(*kind.split(), "--filter", label, "--format", "{{.Names}}"
                              if kind == "ps -a" else "{{.Name}}").stdout  # fmt: skip
            found += [f"{kind.split()[0]}: {name}" for name in out.split()]
        names = self.podman("ps", "-a", "--format", "{{.Names}}").stdout.split()
        found += [f"container: {n}" for n in names if n.startswith(self.project)]
        return found

    def down(self) -> list[str]:
        """`down -v` once the probes are gone (the workstation's is on the compose network);
        what is left of the project."""
        self.stop_probes()
        self.compose("down", "-v", "-t", "5", timeout=240)
        return self.leftovers()

    def stop_probes(self) -> None:
        for proc in self.procs:
            if proc.popen.poll() is None:
                proc.popen.send_signal(signal.SIGTERM)
        self.podman("rm", "-f", "-t", "2", self.container("probe"), check=False)
        for proc in self.procs:
            try:
                proc.popen.wait(15)
            except subprocess.TimeoutExpired:
                proc.popen.kill()
                proc.popen.wait(5)

    def close(self) -> None:
        self.stop_probes()
        with contextlib.suppress(Exception):
            self.compose("down", "-v", "-t", "2", timeout=240)
        label = f"label=io.podman.compose.project={self.project}"  # whatever down left
        for kind in ("container", "network", "volume"):
            listed = self.podman(kind, "ls", "-q", *(["-a"] if kind == "container" else []),
                                 "--filter", label, check=False).stdout.split()  # fmt: skip
            if listed:
                self.podman(kind, "rm", "-f", *listed, check=False)
        subprocess.run(["ip", "netns", "delete", self.ns], check=False, timeout=20)


@pytest.fixture
def deployment(built: Built, request: pytest.FixtureRequest) -> Iterator[Deployment]:
    d = Deployment(request.node.name.rsplit("_", 1)[-1][:6])
    try:
        yield d
    finally:
        d.close()


def test_the_deployment_describes_survives_a_cut_link_restarts_and_cleans_up(
    deployment: Deployment, built: Built, show: Callable[[str], None]
) -> None:
    """One deployment, checked in stages (one `up` and one `down` instead of one per stage: the
    compose cycle is most of this test's time)."""
    show(built.summary)
    d = deployment
    # as the README deploys it: the workstation first, then the robot, whose replay starts as
    # soon as its own services are up (the cut below needs a link that was up to begin with)
    d.start_robot_probe()
    t_start = time.monotonic()
    d.compose("up", "-d", "--no-build", profiles=("workstation",))
    d.start_ws_probe()
    d.wait(d.robot_events, "the workstation's reasoner seen from the robot", lambda: any(
        e["key"].endswith("/alive/reasoner") and "PUT" in e["kind"]
        for _, e in d.robot_events.where(event="alive")))  # fmt: skip
    d.compose("up", "-d", "--no-build", profiles=("robot",))

    def ended_on_robot() -> dict[int, float]:
        """When each gesture's end reached the robot's probe (live, or from a cache)."""
        return {e["segment"]: t for t, e in reversed(d.robot_events.where(event="end"))}

    # the cut link: gesture 1 ends with the link up, gesture 2 while it is down. It is cut as
    # soon as gesture 1 ends on the robot: 8.4 s of recording before gesture 2 ends
    t_end1 = d.wait(d.robot_events, "gesture 1 ending on the robot",
                    lambda: ended_on_robot().get(1))  # fmt: skip
    t_down = time.monotonic()
    d.link(up=False)
    assert 2 not in ended_on_robot(), "cut too late: gesture 2 had ended"
    d.wait(
        d.robot_events, "the robot giving up on the cut link",
        lambda: gone(d.robot_events, "reasoner", t_down), 60,
    )  # fmt: skip
    d.wait(
        d.robot_events, "gesture 2 ending on the robot while the link is down",
        lambda: 2 in ended_on_robot(), 120,
    )  # fmt: skip
    # Each robot process gives up on its own link at its own lease's end: until the router has
    # dropped the gestures service's session too, TCP would still retransmit gesture 2's end
    # on the old connection once the link is back, and it would arrive live, not from a cache.
    d.wait(
        d.ws_events, "the router giving up on the robot's gestures service",
        lambda: gone(d.ws_events, "gestures", t_down), 60,
    )  # fmt: skip
    t_up = time.monotonic()
    d.link(up=True)
    described = d.all_described()
    live = {e["segment"] for _, e in d.ws_events.where(event="end", via="live")}
    recovering = {e["segment"] for _, e in d.ws_events.where(event="end", via="recovering")}
    assert recovering == {1, 2}
    assert 2 not in live  # it ended during the outage: it reached the workstation from the cache
    times = {e["segment"]: t for t, e in reversed(d.ws_events.where(event="described"))}
    # when gesture 1's description came only once the link was back, the time to it says little
    # about starting up: the time to gesture 1's end on the robot does
    first = "" if times[1] < t_down else " (only once the link was back)"
    show(
        f"up -> gesture 1 ended on the robot {t_end1 - t_start:.1f} s; "
        f"up -> first description {times[1] - t_start:.1f} s{first}; "
        f"link cut {t_up - t_down:.1f} s; "
        f"gesture 2 described {times[2] - t_up:.1f} s after it came back; gestures described: "
        + "; ".join(f'{g}: "{s}"' for g, s in sorted(described.items())),
    )

    for service in ("router", "gestures", "reasoner"):  # the image's health check, each kind
        assert d.healthy(service), (service, d.health_log(service))

    # SIGKILL a container's init: the restart policy brings it back, the bus sees it again
    name = d.container("describer")
    state = json.loads(d.podman("inspect", name).stdout)[0]["State"]
    count0 = int(json.loads(d.podman("inspect", name).stdout)[0].get("RestartCount", 0))
    t_kill = time.monotonic()
    os.kill(int(state["Pid"]), signal.SIGKILL)

    def token(kind: str, after: float) -> float | None:
        times = [
            t for t, e in d.ws_events.where(event="alive")
            if t > after and e["key"].endswith("/alive/describer") and kind in e["kind"]
        ]  # fmt: skip
        return min(times) if times else None

    t_gone = d.wait(d.ws_events, "the killed describer's token gone",
                    lambda: token("DELETE", t_kill))  # fmt: skip
    d.wait(d.ws_events, "the describer's token back on the bus",
           lambda: token("PUT", t_gone))  # fmt: skip
    back_s = time.monotonic() - t_kill
    back = json.loads(d.podman("inspect", name).stdout)[0]
    assert back["State"]["Running"] and int(back.get("RestartCount", 0)) > count0, back["State"]
    assert back["State"]["Pid"] != state["Pid"]
    health = d.podman("healthcheck", "run", name, check=False)
    assert health.returncode == 0, health.stdout + health.stderr
    # the service answering on the bus is the new process: it has been up since the kill only
    answer = d.podman("exec", name, "beyond", "health", "describer").stdout
    uptime = float(re.search(r"describer up (\d+) s", answer).group(1))  # type: ignore[union-attr]
    assert uptime <= time.monotonic() - t_kill + 1, answer
    show(
        f"describer SIGKILLed: restarted and back on the bus {back_s:.1f} s later, healthy",
    )

    assert d.down() == []
