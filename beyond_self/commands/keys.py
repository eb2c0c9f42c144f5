"""`beyond keys`: the deployment's keystore and the router's access rules.

    beyond keys init DIR [--days N]       a CA and a certificate + key per identity
    beyond keys add NAME [--dir DIR]      one more identity (or a renewed one)
    beyond keys show [--dir DIR]          every certificate and when it expires
    beyond keys acl                       the router's access_control block (JSON)

Identities are the services' names, the sides' (`router`, `robot`, `workstation`) and `tools`
(read-only: `echo`, `topics`, `ask`, `record`). DIR defaults to $BEYOND_ZENOH_SECURE. Use it with
`--secure DIR` on `beyond up`, `router`, `service` and the tools.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from beyond_self.commands import argtypes
from beyond_self.core.errors import InputError

HELP = "make the secure bus's keystore (CA, certificates) and show its access rules"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="keys_command", metavar="ACTION", required=True)
    init = sub.add_parser("init", help="a new CA and one certificate per identity")
    init.add_argument("dir", type=Path, help="keystore folder to create (mode 0700)")
    days = argtypes.count(1, 36500, "days")
    init.add_argument("--days", type=days, default=365, help="validity of the certificates")
    add = sub.add_parser("add", help="a certificate for one more identity (or renew one)")
    add.add_argument("name", help="identity: a service name, a side, or tools")
    add.add_argument("--days", type=days, default=365, help="validity of the certificate")
    show = sub.add_parser("show", help="the certificates in the keystore and their expiry")
    for p in (add, show):
        p.add_argument("--dir", type=Path, help="keystore directory ($BEYOND_ZENOH_SECURE)")
    sub.add_parser("acl", help="print the router's access_control block, generated")


def _directory(args: argparse.Namespace) -> Path:
    given = args.dir or os.environ.get("BEYOND_ZENOH_SECURE")
    if not given:
        raise InputError("no keystore given; pass --dir DIR or set BEYOND_ZENOH_SECURE")
    return Path(given)


def run(args: argparse.Namespace) -> int:
    from beyond_self.runtime import keystore
    from beyond_self.services import registry

    if args.keys_command == "acl":
        print(json.dumps(registry.access_rules(), indent=2))
        return 0
    if args.keys_command == "init":
        for path in keystore.init(args.dir, registry.identities(), days=args.days):
            print(path)
        return 0
    directory = _directory(args)
    if args.keys_command == "add":
        print(keystore.add(directory, args.name, days=args.days))
        return 0
    for entry in keystore.show(directory):
        state = "EXPIRED" if entry.expired else "valid"
        print(
            f"{entry.name:<12} {state:<7} until {entry.not_after:%Y-%m-%d %H:%M} UTC  "
            f"issuer {entry.issuer!r}  {entry.path}"
        )
    return 0
