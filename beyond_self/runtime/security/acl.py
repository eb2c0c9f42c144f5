"""The router's access rules, generated from what the services declare, never written by hand.

Every service class states what it subscribes to, publishes and serves, and the Service base
refuses any key it did not declare, so these rules and the code cannot drift apart.
`access_control()` builds the router's block: default deny; a subject is a certificate's common
name, and its rules name only the robots its certificate is bound to; a service puts only on its
outputs, subscribes only to its inputs and serves only its queryables; `tools` read and ask; a
side may do what its services may. Each stream key comes with its zenoh-ext `<key>/@adv/**`
traffic. A declaration naming an unknown stream is an InputError. docs/concepts/security.md says
why each rule.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from beyond_self.core.errors import InputError, unknown
from beyond_self.schemas.keys import (
    ALIVE,
    ASK,
    DEFAULT_ROBOT,
    HEALTH,
    LEDGER,
    PREFIX,
    PROGRESS,
    STREAMS,
    robot_matches,
)

# queryable name -> key suffix after beyond/<robot>/ (besides every service's own health and
# Progress, answered by each service for itself)
QUERYABLES: dict[str, str] = {"ask": ASK}
TOOLS_ROLE = "tools"
SIDE_MONITORS: dict[str, tuple[str, ...]] = {  # side identity -> its monitors' liveliness names
    "robot": ("monitor-robot", "monitor-fleet-robot"),
    "workstation": ("monitor", "monitor-workstation", "monitor-fleet-workstation"),
    # the workstation's router, seen from the robot's
    "router": ("monitor", "monitor-workstation", "monitor-fleet-workstation"),
}
SIDE_OF = {"robot": "robot", "workstation": "workstation", "router": "workstation"}
_OUT_IN = ["put", "delete", "declare_queryable", "reply", "liveliness_token"]
_OUT_EG = ["declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query"]
_IN_IN = ["declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query"]
_IN_EG = ["put", "delete", "reply", "liveliness_token", "declare_queryable"]


@dataclass(frozen=True)
class Binding:
    """What an identity may do (`role`: a service's name, `tools`, or a side) and for which
    robots (`robots`: one key-expression chunk, `lab-1`, `lab-$*` or `*`); its certificate
    carries it (runtime/security/keystore.py)."""

    role: str
    robots: str = DEFAULT_ROBOT


Grant = tuple[str, list[str], str, list[str]]  # (what, messages, flow, key expressions)


@dataclass(frozen=True)
class Declaration:
    """What one service touches, by stream and queryable name."""

    name: str
    subscribes: tuple[str, ...] = ()
    publishes: tuple[str, ...] = ()
    serves: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for kind, names in (("stream", self.subscribes + self.publishes),):
            for stream in names:
                if stream not in STREAMS:
                    raise unknown(
                        f"{kind} declared by service {self.name!r}", stream, list(STREAMS)
                    )
        for queryable in self.serves:
            if queryable not in QUERYABLES:
                raise unknown(
                    f"queryable declared by service {self.name!r}", queryable, list(QUERYABLES)
                )


def declaration_of(name: str, cls: type) -> Declaration:
    """A service class's declaration; a class that declares nothing has no place in the rules."""
    parts = [getattr(cls, a, None) for a in ("subscribes", "publishes", "serves")]
    if all(p is None for p in parts):
        raise InputError(
            f"service {name!r} ({cls.__module__}.{cls.__qualname__}) declares no streams; "
            "give it `subscribes`, `publishes` and `serves` class attributes"
        )
    subscribes, publishes, serves = (tuple(p or ()) for p in parts)
    return Declaration(name, subscribes, publishes, serves)


def _key(robots: str, suffix: str) -> str:
    return f"{PREFIX}/{robots}/{suffix}"


def _stream_keys(robots: str, streams: Iterable[str]) -> list[str]:
    keys = []
    for stream in streams:
        key = _key(robots, STREAMS[stream][0])
        keys += [key, f"{key}/@adv/**"]
    return keys


@dataclass
class _Rules:
    rules: list[dict[str, Any]] = field(default_factory=list)
    subjects: list[dict[str, Any]] = field(default_factory=list)
    policies: list[dict[str, Any]] = field(default_factory=list)

    def role(self, subject: str, grants: list[Grant]) -> None:
        """One subject (certificate common name) and its rules: (what, messages, flow, keys);
        grants of the same what and flow are one rule."""
        merged: dict[tuple[str, str], tuple[list[str], set[str]]] = {}
        for what, messages, flow, keys in grants:
            if keys:
                old = merged.setdefault((what, flow), (list(messages), set()))
                old[0].extend(m for m in messages if m not in old[0])
                old[1].update(keys)
        ids: list[str] = []
        for (what, flow), (messages, exprs) in merged.items():
            rule_id = f"{subject}-{what}-{flow}"
            self.rules.append(
                {
                    "id": rule_id,
                    "messages": messages,
                    "flows": [flow],
                    "permission": "allow",
                    "key_exprs": sorted(exprs),
                }
            )
            ids.append(rule_id)
        self.subjects.append({"id": subject, "cert_common_names": [subject]})
        self.policies.append({"id": subject, "rules": ids, "subjects": [subject]})


def _reader_grants(declarations: list[Declaration], robots: str) -> list[Grant]:
    """Read everything of `robots`, ask every queryable, watch liveliness: no put, no
    serving."""
    everything = [_key(robots, "**")]
    streams = sorted({s for d in declarations for s in d.publishes})
    read = everything + _stream_keys(robots, streams)
    ask = [_key(robots, QUERYABLES[q]) for d in declarations for q in d.serves]
    ask.append(_key(robots, f"{HEALTH}/*"))
    alive = [_key(robots, f"{ALIVE}/**")]
    return [
        ("read", _IN_IN, "ingress", read),
        ("read", _IN_EG, "egress", read),
        ("ask", ["query"], "ingress", ask),
        ("ask", ["reply"], "egress", ask),
        ("watch", ["declare_liveliness_subscriber", "liveliness_query"], "ingress", alive),
        ("watch", ["liveliness_token"], "egress", alive),
    ]


def _service_grants(d: Declaration, robots: str) -> list[Grant]:
    """What service `d` may do, on the keys of `robots`."""

    def key(suffix: str) -> str:
        return _key(robots, suffix)

    health = [key(f"{HEALTH}/{d.name}")]
    progress = [key(f"{PROGRESS}/{d.name}")]  # its own Progress, answered to players
    ledgers = [key(f"{LEDGER}/*")]  # everyone's ledger, kept and answered for by all
    alive = [key(f"{ALIVE}/**")]
    # every service reports its own Progress and Ledger and may read and ask everyone's
    # (pacing, resuming, exactly once): what each has handled, never any data; and every
    # service may follow a replay's clock (runtime.clock)
    outputs = [*_stream_keys(robots, d.publishes), *health, *progress, key(f"{LEDGER}/{d.name}")]
    clock = key(STREAMS["clock"][0])
    inputs = [*_stream_keys(robots, d.subscribes), key(f"{PROGRESS}/*"), *ledgers, clock]
    serves = [key(QUERYABLES[q]) for q in d.serves] + health + progress + ledgers
    return [
        ("out", _OUT_IN, "ingress", outputs),
        # whoever subscribes or asks, with whatever wildcard: a publisher must hear of it to
        # send at all (clients filter on the writer's side); it learns only what others ask
        # for, and still puts and replies on nothing but its own keys
        ("out", _OUT_EG, "egress", [key("**"), *outputs]),
        ("in", _IN_IN, "ingress", inputs),
        ("in", _IN_EG, "egress", inputs),
        ("serve", ["declare_queryable", "reply"], "ingress", serves),
        ("serve", ["query"], "egress", serves),
        # its own token, and as a fleet's process the token saying which host serves a robot
        ("alive", ["liveliness_token"], "ingress", [key(f"{ALIVE}/{d.name}/**")]),
        ("watch", ["declare_liveliness_subscriber", "liveliness_query"], "ingress", alive),
        ("watch", ["liveliness_token"], "egress", alive),
    ]


def access_control(
    declarations: list[Declaration],
    sides: Mapping[str, Sequence[str]],
    subjects: Mapping[str, Binding] | None = None,
) -> dict[str, Any]:
    """The `access_control` block of the router's Zenoh configuration, for the services
    `declarations` describe, `sides` saying which services run on the robot's side and which
    on the workstation's (services.registry.SIDES), one subject per identity of `subjects`
    (certificate name -> binding, runtime.security.keystore.bindings; default: every identity in its
    own role for the one robot `robot`)."""
    published = {s: d.name for d in declarations for s in d.publishes}
    names = [d.name for d in declarations]
    reserved = [TOOLS_ROLE, *SIDE_MONITORS]
    for d in declarations:
        if names.count(d.name) > 1 or d.name in reserved:
            raise InputError(f"service name {d.name!r} is used twice or reserved ({reserved})")
        for stream in d.subscribes:
            if stream not in published:
                raise InputError(
                    f"service {d.name!r} subscribes to {stream!r}, which no service publishes; "
                    f"published: {', '.join(sorted(published))}"
                )
    if subjects is None:
        subjects = {name: Binding(name) for name in identities(declarations)}
    by_name = {d.name: d for d in declarations}
    rules = _Rules()
    for subject, binding in subjects.items():
        robots = binding.robots
        if binding.role in by_name:
            grants = _service_grants(by_name[binding.role], robots)
        elif binding.role == TOOLS_ROLE:
            grants = _reader_grants(declarations, robots)
        elif binding.role in SIDE_MONITORS:
            grants = []
            for chunk in _side_chunks(subject, binding):
                monitors = SIDE_MONITORS[binding.role]
                tokens = [_key(chunk, f"{ALIVE}/{m}") for m in monitors]
                ledgers = [_key(chunk, f"{LEDGER}/{m}") for m in monitors]
                grants += [
                    *_reader_grants(declarations, chunk),
                    ("alive", ["liveliness_token"], "ingress", tokens),
                    ("ledger", ["put"], "ingress", ledgers),  # its monitor's (beyond_self.monitor)
                ]
                for name in sides[SIDE_OF[binding.role]]:
                    grants += _service_grants(by_name[name], chunk)
        else:
            raise unknown(f"role of identity {subject!r}", binding.role, identities(declarations))
        rules.role(subject, grants)
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules.rules,
        "subjects": rules.subjects,
        "policies": rules.policies,
    }


def _side_chunks(subject: str, binding: Binding) -> list[str]:
    """The robot chunks a side's certificate acts on: its robots, and for a fleet's
    workstation (`beyond keys add ws-1 --workstation 'lab-*'`) also its own name, under which
    its processes are alive and report (runtime/fleet.py) and its monitor watches them."""
    fleet_host = binding.role == "workstation" and subject != "workstation"
    own = fleet_host and not robot_matches(binding.robots, subject)
    return [binding.robots, *([subject] if own else [])]


def identities(declarations: list[Declaration]) -> list[str]:
    """Every identity the rules know: the services, the tools, the sides (and the router)."""
    return [d.name for d in declarations] + [TOOLS_ROLE, *SIDE_MONITORS]


def declared_keys(declaration: Declaration, robot_root: str) -> Mapping[str, set[str]]:
    """The concrete keys of one robot a declaration allows, by kind (for the Service guard)."""
    return {
        "subscribe": {f"{robot_root}/{STREAMS[s][0]}" for s in declaration.subscribes},
        "publish": {f"{robot_root}/{STREAMS[s][0]}" for s in declaration.publishes},
        "serve": {f"{robot_root}/{QUERYABLES[q]}" for q in declaration.serves},
    }


def check_declared(name: str, cls: type, kind: str, key: str, robot_root: str) -> None:
    """Refuse (InputError) a key service `name` of class `cls` did not declare for `kind`
    ("subscribe", "publish", "serve"): the rules are generated from the declarations, so a
    service must not use what it did not declare. A class that declares nothing is not checked
    (it has no place on a secure bus). Progress and the stream clock may be read by all; its own
    health and Progress queryables served by all."""
    if all(getattr(cls, a, None) is None for a in ("subscribes", "publishes", "serves")):
        return
    if kind == "subscribe" and (
        key.startswith(f"{robot_root}/{PROGRESS}/") or key == f"{robot_root}/{STREAMS['clock'][0]}"
    ):
        return
    if kind == "serve" and key in (
        f"{robot_root}/{HEALTH}/{name}",
        f"{robot_root}/{PROGRESS}/{name}",
    ):
        return
    allowed = declared_keys(declaration_of(name, cls), robot_root)[kind]
    if key not in allowed:
        raise InputError(
            f"service {name!r} may {kind} only on the keys its class declares "
            f"({', '.join(sorted(allowed)) or 'none'}), not {key}; add it to "
            f"{cls.__qualname__}'s declarations"
        )
