"""Our files and messages as programs nobody here wrote read them: @mcap/core (Foxglove's MCAP
reader, in Node.js) with CRC checks, `pymcap-cli doctor`, and any JSON reader in JavaScript, whose
numbers are doubles (integers beyond 2^53 - 1 come back rounded)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from busutil_net import REPO

from beyond_self.runtime.recording.reader import inspect_recording

CHECKER = REPO / "tests" / "js" / "mcap_check.js"

JS_INT_MAX = 2**53 - 1


def unsafe_integers(value: Any, where: str = "$") -> Iterator[str]:
    """Where `value` (decoded JSON) holds an integer a double would round."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from unsafe_integers(v, f"{where}.{k}")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from unsafe_integers(v, f"{where}[{i}]")
    elif isinstance(value, int) and not isinstance(value, bool) and abs(value) > JS_INT_MAX:
        yield f"{where} = {value}"


def unbounded_integers(schema: Any, where: str = "$") -> Iterator[str]:
    """Where a JSON Schema allows an integer beyond 2^53 - 1 (no maximum, or a larger one),
    with the node itself (to tell stamps apart)."""
    if isinstance(schema, dict):
        if schema.get("type") == "integer":
            top = schema.get("maximum")
            low = schema.get("minimum")
            if top is None or top > JS_INT_MAX or low is None or low < -JS_INT_MAX:
                yield where
        for k, v in schema.items():
            yield from unbounded_integers(v, f"{where}.{k}")
    elif isinstance(schema, list):
        for i, v in enumerate(schema):
            yield from unbounded_integers(v, f"{where}[{i}]")


def js_reports(node_modules: Path, paths: list[Path]) -> list[dict[str, Any]]:
    done = subprocess.run(
        ["node", str(CHECKER), *map(str, paths)],
        env={**os.environ, "NODE_PATH": str(node_modules)},
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    return [json.loads(line) for line in done.stdout.splitlines()]


def doctor(path: Path) -> dict[str, Any]:
    exe = shutil.which("pymcap-cli", path=str(Path(sys.executable).parent))
    if exe is None:
        pytest.skip("pymcap-cli is not installed (pip install -e '.[dev]')")
    done = subprocess.run(
        [exe, "doctor", "--format", "jsonl", str(path)], capture_output=True, text=True, timeout=60
    )
    lines = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    summary = next(x for x in lines if x["type"] == "summary")
    summary["findings"] = [x for x in lines if x["type"] == "finding"]
    summary["returncode"] = done.returncode
    return summary


def assert_trusted(report: dict[str, Any], path: Path) -> None:
    assert "error" not in report, report
    assert report["messages"] == inspect_recording(path).messages > 0
    assert report["data_section_crc_ok"], report
    assert report["publish_time_zero"] == 0, report
    assert report["json_errors"] == 0, report
    assert report["unsafe_numbers"] == 0, report
    assert report["stamp_mismatch"] == {}, report
    assert report["timestamp_mismatch"] == {}, report
    found = doctor(path)
    errors = [f for f in found["findings"] if f["severity"] in ("error", "warning")]
    assert found["errors"] == 0 and errors == [] and found["returncode"] == 0, found


def official_schemas(node_modules: Path) -> dict[str, Any]:
    """Foxglove's own JSON Schemas of its message types (@foxglove/schemas), by name."""
    script = 'console.log(JSON.stringify(require("@foxglove/schemas/jsonschema")))'
    done = subprocess.run(
        ["node", "-e", script],
        env={**os.environ, "NODE_PATH": str(node_modules)},
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    schemas: dict[str, Any] = json.loads(done.stdout)
    return schemas
