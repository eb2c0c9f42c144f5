"""Every service by name, in pipeline order (what `beyond service` and `beyond up` start)."""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

from beyond_self.core.errors import unknown
from beyond_self.runtime.security import acl
from beyond_self.runtime.service import Service

SERVICES: dict[str, str] = {
    "ingest": "beyond_self.services.ingest:SensorIngest",
    "gestures": "beyond_self.services.gestures:GestureStreamer",
    "objects": "beyond_self.services.objects:ObjectSegmenter",
    "reasoner": "beyond_self.services.reasoner:AffordanceReasoner",
    "describer": "beyond_self.services.describer:DescriptionGenerator",
    "speech": "beyond_self.services.speech:SpeechSynthesizer",
    # the ROS 2 face (`beyond up --ros2`, `beyond ros2 bridge`): started only when asked for
    "ros2": "beyond_self.services.ros2_bridge:Ros2Bridge",
}
OPTIONAL = ("ros2",)
PIPELINE = tuple(n for n in SERVICES if n not in OPTIONAL)  # what every deployment runs
PROFILES: dict[str, tuple[str, ...]] = {
    "all": PIPELINE,
    "robot": ("ingest", "gestures", "objects"),
    "workstation": ("reasoner", "describer", "speech"),
    # a fleet: each robot its source and its voice, one workstation the rest for many robots
    "fleet-robot": ("ingest", "speech"),
    "fleet-workstation": ("gestures", "objects", "reasoner", "describer"),
}
# what may run on each side, in either layout: a robot with its own pipeline (PROFILES), or a
# fleet's robot, whose gestures and objects are served by a workstation for many robots
SIDES: dict[str, tuple[str, ...]] = {
    "robot": ("ingest", "gestures", "objects", "speech", "ros2"),
    "workstation": ("gestures", "objects", "reasoner", "describer", "speech", "ros2"),
}


def service_class(name: str) -> type[Service]:
    if name not in SERVICES:
        raise unknown("service", name, list(SERVICES))
    module, _, cls = SERVICES[name].partition(":")
    found: type[Service] = getattr(importlib.import_module(module), cls)
    return found


def declarations() -> list[acl.Declaration]:
    """What every service touches, from its class (the access rules are made of these)."""
    return [acl.declaration_of(n, service_class(n)) for n in SERVICES]


def _fed_by(by_name: dict[str, acl.Declaration], name: str) -> list[str]:
    """The services that subscribe to something service `name` publishes."""
    outputs = set(by_name[name].publishes)
    return [d.name for d in by_name.values() if d.name != name and outputs & set(d.subscribes)]


def stages_after(name: str) -> int:
    """How many services deep the chain fed by service `name` goes (the describer 1: speech
    takes its descriptions; speech 0). A standby workstation takes a dead one's robots over
    sink first (runtime.fleet), so a producer's new run finds its consumers' new instances."""
    by_name = {d.name: d for d in declarations()}

    def depth(service: str, seen: frozenset[str]) -> int:
        fed = _fed_by(by_name, service)
        return max((1 + depth(c, seen | {c}) for c in fed if c not in seen), default=0)

    return depth(name, frozenset({name}))


def fleet_consumers(name: str) -> tuple[str, ...]:
    """The fleet services service `name` feeds directly: a standby's run of `name` waits for
    theirs (runtime.fleet)."""
    by_name = {d.name: d for d in declarations()}
    return tuple(c for c in _fed_by(by_name, name) if service_class(c).fleet)


def identities() -> list[str]:
    """Every identity a secure deployment's keystore needs a certificate for."""
    return acl.identities(declarations())


def access_rules(keystore: Path | None = None) -> dict[str, Any]:
    """The secure router's `access_control` block for these services, one subject per
    certificate of `keystore`, each on the robots it is bound to (default: every identity for
    the one robot `robot`)."""
    from beyond_self.runtime.security.keystore import bindings

    subjects = bindings(keystore) if keystore is not None else None
    return acl.access_control(declarations(), SIDES, subjects)
