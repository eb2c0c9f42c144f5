"""`beyond service NAME`: run one service in this process until SIGINT/SIGTERM.

    beyond service NAME [--config FILE] [--set OPTION=VALUE ...] [bus options]

Options come from the config file's `services.NAME` section, then `--set` (values are JSON when
they parse as JSON, else strings). The bus joins as the environment and bus options say.
"""

from __future__ import annotations

import argparse
import contextlib
import json
from typing import Any

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args
from beyond_self.runtime.process import configure, exit_process
from beyond_self.runtime.shard import parse_shard
from beyond_self.services.launcher import wait_for_release
from beyond_self.services.options import check_options, load_options
from beyond_self.services.registry import SERVICES, service_class

HELP = "run one service (ingest, gestures, objects, reasoner, describer, speech, ros2)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", choices=list(SERVICES), metavar="NAME", help=", ".join(SERVICES))
    parser.add_argument("--config", metavar="FILE", help="YAML/JSON file with a services section")
    parser.add_argument(
        "--set", action="append", default=[], metavar="OPTION=VALUE", help="override an option"
    )
    parser.add_argument(
        "--robots",
        metavar="PATTERN",
        help="serve every robot PATTERN matches, e.g. 'lab-*' (gestures, objects, reasoner, "
        "describer; default: the one robot --robot), a run per robot while its ingest is alive "
        "($BEYOND_ROBOTS)",
    )
    parser.add_argument(
        "--standby",
        metavar="PATTERN",
        help="with --robots: also serve the robots PATTERN matches while no other workstation "
        "does, taking over a dead workstation's robots ($BEYOND_STANDBY)",
    )
    parser.add_argument(
        "--shard",
        metavar="K/N",
        help="with --robots: serve only shard K (0 to N-1) of N, the robots a stable hash of "
        "their names gives it (`beyond up --shards N` starts one process per shard)",
    )
    add_bus_arguments(parser)


def parse_sets(items: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name:
            raise InputError(f"--set expects OPTION=VALUE; got {item!r}")
        try:
            out[name.replace("-", "_")] = json.loads(text)
        except json.JSONDecodeError:
            out[name.replace("-", "_")] = text
    return out


def service_options(name: str, config: str | None, sets: list[str]) -> dict[str, Any]:
    options = {**load_options(config).get(name, {}), **parse_sets(sets)}
    return check_options(name, service_class(name), options)


def run(args: argparse.Namespace) -> int:
    options = service_options(args.name, args.config, args.set)
    cls = service_class(args.name)
    config = config_from_args(args)
    shard = parse_shard(args.shard) if args.shard is not None else None
    if shard is not None and config.robots is None:
        raise InputError("--shard K/N shares out a fleet's robots: give --robots PATTERN too")
    configure()
    with contextlib.suppress(Exception):  # what fails is said by the service's setup
        cls.warm(options)
    if not wait_for_release():  # started held (services.launcher), and let go without joining
        return 0
    if config.robots is None:
        cls.main(argv=(), config=config, **options)
    if not cls.fleet:  # a robot's source or voice
        raise InputError(f"service {args.name!r} serves one robot (its --robot), not a fleet")
    from beyond_self.runtime.fleet import Fleet, takeover_latest_s
    from beyond_self.runtime.process import run_to_completion
    from beyond_self.services.registry import fleet_consumers, stages_after

    latest = takeover_latest_s(stages_after(args.name))
    consumers = fleet_consumers(args.name)

    def fleet() -> Fleet:
        return Fleet(
            cls, config, options, consumers=consumers, takeover_latest_s=latest, shard=shard
        )

    exit_process(run_to_completion(lambda: fleet().run()))
