"""One vocabulary across commands: every option says what it is for, and a flag several commands
share means the same in each (ports, outputs, durations, data folders); older spellings still
work and say what replaced them; the docs name every key. In-process, except one run of `echo`."""

from __future__ import annotations

import argparse
import os
import re
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from busutil_net import REPO, free_port

from beyond_self.cli import build_parser, main
from beyond_self.commands import argtypes
from beyond_self.runtime.bus.cliargs import _port, config_from_args
from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.bus.session import open_failure
from beyond_self.schemas.keys import ALIVE, HEALTH, PROGRESS, STREAMS
from beyond_self.services.launcher import BEYOND

SECONDS = ("--duration", "--timeout", "--wait-timeout", "--window")


def options() -> Iterator[tuple[str, argparse.ArgumentParser, argparse.Action]]:
    """(command, its parser, one of its arguments) for every command and subcommand."""

    def walk(
        parser: argparse.ArgumentParser, path: str
    ) -> Iterator[tuple[str, argparse.ArgumentParser, argparse.Action]]:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    yield from walk(sub, f"{path} {name}")
            elif not isinstance(action, argparse._HelpAction | argparse._VersionAction):
                yield path, parser, action

    yield from walk(build_parser(), "beyond")


ALL = list(options())


def named(flag: str) -> list[tuple[str, argparse.Action]]:
    return [(cmd, a) for cmd, _, a in ALL if flag in a.option_strings]


def test_every_option_of_every_command_says_what_it_is_for() -> None:
    silent = [
        f"{cmd} {'/'.join(a.option_strings) or a.dest}"
        for cmd, _, a in ALL
        if not a.help or a.help == argparse.SUPPRESS
    ]
    assert silent == []
    assert len(ALL) > 200  # every command was walked


def test_port_is_the_bus_port_everywhere() -> None:
    ports = named("--port")
    assert len(ports) >= 14
    for cmd, action in ports:
        assert action.dest == "port" and action.type is _port, cmd
        assert "rendezvous port" in str(action.help), cmd
    (ws,) = [a for cmd, a in named("--ws-port") if cmd == "beyond foxglove"]
    assert ws.default == 8765 and "WebSocket" in str(ws.help)


def test_outputs_are_dash_o_everywhere_and_out_is_an_old_spelling() -> None:
    outputs = named("--output")
    assert {cmd for cmd, _ in outputs} >= {
        "beyond bn learn",
        "beyond gesture train",
        "beyond gesture evaluate",
        "beyond reproduce",
        "beyond learn",
        "beyond simulate",
        "beyond record",
        "beyond foxglove",
    }
    for cmd, action in outputs:
        assert action.option_strings == ["-o", "--output"] and action.dest == "output", cmd
        assert action.type in (argtypes.output_file, argtypes.output_dir), cmd
    for cmd, action in named("--out"):
        assert action.dest == "output" and "deprecated" in str(action.help), cmd
        assert action.option_strings == ["--out"], cmd


def test_durations_are_seconds_and_flags_keep_their_meaning() -> None:
    for flag in SECONDS:
        for cmd, action in named(flag):
            assert getattr(action.type, "what", None) == "seconds", (cmd, flag)
    for cmd, action in named("--json"):
        assert isinstance(action, argparse._StoreTrueAction), cmd
    for cmd, action in named("--seed"):
        assert action.type is argtypes.seed, cmd
    for cmd, action in named("--rate"):  # a speed factor; `pub --rate` is Hz, as in ROS 2
        expected = "Hz" if cmd == "beyond pub" else argtypes.rate.what  # type: ignore[attr-defined]
        assert getattr(action.type, "what", None) == expected, cmd


def parse(argv: list[str]) -> argparse.Namespace:
    return build_parser(argv[0]).parse_args(argv)


def test_older_spellings_work_and_say_what_replaced_them(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Said once the command has run, so that an error stays the first line of stderr."""
    args = parse(["foxglove", "--bus-port", "7999"])
    assert args.port == 7999 and args.ws_port == 8765
    assert args._notes == ["--bus-port is deprecated; use --port"]
    args = parse(["reproduce", "--out", str(tmp_path / "r")])
    assert args.output == tmp_path / "r"
    args = parse(["gesture", "train", "--out", str(tmp_path / "m.json")])
    assert args.output == tmp_path / "m.json"
    with pytest.raises(SystemExit):  # one output, not two
        parse(["learn", "--out", str(tmp_path), "-o", str(tmp_path)])
    capsys.readouterr()
    assert main(["reproduce", "--out", str(tmp_path / "r"), "--data", str(tmp_path / "no")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("beyond reproduce: error: ") and len(err) == 2
    assert err[1] == "beyond reproduce: note: --out is deprecated; use -o/--output"


def test_data_folders_are_relative_to_the_current_folder(tmp_path: Path) -> None:
    here = Path.cwd()
    os.chdir(tmp_path)
    try:
        args = parse(["reproduce", "--data", "data", "-o", "out"])
    finally:
        os.chdir(here)
    assert args.data == tmp_path / "data" and args.data.is_absolute()


def test_a_listening_tool_waits_for_a_router_no_longer_than_its_duration(tmp_path: Path) -> None:
    args = parse(["echo", "--secure", str(tmp_path), "beyond/r/x", "--duration", "2"])
    assert config_from_args(args).connect_timeout_ms == 2000
    zenoh_said = (
        "Unable to connect to any of [Single(tls/127.0.0.1:7447)]. Timeout! at "
        "/root/.cargo/git/checkouts/zenoh-9c599d5ef3e0480e/cc83980/zenoh/src/net/runtime/"
        "orchestrator.rs:388."
    )
    line = open_failure(BusConfig(mode="client", connect_timeout_ms=2000), Exception(zenoh_said))
    assert ".rs" not in line and "within 2 s" in line and "beyond router" in line
    nobody = f"tcp/127.0.0.1:{free_port()}"  # a client, as --secure makes it, of no router
    echo = ["echo", "--mode", "client", "--connect", nobody, "beyond/robot/x"]
    done = subprocess.run(
        [*BEYOND, *echo, "--duration", "1"],
        env={k: v for k, v in os.environ.items() if not k.startswith("BEYOND_")},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert f"no router answered at {nobody} within 1 s" in done.stderr
    assert ".rs" not in done.stderr


def test_the_docs_name_every_key_and_schemas_list_names_progress() -> None:
    text = (REPO / "runtime" / "README.md").read_text(encoding="utf-8")
    table = text.split("## Key expressions", 1)[1].split("\n## ", 1)[0]
    documented = set(re.findall(r"^\| `beyond/<robot>/([^`]+)`", table, re.M))
    expected = {suffix for suffix, _ in STREAMS.values()}
    expected |= {f"{HEALTH}/<service>", f"{PROGRESS}/<service>", f"{ALIVE}/<service>"}
    assert expected <= documented, expected - documented
    done = subprocess.run([*BEYOND, "schemas", "list"], capture_output=True, text=True, timeout=60)
    (progress,) = [line for line in done.stdout.splitlines() if line.startswith("Progress ")]
    assert "beyond/<robot>/progress/<service>" in progress and "query/reply" not in progress
    assert "handled.*" in progress  # its stamps, each a Time in JSON
