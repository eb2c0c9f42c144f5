"""One deployment's run state is its own: `beyond up` keys it by the bus and the outputs folder,
so a demo's `--fresh` on another port never clears another deployment's unfinished run, and the
same command again still finds its own (tests/test_up_owns_children.py runs that end to end)."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from beyond_self.cognition.paths import DEMO_RECORDING
from beyond_self.commands import up
from beyond_self.runtime.bus.cliargs import config_from_args
from beyond_self.runtime.resilience.run_state import Printed, RunState
from beyond_self.runtime.resilience.state import STATE_DIR_VAR


def side_state(*argv: str) -> tuple[RunState, str, dict[str, str]]:
    """What `beyond up ARGV` takes as its state: the state, its command, its services' env."""
    parser = argparse.ArgumentParser()
    up.add_arguments(parser)
    args = parser.parse_args(["--recording", str(DEMO_RECORDING), *argv])
    config = up.local_group(config_from_args(args))
    side, _ = up.deployment(args, config, up.EventLines())
    state = up.run_state(args, side, config)
    return state, up.run_command(args, side), dict(side.env)


def unfinished(*argv: str) -> None:
    """A run of `beyond up ARGV` killed after telling gesture 1."""
    state, command, _ = side_state(*argv)
    assert state.begin(command, fresh=False) == ""
    state.told(Printed(1, described=True))


def goes_on(*argv: str) -> bool:
    state, command, _ = side_state(*argv)
    said = state.begin(command, fresh=False)
    return said.startswith("going on") and 1 in state.before


def test_a_demo_on_another_port_leaves_the_other_run_s_state() -> None:
    robot = ("--port", "17911")  # the same outputs folder, as two checkouts of one user
    unfinished(*robot)
    demo, command, _ = side_state("--port", "17900", "--fresh")  # what `make demo` runs
    assert demo.begin(command, fresh=True) == ""  # nothing of its own to clear
    assert goes_on(*robot)


@pytest.mark.parametrize(
    "other",
    [
        ("--port", "17912"),
        ("--connect", "tcp/127.0.0.1:17913"),
        ("--zenoh-config", "deploy/zenoh/robot.json5"),
    ],
)
def test_deployments_on_different_buses_keep_apart(
    other: tuple[str, ...], monkeypatch: pytest.MonkeyPatch
) -> None:
    repo = Path(__file__).resolve().parent.parent
    monkeypatch.chdir(repo)  # the config file's path as the how-to types it
    unfinished("--port", "17910")
    fresh, command, env = side_state(*other, "--fresh")
    assert fresh.begin(command, fresh=True) == ""
    _, _, env_first = side_state("--port", "17910")
    assert env[STATE_DIR_VAR] != env_first[STATE_DIR_VAR]  # the services' state too
    assert goes_on("--port", "17910")


def test_deployments_with_different_outputs_folders_keep_apart(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Also when $BEYOND_STATE_DIR names one state root for both."""
    monkeypatch.setenv(STATE_DIR_VAR, str(tmp_path / "state"))
    unfinished("--out-dir", str(tmp_path / "a"))
    fresh, command, _ = side_state("--out-dir", str(tmp_path / "b"), "--fresh")
    assert fresh.begin(command, fresh=True) == ""
    assert goes_on("--out-dir", str(tmp_path / "a"))


def test_the_same_command_again_goes_on_and_fresh_clears_only_its_own(tmp_path: Path) -> None:
    unfinished("--port", "17914")
    unfinished("--port", "17915")
    assert goes_on("--port", "17914")
    again, command, _ = side_state("--port", "17914", "--fresh")
    assert "cleared (--fresh)" in again.begin(command, fresh=True)
    assert goes_on("--port", "17915")
