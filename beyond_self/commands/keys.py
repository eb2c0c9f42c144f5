"""`beyond keys init|add|show|acl`: the deployment's keystore and the router's access rules.

Identities are the services' names, the sides' (`router`, `robot`, `workstation`) and `tools`
(read-only), each bound to the robots it may act for; a fleet adds one certificate per robot and
one per workstation (runtime/security/keystore.py, runtime/security/acl.py). DIR defaults to
$BEYOND_ZENOH_SECURE. A router makes its rules from the certificates when it starts, so restart
it after adding one.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from beyond_self.commands import argtypes
from beyond_self.core.errors import InputError
from beyond_self.schemas.keys import DEFAULT_ROBOT

HELP = "make the secure bus's keystore (CA, certificates) and show its access rules"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="keys_command", metavar="ACTION", required=True)
    init = sub.add_parser("init", help="a new CA and one certificate per identity")
    init.add_argument("dir", type=Path, help="keystore folder to create (mode 0700)")
    days = argtypes.count(1, 36500, "days")
    init.add_argument("--days", type=days, default=365, help="validity of the certificates")
    add = sub.add_parser("add", help="a certificate for one more identity (or renew one)")
    add.add_argument("name", help="identity: a service name, a side, tools, or a fleet's robot")
    add.add_argument("--days", type=days, default=365, help="validity of the certificate")
    role = add.add_mutually_exclusive_group()
    role.add_argument(
        "--robot",
        action="store_true",
        help="NAME is a robot of a fleet: its certificate speaks for that robot alone",
    )
    role.add_argument(
        "--workstation",
        metavar="PATTERN",
        help="NAME is a workstation serving the robots PATTERN matches (e.g. 'lab-*')",
    )
    for p in (init, add):
        p.add_argument(
            "--robots",
            metavar="PATTERN",
            default=DEFAULT_ROBOT,
            help=f"the robots a service's or side's certificate acts for (default {DEFAULT_ROBOT}"
            "; '*' every robot, 'lab-*' those named lab-...)",
        )
    show = sub.add_parser("show", help="the certificates in the keystore, their robots, expiry")
    acl = sub.add_parser("acl", help="print the router's access_control block, generated")
    # DIR as `keys init DIR` spells it; --dir too, as `add` takes it
    for p in (show, acl):
        p.add_argument(
            "directory", nargs="?", type=Path, metavar="DIR", help="keystore ($BEYOND_ZENOH_SECURE)"
        )
    for p in (add, show, acl):
        p.add_argument("--dir", type=Path, help="keystore directory ($BEYOND_ZENOH_SECURE)")


def _directory(args: argparse.Namespace, required: bool = True) -> Path | None:
    positional = getattr(args, "directory", None)
    if positional is not None and args.dir is not None and positional != args.dir:
        raise InputError(f"two keystores given ({positional} and --dir {args.dir}); give one")
    given = positional or args.dir or os.environ.get("BEYOND_ZENOH_SECURE")
    if not given and not required:
        return None
    if not given:
        raise InputError("no keystore given; pass DIR (or --dir DIR) or set BEYOND_ZENOH_SECURE")
    return Path(given)


def run(args: argparse.Namespace) -> int:
    from beyond_self.runtime.security import keystore
    from beyond_self.schemas.keys import typed_pattern
    from beyond_self.services import registry

    if args.keys_command == "acl":
        print(json.dumps(registry.access_rules(_directory(args, required=False)), indent=2))
        return 0
    if args.keys_command == "init":
        names = registry.identities()
        for path in keystore.init(args.dir, names, days=args.days, robots=args.robots):
            print(path)
        return 0
    directory = _directory(args)
    assert directory is not None
    if args.keys_command == "add":
        role, robots = _binding(args)
        print(keystore.add(directory, args.name, days=args.days, role=role, robots=robots))
        return 0
    for entry in keystore.show(directory):
        state = "EXPIRED" if entry.expired else "valid"
        bound = (
            f"{entry.binding.role} of {typed_pattern(entry.binding.robots)}"
            if entry.binding
            else "CA"
        )
        print(
            f"{entry.name:<12} {state:<7} until {entry.not_after:%Y-%m-%d %H:%M} UTC  "
            f"{bound:<28} issuer {entry.issuer!r}  {entry.path}"
        )
    return 0


def _binding(args: argparse.Namespace) -> tuple[str | None, str]:
    """The role and robots of a new certificate: a fleet's robot or workstation is named
    freely, so its name must not be one the rules already give another role."""
    from beyond_self.schemas.keys import check_name
    from beyond_self.services import registry

    if not (args.robot or args.workstation):
        return None, args.robots
    if args.name in registry.identities():
        raise InputError(
            f"{args.name!r} is the name of a service, a side or tools; a fleet's robot or "
            f"workstation needs another ({', '.join(registry.identities())} are taken)"
        )
    if args.robot:
        return "robot", check_name("robot", args.name)
    return "workstation", args.workstation
