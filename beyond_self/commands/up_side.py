"""Where a side of `beyond up` meets the bus: its group on loopback, its monitor's name, and on a
secure bus its own router and the certificates of its processes (a fleet's side presents one)."""

from __future__ import annotations

import argparse
import os

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.config import BusConfig
from beyond_self.services.registry import PROFILES


def secure_router(
    config: BusConfig, names: list[str], profile: str
) -> tuple[list[str], str | None]:
    """On a secure bus every side runs its own router: check every certificate this side needs
    (one line naming the file, before anything starts) and return the router's command, and
    where this side's processes reach it when it is not the default (None). Given endpoints
    elsewhere (the workstation's router), this side's router links to them with the side's
    certificate, and this side's processes stay on their own router, so a robot's pipeline
    keeps running when the network between the machines fails; that router listens on
    loopback only, on the bus's port (7447 unless told) if free, else on a free port: a second
    workstation of a fleet on the first one's host links to the first one's router there."""
    from beyond_self.runtime.security import keystore
    from beyond_self.runtime.security.secure import router_listen

    assert config.secure is not None
    remote = list(config.connect or ()) + list(config.routers)
    fleet = fleet_side(profile)  # one certificate for the side: its robot's, or its host's
    if fleet:
        identity = str(config.identity)
    elif remote:
        identity = side_identity(profile, config.robot)
    else:
        identity = "router"
    for name in [*([] if fleet else names), str(config.identity), identity]:
        keystore.check(config.secure, name)
    command = ["router", "--secure", str(config.secure), "--identity", identity]
    if not remote:
        # on the rendezvous port; everything on one machine (`--profile all`) stays on
        # loopback, a side meant for other machines listens on every interface
        command += ["--listen", router_listen(config.port, loopback=profile == "all")]
        return command, None
    local = router_listen(loopback_port(config.port), loopback=True)
    command += ["--listen", local] + [a for e in remote for a in ("--connect", e)]
    return command, local


def loopback_port(preferred: int) -> int:
    """`preferred` if nothing listens there on this machine, else a port the system picks."""
    import socket

    for port in (preferred, 0):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            try:
                probe.bind(("127.0.0.1", port))
            except OSError:
                continue
            found: int = probe.getsockname()[1]
            return found
    raise InputError("no free TCP port on 127.0.0.1 for this side's router")


def side_identity(profile: str, robot: str) -> str:
    """The certificate of a side's monitor and router: the robot's or the workstation's. A
    fleet's side is its own name (`--robot lab-1`, `--robot ws-1`): the certificate `beyond
    keys add` bound to that robot, or to the robots that workstation is granted, which its
    router and every process it starts present (fleet_env)."""
    if fleet_side(profile):
        return robot
    return "robot" if profile.endswith("robot") else "workstation"


def fleet_side(profile: str) -> bool:
    return profile.startswith("fleet-")


def fleet_env(config: BusConfig, profile: str) -> dict[str, str]:
    """On a secure fleet every process of the side presents the side's certificate, bound to
    its robots (elsewhere each service presents its own, bound to the deployment's robot)."""
    if config.secure is None or not fleet_side(profile) or config.identity is None:
        return {}
    return {"BEYOND_ZENOH_IDENTITY": config.identity}


def check_fleet_profile(profile: str) -> None:
    """A workstation's services for every robot `--robots` matches: only those that can serve
    many robots from one process (not a robot's source or voice)."""
    from beyond_self.services.registry import service_class

    single = [n for n in PROFILES[profile] if not service_class(n).fleet]
    if single:
        raise InputError(
            f"--robots: profile {profile} has {', '.join(single)}, which serve one robot; "
            "use --profile fleet-workstation"
        )


def mode_unset(args: argparse.Namespace, config: BusConfig) -> bool:
    return (
        getattr(args, "mode", None) is None
        and not os.environ.get("BEYOND_ZENOH_MODE")
        and config.config_file is None
    )


def local_group(config: BusConfig) -> BusConfig:
    """In peer mode, endpoints given to connect to are routers linked to this machine's group,
    not a replacement of it: the services `up` starts keep meeting on loopback."""
    if config.mode == "peer" and config.connect is not None:
        return config.with_(connect=None, routers=config.routers + config.connect)
    return config


def monitor_name(profile: str) -> str:
    """Liveliness name of `up`'s own monitor: one per side, so two sides never mistake each
    other's monitor for their own."""
    return "monitor" if profile == "all" else f"monitor-{profile}"
