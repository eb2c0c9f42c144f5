"""Entry point of the `beyond` command.

Each command lives in its own module under `beyond.commands`, imported only when that command runs:
the science stack (pgmpy, hmmlearn) and the bus (zenoh) are slow to import, and a service or a
quick `beyond inspect` should not pay for what it does not use.

A command module exposes two functions:
    add_arguments(parser: argparse.ArgumentParser) -> None
    run(args: argparse.Namespace) -> int
and may expose `HELP` (one line). Errors meant for the user are `cognition.errors.InputError`:
the dispatcher prints them as one line on stderr and exits with status 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from types import ModuleType

from cognition.errors import InputError

# command name -> module under beyond.commands. One table, so `beyond --help` lists everything.
COMMANDS: dict[str, str] = {
    "demo": "demo",
    "bn": "bn",
    "gesture": "gesture",
    "describe": "describe",
    "reproduce": "reproduce",
    "learn": "learn",
    "segment": "segment",
    "simulate": "simulate",
    "record": "record",
    "replay": "replay",
    "inspect": "inspect_cmd",
    "topics": "topics",
    "echo": "echo",
    "router": "router",
    "service": "service",
    "up": "up",
    "ask": "ask",
    "health": "health",
}


def _load(command: str) -> ModuleType | None:
    try:
        return importlib.import_module(f"beyond.commands.{COMMANDS[command]}")
    except ModuleNotFoundError as exc:
        if exc.name == f"beyond.commands.{COMMANDS[command]}":
            return None  # not built yet
        raise


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="beyond",
        description="Interpret and describe human actions with grounded affordances.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        if only is not None and name != only:
            continue
        module = _load(name)
        if module is None:
            continue
        cmd = sub.add_parser(name, help=getattr(module, "HELP", None))
        module.add_arguments(cmd)
        cmd.set_defaults(_module=module)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args_list = list(sys.argv[1:] if argv is None else argv)
    first = args_list[0] if args_list else None
    parser = build_parser(first if first in COMMANDS else None)
    args = parser.parse_args(args_list)
    module = getattr(args, "_module", None)
    if module is None:
        parser.print_help()
        return 2
    try:
        return int(module.run(args) or 0)
    except InputError as exc:
        print(f"beyond {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
