"""The processes of a deployment: one per service, or with `shards` N, N per fleet service.

A shard is a normal fleet service process (runtime/fleet.py) serving the robots runtime.shard
gives it, under its own host name (`ws-1.shard0`): it is alive and answers health there, and
its deployment supervises and restarts it like any service. N = 1 is a deployment as it always
was: one process per service, named as the service, on the deployment's robot.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.shard import Shard
from beyond_self.schemas.keys import robot_matches, typed_pattern


@dataclass(frozen=True)
class Unit:
    """One process: `beyond service SERVICE ARGS...`, alive on robot `robot`'s keys."""

    name: str
    service: str
    robot: str
    args: tuple[str, ...] = ()

    @property
    def command(self) -> list[str]:
        return ["service", self.service, *self.args]


def plan_units(
    config: BusConfig, services: Sequence[str], shards: int, fleet: Sequence[str] = ()
) -> dict[str, Unit]:
    """Each process of a deployment of `services` on `config`, by name, in the services' order;
    with `shards` > 1, each of them (all fleet services: `fleet`) runs as that many shards."""
    if shards == 1:
        return {n: Unit(n, n, config.robot) for n in services}
    if config.robots is None:
        raise InputError(f"--shards {shards}: shards share out a fleet's robots; give --robots")
    if config.secure is not None:  # the access rules grant a workstation its own name only
        raise InputError(
            f"--shards {shards}: not on a secure bus yet (the certificates name the workstation, "
            "not its shards); use --shards 1"
        )
    single = [n for n in services if n not in fleet]
    if single:
        raise InputError(
            f"--shards {shards}: only a fleet's services are sharded, not {', '.join(single)} "
            "(one robot's own)"
        )
    hosts = [Shard(k, shards).host(config.robot) for k in range(shards)]
    for pattern in (config.robots, config.standby):
        taken = [h for h in hosts if pattern is not None and robot_matches(pattern, h)]
        if pattern is not None and taken:
            raise InputError(
                f"--shards {shards}: shard host {taken[0]!r} is one of the robots "
                f"{typed_pattern(pattern)!r}; give the workstation another --robot"
            )
    units: dict[str, Unit] = {}
    for name in services:
        for k, host in enumerate(hosts):
            args = ("--robot", host, "--shard", str(Shard(k, shards)))
            units[f"{name}.shard{k}"] = Unit(f"{name}.shard{k}", name, host, args)
    return units
