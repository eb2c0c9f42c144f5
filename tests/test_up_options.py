"""`beyond up --help` lists every group of options `commands/up_options.py` defines, in the order
the groups are added, once each, with the ROS 2 bridge's and the bus's after them."""

from __future__ import annotations

import argparse
from collections.abc import Callable

import pytest

from beyond_self.cli import main
from beyond_self.commands import up_options

GROUPS: list[Callable[[argparse.ArgumentParser], None]] = [
    up_options.add_source_options,
    up_options.add_service_options,
    up_options.add_run_options,
    up_options.add_side_options,
]


def options_of(add: Callable[[argparse.ArgumentParser], None]) -> list[str]:
    parser = argparse.ArgumentParser(add_help=False)
    add(parser)
    return [a.option_strings[0] for a in parser._actions]


def help_text(capsys: pytest.CaptureFixture[str]) -> str:
    assert main(["up", "--help"]) == 0
    return capsys.readouterr().out


def test_help_lists_every_group_in_order(capsys: pytest.CaptureFixture[str]) -> None:
    text = help_text(capsys)
    options = text[text.index("options:") :]
    listed = [line.split()[0].rstrip(",") for line in options.splitlines()[1:] if line[2:3] == "-"]
    expected = [o for add in GROUPS for o in options_of(add)]
    assert all(options_of(add) for add in GROUPS)
    assert [o for o in listed if o in expected] == expected
    assert listed.index("--ros2") > listed.index(expected[-1])
    assert listed.index("--robot") > listed.index("--ros2")
    assert len(listed) == len(set(listed))


def test_the_source_options_exclude_each_other(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["up", "--recording", "a.mcap", "--log", "data.log"]) == 2
    assert "not allowed with argument" in capsys.readouterr().err
