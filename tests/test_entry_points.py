"""Every script of the repository answers `--help` and exits: a user who asks what a script does
is told, and nothing starts (a service run as a script parses its command line in
`Service.main`, so the README's and runtime/README.md's services do too).

The scripts are found, not listed: every file with a `__main__` guard, except the test suite's
own drivers (tests/*.py), which the tests start with the arguments they need.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from test_runtime_example import example_source

REPO = Path(__file__).resolve().parents[1]
SKIPPED_DIRS = {".venv", ".git", "build", "dist"}
# real rclpy nodes: they run in the side environment with ROS 2's wheels (tests/rclpyutil.py),
# never in ours, and the tests and bench that start them check they answer
SIDE_ENVIRONMENT = "rclpy_nodes"


def scripts() -> list[Path]:
    found = []
    for path in sorted(REPO.rglob("*.py")):
        rel = path.relative_to(REPO)
        if SKIPPED_DIRS & set(rel.parts) or SIDE_ENVIRONMENT in rel.parts:
            continue
        if rel.parent == Path("tests"):
            continue
        if 'if __name__ == "__main__":' in path.read_text(encoding="utf-8"):
            found.append(rel)
    return found


def answers_help(script: Path) -> subprocess.CompletedProcess[str]:
    # stdin closed, a deadline: a script that ignores --help and starts its work fails here
    return subprocess.run(
        [sys.executable, str(script), "--help"],
        cwd=REPO,
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_the_scripts_are_found() -> None:
    found = {str(p) for p in scripts()}
    assert {"bench/gestures.py", "docs/examples/my_speech.py"} <= found
    assert "tests/runtime_examples/doubler.py" in found
    assert "beyond_self/cognition/bn/synthetic.py" in found  # the package's own, at its path


@pytest.mark.parametrize("script", scripts(), ids=str)
def test_every_script_answers_help_and_exits(script: Path) -> None:
    done = answers_help(script)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("usage: "), done.stdout[:500]
    assert "show this help message and exit" in done.stdout


def test_the_runtime_readme_service_answers_help(tmp_path: Path) -> None:
    script = tmp_path / "timer.py"
    script.write_text(example_source(), encoding="utf-8")
    done = answers_help(script)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "Says how long each gesture lasted." in done.stdout  # the module's docstring
    assert "--port PORT" in done.stdout and "service 'timer'" in done.stdout


def test_a_bad_option_of_a_service_script_is_one_line_and_exit_2() -> None:
    done = subprocess.run(
        [sys.executable, "tests/runtime_examples/doubler.py", "--port", "0"],
        cwd=REPO,
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2
    assert done.stderr.splitlines()[-1].startswith("doubler.py: error: argument --port")
