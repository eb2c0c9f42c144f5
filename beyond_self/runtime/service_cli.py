"""A service script's command line (`python my_service.py --help`, `Service.main`).

A service run as a script answers `--help` and exits, takes the bus options every `beyond`
command takes, and its own (`Service.add_arguments`); what it needs outside Python is checked
first (`Service.check_requirements`), so a missing program is one line, not a failure inside
the first message's handler.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping, Sequence
from typing import Any, Protocol

from beyond_self.core.errors import InputError
from beyond_self.runtime import process
from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args


class ScriptService(Protocol):
    """What a command line is made from: a service (runtime.service.Service), its class's
    docstring or its module's, its name, its own options and what it needs outside Python."""

    name: str

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None: ...
    @classmethod
    def check_requirements(cls) -> None: ...


def options_from_command_line(
    cls: type[ScriptService], argv: Sequence[str] | None, given: Mapping[str, Any]
) -> dict[str, Any]:
    """The constructor's keyword arguments: `given`, then the command line's own options (the
    bus configuration from the bus options unless `given` holds a config or a bus). `--help`,
    a bad option or a missing requirement: said on stderr, and the process exits (0 or 2)."""
    parser = argparse.ArgumentParser(
        description=cls.__doc__ or sys.modules[cls.__module__].__doc__,
        epilog=f"Runs as service {cls.name!r} until SIGINT or SIGTERM.",
        formatter_class=argparse.RawDescriptionHelpFormatter,  # a docstring's lines as written
    )
    add_bus_arguments(parser)
    bus_options = set(vars(parser.parse_args([])))
    cls.add_arguments(parser)
    parsed = vars(parser.parse_args(sys.argv[1:] if argv is None else argv))
    options = dict(given)
    try:
        cls.check_requirements()
        if "config" not in options and "bus" not in options:
            options["config"] = config_from_args(argparse.Namespace(**parsed))
    except InputError as exc:
        print(f"{parser.prog}: error: {exc}", file=sys.stderr, flush=True)
        process.exit_process(2)
    options.update({k: v for k, v in parsed.items() if k not in bus_options and v is not None})
    return options
