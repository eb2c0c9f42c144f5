"""A bench's last line kept in bench/results/NAME.json, with the date, the machine and where it
comes from (command and commit): the docs' performance page is made from these files, so each
figure on it says how it was measured."""

from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent


def git(*argv: str) -> str:
    done = subprocess.run(["git", *argv], cwd=REPO, capture_output=True, text=True, check=False)
    return done.stdout.strip()


def machine(load_at_start: float, load_note: str = "") -> str:
    """The machine as the results files describe it, with the load before and after the run."""
    cpuinfo = Path("/proc/cpuinfo").read_text()
    model = next(
        (x.split(":", 1)[1].strip() for x in cpuinfo.splitlines() if "model name" in x), ""
    )
    return (
        f"{os.cpu_count()} cores ({model}), Linux {platform.release()}, Python "
        f"{platform.python_version()}; load average {load_at_start:.2f} at the start, "
        f"{os.getloadavg()[0]:.2f} at the end (one-minute figure{load_note})"
    )


def save(
    name: str,
    result: dict[str, Any],
    began: datetime.datetime,
    load_at_start: float,
    *,
    how: str = "",
    load_note: str = "",
) -> None:
    """`result` into bench/results/`name`.json, keeping the file's table (its rows are templates
    over `result`). `how` says more of the run (e.g. the search's mode) after the command; a
    run of code with changes not committed says so."""
    path = REPO / "bench" / "results" / f"{name}.json"
    old = json.loads(path.read_text(encoding="utf-8")) if path.exists() else {}
    commit = git("rev-parse", "--short", "HEAD")
    changed = git(
        "status", "--porcelain", "--", "bench/", "beyond_self/", ":(exclude)bench/results"
    )
    dirty = " with uncommitted changes" if changed else ""
    command = " ".join([".venv/bin/python", f"bench/{name}.py", *sys.argv[1:]])
    data = {
        "script": f"bench/{name}.py",
        "date": began.strftime("%Y-%m-%d"),
        "machine": machine(load_at_start, load_note),
        "provenance": (
            f"printed by `{command}`{how} on {began:%Y-%m-%d} from {began:%H:%M} UTC at commit "
            f"{commit}{dirty}, its last line kept as `result`"
        ),
        "result": result,
        "table": old.get("table", []),
    }
    path.write_text(json.dumps(data, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
    print(f"written: {path.relative_to(REPO)}", file=sys.stderr)
