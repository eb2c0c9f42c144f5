"""A robot's identity is its own: on a secure bus a certificate speaks only for the robots it is
bound to (runtime/security/keystore.py bindings, runtime/security/acl.py rules).

A real secure router runs in this process (mutual TLS on a free loopback port, the rules made
from the keystore's certificates) and clients join it with their certificates, as
tests/secure_probe.py does inside a namespace. Denials are judged by order, never by waiting: a
put is known not to have been delivered once a later put of the same session, allowed, has
arrived; a session receives its own puts locally whatever the router says, so only others'
payloads count.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.config import BusConfig, zenoh_config
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.security import keystore
from beyond_self.runtime.security.acl import Binding
from beyond_self.schemas.keys import robot_matches, robot_pattern
from beyond_self.services import registry

WAIT_S = 30.0


@pytest.fixture(scope="module")
def fleet_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The deployment's identities (for the one robot `robot`), two robots of a fleet, a
    workstation for the robots named lab-*, and an operator's for every robot."""
    directory = tmp_path_factory.mktemp("fleet") / "keys"
    keystore.init(directory, registry.identities())
    for robot in ("lab-1", "lab-2", "other"):
        keystore.add(directory, robot, role="robot", robots=robot)
    keystore.add(directory, "ws-lab", role="workstation", robots="lab-*")
    keystore.add(directory, "ops", role="workstation", robots="*")
    return directory


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Heard:
    """Payloads received, with a condition to wait on."""

    def __init__(self) -> None:
        self.payloads: list[str] = []
        self.cond = threading.Condition()

    def __call__(self, sample: Any) -> None:
        with self.cond:
            self.payloads.append(sample.payload.to_bytes().decode())
            self.cond.notify_all()

    def wait(self, payload: str) -> None:
        deadline = time.monotonic() + WAIT_S
        with self.cond:
            while payload not in self.payloads:
                assert time.monotonic() < deadline, f"{payload} never arrived: {self.payloads}"
                self.cond.wait(0.2)


@pytest.fixture(scope="module")
def router(fleet_store: Path) -> Iterator[str]:
    endpoint = f"tls/127.0.0.1:{free_port()}"
    config = BusConfig(mode="router", secure=fleet_store, listen=(endpoint,), connect=())
    with Bus.open(config, access_rules=registry.access_rules(fleet_store)):
        yield endpoint


def session(store: Path, endpoint: str, identity: str) -> Any:
    config = BusConfig(mode="client", secure=store, identity=identity, connect=(endpoint,))
    return zenoh.open(zenoh_config(config))


def test_certificates_carry_their_robots(fleet_store: Path) -> None:
    bound = keystore.bindings(fleet_store)
    assert bound["lab-1"] == Binding("robot", "lab-1")
    assert bound["ws-lab"] == Binding("workstation", "lab-$*")
    assert bound["describer"] == Binding("describer", "robot")
    rules = registry.access_rules(fleet_store)
    by_id = {r["id"]: r for r in rules["rules"]}
    puts = by_id["lab-1-out-ingress"]["key_exprs"]
    assert "beyond/lab-1/sensors/skeleton" in puts
    assert all(k.startswith("beyond/lab-1/") for k in puts), puts
    ws_puts = by_id["ws-lab-out-ingress"]["key_exprs"]
    assert all(k.startswith(("beyond/lab-$*/", "beyond/ws-lab/")) for k in ws_puts), ws_puts
    # a fleet's workstation is alive and reports under its own name too (runtime/fleet.py),
    # and nothing more: a robot's data is not among its own name's keys
    tokens = by_id["ws-lab-alive-ingress"]["key_exprs"]
    assert "beyond/ws-lab/alive/monitor-fleet-workstation" in tokens, tokens
    assert "beyond/lab-$*/alive/monitor-fleet-workstation" in tokens, tokens
    assert not [k for k in by_id["workstation-out-ingress"]["key_exprs"] if "/workstation/" in k]
    assert not [k for k in by_id["ops-out-ingress"]["key_exprs"] if k.startswith("beyond/ops/")]
    assert robot_pattern("lab-*") == "lab-$*" and robot_pattern("*") == "*"
    assert robot_matches("lab-$*", "lab-7") and not robot_matches("lab-$*", "other")
    for bad in ("lab/1", "lab-**", "", "-x"):
        with pytest.raises(InputError, match="invalid robots pattern"):
            robot_pattern(bad)


def test_a_certificate_delivers_nothing_outside_its_robots(fleet_store: Path, router: str) -> None:
    opened: list[Any] = []

    def join(identity: str) -> Any:
        opened.append(session(fleet_store, router, identity))
        return opened[-1]

    try:
        counter, counted = join("ops"), Heard()  # reads every robot
        counter.declare_subscriber("beyond/*/**", counted)
        ws, ws_heard = join("ws-lab"), Heard()
        ws.declare_subscriber("beyond/lab-$*/**", ws_heard)
        ws.declare_subscriber("beyond/other/**", ws_heard)  # outside its robots
        lab1, other, ingest = join("lab-1"), join("other"), join("ingest")

        own = "beyond/lab-1/sensors/skeleton"
        deadline = time.monotonic() + WAIT_S  # the subscriptions reach the router first
        while "lab-1 own" not in counted.payloads and time.monotonic() < deadline:
            lab1.put(own, b"lab-1 own")
            with counted.cond:
                counted.cond.wait(0.2)
        counted.wait("lab-1 own")

        # a robot's certificate publishing under another robot's keys
        lab1.put("beyond/lab-2/sensors/skeleton", b"fake lab-1 as lab-2")
        lab1.put("beyond/lab-2/language/description", b"fake lab-1 as lab-2 description")
        lab1.put(own, b"lab-1 own 2")
        counted.wait("lab-1 own 2")
        # a service's certificate (bound to the deployment's robot) as a fleet's robot: the
        # hole the rules had when they named beyond/*/...
        ingest.put("beyond/lab-2/sensors/skeleton", b"fake ingest as lab-2")
        ingest.put("beyond/robot/sensors/skeleton", b"ingest own")
        counted.wait("ingest own")
        # a workstation's certificate outside its granted robots
        ws.put("beyond/other/language/description", b"fake ws-lab as other")
        ws.put("beyond/lab-1/language/description", b"ws-lab for lab-1")
        counted.wait("ws-lab for lab-1")
        # nor does it read them: other's frame reached the router before lab-1's next did
        other.put("beyond/other/sensors/skeleton", b"other own")
        counted.wait("other own")
        lab1.put(own, b"lab-1 own 3")
        ws_heard.wait("lab-1 own 3")
    finally:
        for s in opened:
            s.close()
    print("ops heard:", counted.payloads, "ws-lab heard:", ws_heard.payloads)
    assert not [p for p in counted.payloads if p.startswith("fake")], counted.payloads
    others = [p for p in ws_heard.payloads if p.startswith("other") or p.startswith("fake lab")]
    assert others == [], ws_heard.payloads
