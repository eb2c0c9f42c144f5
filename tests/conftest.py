"""Tests needing the article's data skip, with the reason, only when it is absent."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from busutil_net import busy_loops
from netns_util import TwoHosts, unavailable

from beyond_self.cognition.paths import SOURCES, shared_data_dir
from beyond_self.runtime.outputs import OUT_DIR_VAR


@pytest.fixture(scope="session", autouse=True)
def run_outputs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """What the services the tests start write (runtime.outputs) goes to a folder of the
    session's, never into the state folder of the user running the suite."""
    folder = tmp_path_factory.mktemp("outputs")
    before = os.environ.get(OUT_DIR_VAR)
    os.environ[OUT_DIR_VAR] = str(folder)
    yield folder
    if before is None:
        os.environ.pop(OUT_DIR_VAR, None)
    else:
        os.environ[OUT_DIR_VAR] = before


@pytest.fixture(autouse=True)
def test_outputs(run_outputs: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Each test's own outputs folder, below the session's: what an interrupted `beyond up`
    keeps to go on with (runtime.resilience.run_state) is not found by the next test's."""
    folder = run_outputs / tmp_path.name
    monkeypatch.setenv(OUT_DIR_VAR, str(folder))
    # and for a process started without our variables: not the state folder of the user
    monkeypatch.setenv("XDG_STATE_HOME", str(folder / "xdg"))
    return folder


@pytest.fixture(scope="session")
def shared_data() -> Path:
    root = shared_data_dir()
    if root is None:
        pytest.skip(f"../shared/data is absent (the article's data, from {SOURCES})")
    return root


@pytest.fixture
def hosts() -> Iterator[TwoHosts]:
    """Two network namespaces joined by a veth pair (tests/netns_util.py), removed afterwards
    with every process started in them; skips with the reason where they cannot be made.
    NETNS_DUMP=FOLDER keeps each process's output there, timed (for debugging)."""
    reason = unavailable()
    if reason is not None:
        pytest.skip(reason)
    h = TwoHosts()
    try:
        yield h
    finally:
        h.close()
        if os.environ.get("NETNS_DUMP"):
            for proc in h.procs:
                Path(os.environ["NETNS_DUMP"], f"{proc.name}.log").write_text(
                    "\n".join(f"{t:.3f} {line}" for t, line in proc.lines)
                )
        assert h.namespaces_left() == [], "namespaces left behind"
        assert all(p.popen.poll() is not None for p in h.procs), "processes left behind"


# The JavaScript packages third-party tools read our files and streams with: @mcap/core (the MCAP
# reader Foxglove uses), fzstd (its zstd decompressor), @foxglove/schemas (the official JSON
# Schemas of Foxglove's message types), and @foxglove/ws-protocol (the npm Foxglove WebSocket
# client) on ws (the WebSocket its README names for Node.js). Installed once per run into a
# temporary folder.
NODE_PACKAGES = (
    "@mcap/core@2",
    "@foxglove/schemas@2",
    "fzstd@0.1",
    "@foxglove/ws-protocol@0.8",
    "ws@8",
)


@pytest.fixture(scope="session")
def node_modules(tmp_path_factory: pytest.TempPathFactory) -> Path:
    import shutil
    import subprocess

    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        pytest.skip("node and npm are absent (the JavaScript readers run on Node.js)")
    folder = tmp_path_factory.mktemp("node")
    (folder / "package.json").write_text('{"name": "beyond-self-tests", "private": true}\n')
    done = subprocess.run(
        [npm, "install", "--no-audit", "--no-fund", "--loglevel=error", *NODE_PACKAGES],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=300,
    )
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["?"])[-1]
        pytest.skip(f"npm install {' '.join(NODE_PACKAGES)} failed: {last}")
    return folder / "node_modules"


@pytest.fixture(scope="module")
def busy_machine() -> Iterator[str]:
    """A loaded machine for the module's tests, said in words for their reports. With two cores
    or more: everything the tests start confined to one core (the worker's own) beside a
    process spinning on it, so their services get a fraction of a core each and are preempted
    at any instruction, as on a loaded machine, while the suite's other worker keeps its core.
    On one core: three spinners."""
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        with busy_loops(3):
            yield "3 busy loops"
        return
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw")
    cpu = cpus[int(worker) % len(cpus) if worker.isdigit() else 0]
    with busy_loops(1, cpu=cpu):
        yield f"confined to core {cpu} beside a busy loop"


# -- figures a passing test shows in CI's log ---------------------------------------------------
# Tests run in pytest-xdist workers (Makefile), a file at a time. A worker's output never
# reaches the terminal, so a figure a test wants seen in CI's log (build times, outage
# timelines) goes through its report instead.

SHOWN = "shown"


@pytest.fixture
def show(request: pytest.FixtureRequest) -> Callable[[str], None]:
    """Call it with text to print in the run's summary, even when the test passes."""

    def add(text: str) -> None:
        request.node.user_properties.append((SHOWN, text))

    return add


# The files that take longest (most of it waiting on podman, pip, paced replays at real time or
# services starting again after a kill), longest first: xdist hands them out before the rest.
# Every file of more than about 15 s of a run is named: one left out starts among the short
# files near the end and finishes alone (a run of 2026-12-07: test_ros2_drivers.py, 125 s under
# load, started last and ended 27 s after the other three workers).
LONG_FILES = (
    "test_event_time.py",
    "test_chaos_b.py",
    "test_chaos_a.py",
    "test_containers.py",
    "test_deploy_netns.py",
    "test_secure_netns.py",
    "test_fleet_netns.py",
    "test_package.py",
    "test_fleet.py",
    "test_fleet_shards.py",  # twelve processes start, one shard is killed mid-burst
    "test_chaos_pair.py",  # a producer and its consumer killed at once, a restart held
    "test_ros2_drivers.py",
    "test_cli_hostile.py",
    "test_bus_fuzz.py",
    "test_up_owns_children.py",
    "test_stray_messages.py",
    "test_docs_blocks.py",
    "test_site_browser.py",
    "test_pipeline_up.py",
    "test_ros2_bridge.py",
    "test_ros2_rclpy.py",  # first run: installs real rclpy into its side environment
    "test_gesture_people.py",
    "test_ros2.py",
    "test_damaged_recordings.py",
    "test_bn_inference.py",
    "test_episodes.py",
    "test_video_cli.py",
    "test_vision_pipeline.py",
    "test_live_load.py",
    "test_recording_readers.py",
    "test_foxglove_bridge.py",
    "test_entry_points.py",
    "test_simulate.py",
    "test_ask_hostile.py",
    "test_bus_tools.py",
    "test_soak.py",
    "test_bn_zero_columns.py",
    "test_gesture_cli.py",
    "test_stamp_gaps.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The long files first. The workers (Makefile: `--dist loadfile`, a file's tests in one
    worker, its module fixtures built once) take files in this order as they finish one, so
    the long ones start at once and neither worker is left with a long tail."""
    rank = {name: i for i, name in enumerate(LONG_FILES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONG_FILES)))  # stable: file order


def pytest_terminal_summary(terminalreporter: Any) -> None:
    shown: dict[str, list[str]] = {}  # each phase's report carries all the test showed so far
    for reports in terminalreporter.stats.values():
        for report in reports:
            texts = [t for k, t in getattr(report, "user_properties", ()) if k == SHOWN]
            if len(texts) > len(shown.get(report.nodeid, [])):
                shown[report.nodeid] = texts
    if shown:
        terminalreporter.section("figures shown by the tests")
        for nodeid, texts in shown.items():
            terminalreporter.write_line(f"{nodeid}:")
            for text in texts:
                terminalreporter.write_line(text.strip("\n"))
