"""One place that decides how a process joins the bus.

By default the processes of a machine are Zenoh peers on loopback, multicast scouting off: each
listens on an ephemeral port and connects to a rendezvous port where the first to start listens,
and Zenoh's gossip meshes them with no router. Across machines a router links them: clients of it,
or a machine's peer group linked to it (BEYOND_ZENOH_ROUTER). A secure bus is clients of a router
over mutual TLS (runtime/security/secure.py). `BusConfig.to_env` hands a configuration to the
processes
`beyond up` starts. Precedence: defaults < config file < environment < arguments.
More: docs/concepts/deployment.md.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from beyond_self.core.errors import InputError
from beyond_self.schemas.keys import DEFAULT_ROBOT, check_name, robot_pattern

if TYPE_CHECKING:
    import zenoh

MODES = ("peer", "client", "router")
DEFAULT_PORT = 7448  # rendezvous port of the default local group (7447 is Zenoh's router port)
SECURE_PORT = 7447  # a secure bus's router (runtime.security.secure)
ROUTER_LISTEN = "tcp/[::]:7447"
OPEN_WAIT_MS = 100  # open() waits this long to connect, then keeps retrying in the background
CLIENT_WAIT_MS = 30_000  # a client's open() waits this long for a router, then fails
LEASE_MS = 4000  # Zenoh's default is 10 s: too long for a robot on Wi-Fi (deploy/zenoh agrees)
# How long a blocking message waits for room in a link's full queue before Zenoh closes the link
# (Zenoh's default is 5 s). It must be shorter than the lease: the wait holds the thread that
# received the message, so a router forwarding it onto a dead link stops routing everything else
# that thread carries, past the lease of its own local sessions; and the dead link's transport,
# closed late, tears down the new one to the same peer (zenoh 1.10). Half the lease: a live
# link drains a batch in far less, a dead one is given up on before anything else times out.
BLOCK_CLOSE_MS = LEASE_MS // 2

ENV_VARS: dict[str, str] = {
    "BEYOND_ROBOT": "robot name, the second chunk of every key (default 'robot')",
    "BEYOND_ROBOTS": "the robots a workstation's services serve, a pattern such as 'lab-*' "
    "(default: the one robot BEYOND_ROBOT)",
    "BEYOND_STANDBY": "robots a fleet workstation serves only while no other host does, a "
    "pattern such as 'lab-b*': it takes over another workstation's robots when it dies",
    "BEYOND_ZENOH_CONFIG": "path of a Zenoh JSON5 config file used as the base",
    "BEYOND_ZENOH_MODE": "peer | client | router (default peer)",
    "BEYOND_ZENOH_CONNECT": "comma-separated endpoints to connect to, e.g. tcp/10.0.0.2:7447",
    "BEYOND_ZENOH_LISTEN": "comma-separated endpoints to listen on, e.g. tcp/0.0.0.0:7447",
    "BEYOND_ZENOH_PORT": f"rendezvous port of the default local group (default {DEFAULT_PORT})",
    "BEYOND_ZENOH_ROUTER": "comma-separated router endpoints connected to in addition to the "
    "mode's or config file's, e.g. tcp/10.0.0.2:7447",
    "BEYOND_ZENOH_SECURE": "keystore directory: mutual TLS and the router's access rules",
    "BEYOND_ZENOH_IDENTITY": "whose certificate of the keystore to use (default: the service's "
    "name, 'router' for a router, else 'tools')",
}


@dataclass(frozen=True)
class BusConfig:
    """How to open the Zenoh session. `listen`/`connect` None = the mode's default."""

    robot: str = DEFAULT_ROBOT
    # the robots a fleet's workstation services serve (schemas.keys.robot_pattern; None: the
    # one robot `robot`); the workstation's own presence is then under `robot`
    robots: str | None = None
    # robots served only while no other workstation serves them (runtime.fleet: failover)
    standby: str | None = None
    mode: str = "peer"
    connect: tuple[str, ...] | None = None
    listen: tuple[str, ...] | None = None
    port: int = 0  # 0: the bus's default, DEFAULT_PORT (SECURE_PORT on a secure bus)
    config_file: Path | None = None
    routers: tuple[str, ...] = ()  # connected to in addition to the mode's or file's endpoints
    secure: Path | None = None  # keystore directory: mutual TLS and access rules
    identity: str | None = None  # certificate name in the keystore (None: by mode)
    # How long open() waits for a first link (None: the mode's default). A one-shot tool's own
    # choice (`beyond health` must answer in bounded time), never handed to the processes it
    # starts, so it has no environment variable.
    connect_timeout_ms: int | None = None

    def __post_init__(self) -> None:
        check_name("robot", self.robot)
        if self.robots is not None:
            object.__setattr__(self, "robots", robot_pattern(self.robots))
        if self.standby is not None:
            object.__setattr__(self, "standby", robot_pattern(self.standby))
            if self.robots is None:
                raise InputError("a standby workstation serves robots of its own too: --robots")
        if self.mode not in MODES:
            raise InputError(f"unknown Zenoh mode {self.mode!r}; valid: {', '.join(MODES)}")
        if self.secure is not None and self.mode == "peer":
            raise InputError(
                "a secure bus has no peers (they would bypass the router's access rules); "
                "valid modes with --secure: client, router"
            )
        if self.port == 0:
            secure = self.secure is not None
            object.__setattr__(self, "port", SECURE_PORT if secure else DEFAULT_PORT)
        if not 0 < self.port < 65536:
            raise InputError(f"port {self.port} out of range; valid: 1-65535")

    def with_(self, **changes: Any) -> BusConfig:
        return replace(self, **changes)

    def to_env(self) -> dict[str, str]:
        """The variables that make `load_config` in another process build this same
        configuration (`load_config(env=c.to_env()) == c`): `beyond up` hands them to the
        services it starts. Written here, beside their reader, so writer and reader cannot
        drift apart. What the environment cannot carry is refused rather than silently lost."""
        if self.connect_timeout_ms is not None:
            raise ValueError("connect_timeout_ms is a process's own choice: no variable holds it")
        env = {
            "BEYOND_ROBOT": self.robot,
            "BEYOND_ZENOH_MODE": self.mode,
            "BEYOND_ZENOH_PORT": str(self.port),
        }
        lists = {
            "BEYOND_ZENOH_CONNECT": self.connect,
            "BEYOND_ZENOH_LISTEN": self.listen,
            "BEYOND_ZENOH_ROUTER": self.routers or None,
        }
        for name, endpoints in lists.items():
            if endpoints is not None:
                env[name] = _join(name, endpoints)
        paths = {"BEYOND_ZENOH_CONFIG": self.config_file, "BEYOND_ZENOH_SECURE": self.secure}
        env.update({name: str(path) for name, path in paths.items() if path is not None})
        if self.identity is not None:
            env["BEYOND_ZENOH_IDENTITY"] = self.identity
        if self.robots is not None:
            env["BEYOND_ROBOTS"] = self.robots
        if self.standby is not None:
            env["BEYOND_STANDBY"] = self.standby
        return env

    def endpoints(self) -> tuple[list[str], list[str]]:
        """(listen, connect) endpoints actually used."""
        rendezvous = f"tcp/127.0.0.1:{self.port}"
        if self.secure is not None:
            from beyond_self.runtime.security.secure import router_connect, router_listen

            listen, connect = (
                ([router_listen(self.port)], [])
                if self.mode == "router"
                else ([], [router_connect(self.port)])
            )
        elif self.mode == "peer":
            listen = [rendezvous, "tcp/127.0.0.1:0"]
            connect = [rendezvous]
        elif self.mode == "client":
            listen, connect = [], ["tcp/127.0.0.1:7447"]
        else:
            listen, connect = [ROUTER_LISTEN], []
        if self.config_file is not None:  # the file decides unless overridden explicitly
            listen, connect = [], []
        connect = list(self.connect) if self.connect is not None else connect
        if self.mode == "client" and self.routers and self.connect is None:
            connect = []  # a client's default is a router on this machine: the routers replace it
        return (
            list(self.listen) if self.listen is not None else listen,
            connect + [r for r in self.routers if r not in connect],
        )


def _split(value: str) -> tuple[str, ...]:
    return tuple(part.strip() for part in value.split(",") if part.strip())


def _join(name: str, endpoints: tuple[str, ...]) -> str:
    """`endpoints` as `_split` reads them back; an empty list (an empty variable means the
    mode's default) or an endpoint with a comma or blanks around it has no such form."""
    value = ",".join(endpoints)
    if not endpoints or _split(value) != endpoints:
        raise ValueError(f"{name} cannot carry the endpoints {list(endpoints)!r}")
    return value


def load_config(
    env: Mapping[str, str] | None = None,
    *,
    robot: str | None = None,
    robots: str | None = None,
    standby: str | None = None,
    mode: str | None = None,
    connect: list[str] | None = None,
    listen: list[str] | None = None,
    config_file: str | Path | None = None,
    port: int | None = None,
    routers: list[str] | None = None,
    secure: str | Path | None = None,
    identity: str | None = None,
) -> BusConfig:
    """The bus configuration from the environment, overridden by the given arguments."""
    env = os.environ if env is None else env
    file = config_file or env.get("BEYOND_ZENOH_CONFIG") or None
    port_text = env.get("BEYOND_ZENOH_PORT")
    if port is None and port_text:
        try:
            port = int(port_text)
        except ValueError:
            raise InputError(f"BEYOND_ZENOH_PORT={port_text!r} is not a port number") from None
    env_connect = env.get("BEYOND_ZENOH_CONNECT")
    env_listen = env.get("BEYOND_ZENOH_LISTEN")
    env_routers = env.get("BEYOND_ZENOH_ROUTER")
    path = Path(file) if file else None
    if path is not None and not path.is_file():
        raise InputError(f"Zenoh config file {path} does not exist")
    keystore = secure or env.get("BEYOND_ZENOH_SECURE") or None
    return BusConfig(
        robot=robot or env.get("BEYOND_ROBOT") or DEFAULT_ROBOT,
        robots=robots or env.get("BEYOND_ROBOTS") or None,
        standby=standby or env.get("BEYOND_STANDBY") or None,
        mode=mode or env.get("BEYOND_ZENOH_MODE") or ("client" if keystore else "peer"),
        secure=Path(keystore) if keystore else None,
        identity=identity or env.get("BEYOND_ZENOH_IDENTITY") or None,
        connect=tuple(connect) if connect else (_split(env_connect) if env_connect else None),
        listen=tuple(listen) if listen else (_split(env_listen) if env_listen else None),
        port=port or 0,
        config_file=path,
        routers=tuple(routers) if routers else (_split(env_routers) if env_routers else ()),
    )


MAX_CONFIG_NESTING = 64


def _refuse_deep_nesting(path: Path) -> None:
    """Zenoh parses its config in native code, where a file nested thousands deep overflows the
    stack and kills the process (no error to catch): refuse it first. Counting brackets outside
    strings is enough; comments with brackets only make the count safer."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise InputError(f"Zenoh config file {path} cannot be read: {exc.strerror}") from None
    depth = deepest = 0
    quote = ""
    escaped = False
    for ch in text:
        if quote:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == quote:
                quote = ""
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth -= 1
    if deepest > MAX_CONFIG_NESTING:
        raise InputError(
            f"Zenoh config file {path} nests {deepest} levels deep "
            f"(valid: at most {MAX_CONFIG_NESTING})"
        )


def zenoh_config(config: BusConfig, access_rules: Mapping[str, Any] | None = None) -> zenoh.Config:
    """A zenoh.Config for this BusConfig (imported lazily: zenoh is slow to import); a secure
    router enforces `access_rules`."""
    import zenoh

    if config.config_file:
        _refuse_deep_nesting(Path(config.config_file))
    try:
        zc = (
            zenoh.Config.from_file(str(config.config_file))
            if config.config_file
            else zenoh.Config()
        )
    except Exception as exc:  # zenoh raises its own ZError, with a multi-line reason
        reason = " ".join(str(exc).split())[:300]
        raise InputError(f"Zenoh config file {config.config_file} is not valid: {reason}") from None
    sets: dict[str, Any] = {}
    if config.config_file is None or config.mode != "peer":
        sets["mode"] = config.mode
    listen, connect = config.endpoints()
    if config.config_file is None:
        sets["scouting/multicast/enabled"] = False
        # Do not block open() on endpoints; retry quickly so a restarted rendezvous peer or
        # router is found again within about a second. The connect timeout must not be 0:
        # zenoh 1.10 then never retries an endpoint that failed at open() (a router started
        # later would never be reached). The listen timeout stays 0: a listen retry still
        # pending makes session.close() hang until its own timeout.
        retry = {"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2}
        # A client is nothing without its router: it waits for one (started later on the same
        # machine, typically) rather than failing at once.
        sets["connect/timeout_ms"] = CLIENT_WAIT_MS if config.mode == "client" else OPEN_WAIT_MS
        sets["connect/retry"] = retry
        sets["connect/exit_on_failure"] = False
        # A link silent for 4 s is dead (keep-alive every second): sessions across a broken
        # network close and reconnect quickly, and the recovering streams refill the gap.
        sets["transport/link/tx/lease"] = LEASE_MS
        sets["transport/link/tx/keep_alive"] = 4
        sets["transport/link/tx/queue/congestion_control/block/wait_before_close"] = (
            BLOCK_CLOSE_MS * 1000  # microseconds
        )
        if config.mode == "peer":
            sets["listen/timeout_ms"] = 0
            sets["listen/retry"] = retry
            sets["listen/exit_on_failure"] = False
    # A peer file that names no endpoints of its own (deploy/zenoh/robot.json5) meets its group
    # on the port's rendezvous, as without a file: --port and BEYOND_ZENOH_PORT hold with it.
    peer_file = (
        config.config_file is not None
        and config.mode == "peer"  # else the option's mode replaces the file's
        and _mode(zc) == "peer"
        and not config.secure
    )
    own = config.with_(config_file=None, routers=()).endpoints() if peer_file else ([], [])
    if peer_file and config.listen is None and not _named(zc, "listen/endpoints"):
        listen = own[0]
    if config.config_file is not None and config.connect is None:
        listed = _file_endpoints(zc, "connect/endpoints")
        if peer_file and not _named(zc, "connect/endpoints"):
            listed = own[1]
        connect = listed + [r for r in config.routers if r not in listed]
    if listen or config.listen is not None:
        sets["listen/endpoints"] = listen
    if connect or config.connect is not None:
        sets["connect/endpoints"] = connect
    if config.secure is not None:
        from beyond_self.runtime.security.secure import (
            check_endpoints,
            default_identity,
            tls_settings,
        )

        from_file = config.config_file is not None  # the file's own endpoints count too
        check_endpoints(
            listen or (_file_endpoints(zc, "listen/endpoints") if from_file else []),
            connect or (_file_endpoints(zc, "connect/endpoints") if from_file else []),
        )
        identity = config.identity or default_identity(config.mode)
        sets.update(tls_settings(config.secure, identity, config.mode, access_rules))
    if config.connect_timeout_ms is not None:
        sets["connect/timeout_ms"] = config.connect_timeout_ms
    for key, value in sets.items():
        try:
            zc.insert_json5(key, json.dumps(value))
        except Exception as exc:  # zenoh raises its own ZError
            raise InputError(f"bad Zenoh setting {key}={value!r}: {exc}") from None
    return zc


def _mode(zc: zenoh.Config) -> str:
    """The mode a config says (a file's own, unless an option set another)."""
    try:
        return str(json.loads(zc.get_json("mode")) or "peer")
    except Exception:  # zenoh raises its own ZError
        return "peer"


def _named(zc: zenoh.Config, path: str) -> bool:
    """Whether a config file sets `path` (Zenoh fills what a file leaves out with its own
    defaults: a value equal to those is taken as not named)."""
    import zenoh

    try:
        return bool(zc.get_json(path) != zenoh.Config().get_json(path))
    except Exception:  # zenoh raises its own ZError for a path it does not know
        return False


def _file_endpoints(zc: zenoh.Config, path: str) -> list[str]:
    """The endpoints a config file lists at `path` (a list, or a per-mode mapping)."""
    try:
        value = json.loads(zc.get_json(path))
        mode = json.loads(zc.get_json("mode")) or "peer"
    except Exception:
        return []
    if isinstance(value, dict):
        value = value.get(mode) or []
    return [str(v) for v in value] if isinstance(value, list) else []


def describe(config: BusConfig) -> str:
    """One line for logs: mode, robot and endpoints (with a config file, those it lists where
    no option overrides them: the endpoints the session is given)."""
    listen, connect = config.endpoints()
    if config.config_file is not None:
        try:
            zc = zenoh_config(config)
        except InputError:  # a bad file: its own error says why; this line names no endpoint
            pass
        else:
            listen = _file_endpoints(zc, "listen/endpoints")
            connect = _file_endpoints(zc, "connect/endpoints")
    source = f" file={config.config_file}" if config.config_file else ""
    if config.secure is not None:
        source += f" secure={config.secure} identity={config.identity or '-'}"
    return (
        f"mode={config.mode} robot={config.robot} listen={','.join(listen) or '-'} "
        f"connect={','.join(connect) or '-'}{source}"
    )
