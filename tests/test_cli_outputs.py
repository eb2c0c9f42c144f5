"""Where commands write: under the outputs folder (runtime.outputs) or where a path given says,
never into the current folder unless a path was given; a command that fails leaves nothing."""

from __future__ import annotations

import argparse
import os
import subprocess
from pathlib import Path

import pytest

from beyond_self.cli import build_parser
from beyond_self.runtime.outputs import OUT_DIR_VAR
from beyond_self.services.launcher import BEYOND


def run_in(cwd: Path, *args: str, out: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, OUT_DIR_VAR: str(out)}
    return subprocess.run(
        [*BEYOND, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=300
    )


def parsers(
    parser: argparse.ArgumentParser, name: str = "beyond"
) -> list[tuple[str, argparse.ArgumentParser]]:
    found: list[tuple[str, argparse.ArgumentParser]] = [(name, parser)]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub, child in action.choices.items():
                found += parsers(child, f"{name} {sub}")
    return found


def test_no_option_defaults_to_a_path_in_the_current_folder() -> None:
    """A relative default path is the current folder's: every default output is under the
    outputs folder (decided when the command runs), or the option is required."""
    relative = [
        f"{name} {action.option_strings or action.dest}"
        for name, parser in parsers(build_parser())
        for action in parser._actions
        if isinstance(action.default, Path) and not action.default.is_absolute()
    ]
    assert relative == []


def test_a_failing_command_leaves_no_output_folder(tmp_path: Path) -> None:
    cwd, out = tmp_path / "cwd", tmp_path / "outputs"
    cwd.mkdir()
    done = run_in(cwd, "reproduce", "--data", "no-such-data", "-o", "out/repro", out=out)
    assert done.returncode == 2, done.stderr
    assert "no-such-data" in done.stderr
    assert list(cwd.iterdir()) == [] and not out.exists()


def test_gesture_plots_go_under_the_outputs_folder_unless_given(tmp_path: Path) -> None:
    cwd, out = tmp_path / "cwd", tmp_path / "outputs"
    cwd.mkdir()
    args = ("gesture", "evaluate", "default", "synthetic", "--count", "2")
    done = run_in(cwd, *args, out=out)
    assert done.returncode == 0, done.stderr
    assert list(cwd.iterdir()) == []
    assert sorted(p.suffix for p in (out / "gesture-evaluation").iterdir()) == [".png", ".png"]
    given = run_in(cwd, *args, "-o", "plots", out=out)
    assert given.returncode == 0, given.stderr
    assert [p.name for p in cwd.iterdir()] == ["plots"]


def test_the_ros2_bridge_logs_under_the_outputs_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`beyond ros2 bridge` and `beyond up --ros2` (which passes no folder) log what the bridge
    said in ros2/ under the outputs folder, not in ./out/ros2."""
    from beyond_self.services.ros2_bridge import Ros2Bridge

    monkeypatch.setenv(OUT_DIR_VAR, str(tmp_path))
    args = build_parser().parse_args(["ros2", "bridge"])
    assert args.out_dir is None
    assert Ros2Bridge().out_dir == tmp_path / "ros2"
    assert Ros2Bridge(out_dir=str(tmp_path / "given")).out_dir == tmp_path / "given"
