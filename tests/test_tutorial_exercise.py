"""The newcomer's exercise of docs/tutorial.md ("Change what a service reports"): the diff on the
page, applied to a copy of the package, touches only the schema, the cognition function and at
most five lines of services/objects.py, and the new field arrives on the bus."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

from busutil_net import private_config

REPO = Path(__file__).resolve().parent.parent
PACKAGE = REPO / "beyond_self"
ALLOWED = {
    "beyond_self/schemas/messages.py",
    "beyond_self/cognition/vision/features.py",
    "beyond_self/services/objects.py",
}
OBJECTS_LINES_MAX = 5


def exercise_diff() -> str:
    """The `diff` block after the exercise marker of the tutorial."""
    text = (REPO / "docs" / "tutorial.md").read_text(encoding="utf-8")
    found = re.search(r"<!-- exercise:[^>]*-->\s*```diff\n(.*?)\n```", text, re.S)
    assert found, "docs/tutorial.md has no exercise diff block"
    return found.group(1) + "\n"


def changed_lines(diff: str) -> dict[str, int]:
    """Per file of `diff`, the lines it adds or removes."""
    counts: dict[str, int] = {}
    current = ""
    for line in diff.splitlines():
        if line.startswith("+++ "):
            current = line[4:].removeprefix("b/")
            counts.setdefault(current, 0)
        elif line.startswith(("+", "-")) and not line.startswith("--- "):
            counts[current] += 1
    return counts


def test_the_exercise_touches_only_the_schema_the_function_and_five_lines() -> None:
    counts = changed_lines(exercise_diff())
    assert set(counts) == ALLOWED, counts
    assert 0 < counts["beyond_self/services/objects.py"] <= OBJECTS_LINES_MAX, counts


def test_the_exercises_field_arrives_on_the_bus(tmp_path: Path) -> None:
    copy = tmp_path / "beyond_self"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    (tmp_path / "area.diff").write_text(exercise_diff(), encoding="utf-8")
    applied = subprocess.run(
        ["git", "apply", "area.diff"], cwd=tmp_path, capture_output=True, text=True
    )
    assert applied.returncode == 0, applied.stderr  # the page's diff still fits the code
    # the copy is first on the path, ahead of the checkout's editable install
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    config = private_config()
    probe = [
        sys.executable, str(REPO / "tests" / "segmenter_probe.py"),
        str(REPO / "recordings" / "tap-ball-grasp-box.mcap"), config.robot, str(config.port),
    ]  # fmt: skip
    run = subprocess.run(probe, env=env, capture_output=True, text=True, timeout=240)
    assert run.returncode == 0, run.stderr[-2000:]
    found = json.loads(run.stdout.strip().splitlines()[-1])
    assert "area_m2" in found, found  # the new field, on the bus
    # the equivalent diameter (size) is 2*sqrt(area/pi) in metres: the area is pi*(d/2)^2
    diameter = found["size"][0]
    assert found["area_m2"] > 0
    assert math.isclose(found["area_m2"], math.pi * (diameter / 2) ** 2, rel_tol=1e-6), found


def test_the_shipped_schema_is_not_changed_by_the_exercise() -> None:
    """The exercise stays an exercise: the shipped message has no such field."""
    from beyond_self.schemas import DetectedObject

    assert "area_m2" not in DetectedObject.__struct_fields__
