"""Entry point of the `beyond` command.

Each command lives in its own module under `beyond_self.commands`, imported only when that
command runs: the science stack (pgmpy, hmmlearn) and the bus (zenoh) are slow to import, and a
service or a quick `beyond inspect` should not pay for what it does not use. A command module
exposes `add_arguments(parser)`, `run(args) -> int` and may expose `HELP` (one line). Errors
meant for the user are `core.errors.InputError`: one line on stderr, exit status 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from types import ModuleType
from typing import NoReturn

from beyond_self import __version__
from beyond_self.core.errors import InputError

# command name -> module under beyond_self.commands. One table, so `beyond --help` lists everything.
COMMANDS: dict[str, str] = {
    "demo": "demo",
    "bn": "bn",
    "gesture": "gesture",
    "describe": "describe",
    "reproduce": "reproduce",
    "learn": "learn",
    "segment": "segment",
    "simulate": "simulate",
    "video": "video",
    "record": "record",
    "replay": "replay",
    "inspect": "inspect_cmd",
    "topics": "topics",
    "echo": "echo",
    "hz": "hz",
    "bw": "bw",
    "info": "info",
    "pub": "pub",
    "schemas": "schemas_cmd",
    "foxglove": "foxglove",
    "router": "router",
    "service": "service",
    "up": "up",
    "analyse": "analyse",
    "ask": "ask",
    "keys": "keys",
    "health": "health",
    "ros2": "ros2",
}


def _load(command: str) -> ModuleType | None:
    try:
        return importlib.import_module(f"beyond_self.commands.{COMMANDS[command]}")
    except ModuleNotFoundError as exc:
        if exc.name == f"beyond_self.commands.{COMMANDS[command]}":
            return None  # not built yet
        raise


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (what was wrong), then exit 2, like InputError.

    argparse prints the whole usage first; a script reading the first line of stderr (and a
    person reading a log) should see the error itself. Subparsers inherit the class."""

    def error(self, message: str) -> NoReturn:
        text = " ".join(message.split())
        self.exit(2, f"{self.prog}: error: {text} (see {self.prog} --help)\n")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="beyond",
        description="Interpret and describe human actions with grounded affordances.",
    )
    parser.add_argument("--version", action="version", version=f"beyond-self {__version__}")
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


def entry() -> int:
    """The `beyond` program: `main`, then, if the command opened a Zenoh session, leave without
    the interpreter's teardown, which can abort a process that finished cleanly once Zenoh's
    native threads are up (runtime.process.exit_process). A process a supervisor started is
    bound to it first (runtime.process.lifeline): it dies with it."""
    from beyond_self.runtime.process import lifeline

    lifeline.bind()
    code = main()
    bus = sys.modules.get("beyond_self.runtime.bus.session")
    if bus is not None and bus.sessions_opened:
        from beyond_self.runtime.process import exit_process

        exit_process(code)
    return code


def main(argv: Sequence[str] | None = None) -> int:
    args_list = list(sys.argv[1:] if argv is None else argv)
    first = args_list[0] if args_list else None
    parser = build_parser(first if first in COMMANDS else None)
    try:
        args = parser.parse_args(args_list)
    except SystemExit as exc:  # a usage error (already printed, one line) or --help
        return exc.code if isinstance(exc.code, int) else 2
    module = getattr(args, "_module", None)
    if module is None:
        parser.print_help()
        return 2
    try:
        return _run(module, args)
    finally:
        for text in getattr(args, "_notes", None) or ():  # argtypes.note: after the output
            print(f"beyond {args.command}: note: {text}", file=sys.stderr)


def _run(module: ModuleType, args: argparse.Namespace) -> int:
    """Run the command; bad input of any kind is one line and exit status 2."""
    try:
        return int(module.run(args) or 0)
    except InputError as exc:
        print(f"beyond {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `beyond inspect FILE | head`: the reader has what it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no error at exit
        return 141  # as a shell reports a command ended by SIGPIPE
    except OSError as exc:
        # a file the user named (or the folder it is in) cannot be read or written: bad input
        # from the user's side, not a bug; the path checks in argtypes catch most of them earlier
        where = f": {exc.filename}" if exc.filename else ""
        print(f"beyond {args.command}: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2
    except UnicodeDecodeError as exc:
        print(
            f"beyond {args.command}: error: a file given is not UTF-8 text ({exc.reason})",
            file=sys.stderr,
        )
        return 2
    except RecursionError:
        # json and yaml parse nested data recursively: a file of 50,000 '[' is bad input
        print(
            f"beyond {args.command}: error: a file given is nested too deeply to read",
            file=sys.stderr,
        )
        return 2
    except KeyboardInterrupt:
        return 130
