"""The shipped recordings: each is listed in recordings/README.md with the command that makes it,
that command makes it byte for byte, they stay small, and the pipeline reads the demo right."""

from __future__ import annotations

import shlex
from pathlib import Path

import pytest

from beyond_self.cli import main
from beyond_self.cognition.paths import RECORDINGS
from beyond_self.commands.simulate import check_recording, checks_pass

README = RECORDINGS / "README.md"
DEMO = "tap-ball-grasp-box.mcap"


def _commands() -> dict[str, list[str]]:
    """file name -> the `beyond simulate` arguments that README.md gives for it."""
    out = {}
    for line in README.read_text(encoding="utf-8").splitlines():
        if not line.startswith("beyond simulate "):
            continue
        args = shlex.split(line)[1:]
        target = Path(args[args.index("-o") + 1])
        assert target.parent == Path("recordings"), line
        out[target.name] = args
    return out


def _shipped() -> list[str]:
    return sorted(p.name for p in RECORDINGS.glob("*.mcap"))


def test_every_shipped_recording_is_listed_with_its_command() -> None:
    shipped = _shipped()
    assert DEMO in shipped and len(shipped) >= 3
    commands = _commands()
    assert sorted(commands) == shipped
    text = README.read_text(encoding="utf-8")
    for name in shipped:
        assert f"`{name}`" in text  # in the table too, with what it shows


def test_shipped_recordings_total_under_5_mb() -> None:
    total = sum(p.stat().st_size for p in RECORDINGS.glob("*.mcap"))
    assert 0 < total < 5_000_000


@pytest.mark.parametrize("name", _shipped())
def test_the_readme_command_regenerates_it_byte_for_byte(name: str, tmp_path: Path) -> None:
    args = list(_commands()[name])
    out = tmp_path / name
    args[args.index("-o") + 1] = str(out)
    assert main(args) == 0
    assert out.read_bytes() == (RECORDINGS / name).read_bytes(), (
        f"recordings/{name} is not what `beyond {shlex.join(args)}` makes now; if a generator "
        "changed on purpose, regenerate it with the command in recordings/README.md"
    )


def test_the_pipeline_reads_the_demo_right() -> None:
    checks = check_recording(RECORDINGS / DEMO)
    assert checks_pass(checks, 2)
    tap, grasp = sorted(checks, key=lambda c: c.index)
    assert (tap.action, tap.labels["Shape"], tap.labels["ObjVel"]) == ("tap", "circle", "fast")
    assert (grasp.action, grasp.labels["Shape"], grasp.labels["Color"]) == ("grasp", "box", "blue")
