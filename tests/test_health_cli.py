"""`beyond health`: which services it checks when none is named, and what it answers.

The container health check runs it without names, so it must find the container's own service
(or router) from the processes it can see; tests/test_containers.py runs it in real containers.
"""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path

import pytest

from beyond_self.cli import main
from beyond_self.commands.health import local_roles
from beyond_self.services.launcher import BEYOND

REPO = Path(__file__).resolve().parent.parent


def fake_proc(tmp_path: Path, *cmdlines: list[str]) -> Path:
    tmp_path.mkdir(exist_ok=True)
    for pid, argv in enumerate(cmdlines, start=1):
        (tmp_path / str(pid)).mkdir()
        (tmp_path / str(pid) / "cmdline").write_bytes(b"\0".join(a.encode() for a in argv) + b"\0")
    (tmp_path / "self").mkdir()  # not a pid: ignored
    return tmp_path


def test_local_roles_come_from_the_beyond_processes(tmp_path: Path) -> None:
    proc = fake_proc(
        tmp_path,
        ["/usr/libexec/podman/catatonit", "--", "beyond", "service", "gestures"],
        [
            "/opt/python/bin/python",
            "/opt/python/bin/beyond",
            "service",
            "gestures",
            "--config",
            "x",
        ],
        [*BEYOND, "service", "describer"],
        ["/usr/bin/python3", "/usr/local/bin/beyond", "router", "--zenoh-config", "r.json5"],
        ["beyond", "health"],
        ["sleep", "service", "objects"],
    )
    assert local_roles(proc) == (["gestures", "describer"], True)
    assert local_roles(fake_proc(tmp_path / "none", ["bash"])) == ([], False)


def test_no_service_and_none_running_is_an_input_error(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("beyond_self.commands.health.local_roles", lambda: ([], False))
    assert main(["health"]) == 2
    err = capsys.readouterr().err
    assert "no SERVICE given" in err and err.count("\n") == 1


def test_a_running_service_answers_and_a_missing_one_does_not(tmp_path: Path) -> None:
    env = {
        **{k: v for k, v in os.environ.items() if not k.startswith("BEYOND_")},
        "BEYOND_ROBOT": f"health{os.getpid()}",
        "BEYOND_ZENOH_PORT": str(20000 + os.getpid() % 20000),
        "PYTHONPATH": str(REPO),
    }
    beyond = [*BEYOND]
    service = subprocess.Popen([*beyond, "service", "objects"], env=env, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60
        while True:
            ok = subprocess.run(
                [*beyond, "health", "objects", "--timeout", "5"],
                env=env, capture_output=True, text=True, timeout=60,
            )  # fmt: skip
            if ok.returncode == 0 or time.monotonic() > deadline or service.poll() is not None:
                break
        assert ok.returncode == 0, ok.stderr
        assert ok.stdout.startswith("healthy: objects up ")
        missing = subprocess.run(
            [*beyond, "health", "gestures", "--timeout", "1"],
            env=env, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert missing.returncode == 1
        assert "no health reply from gestures" in missing.stderr
    finally:
        service.terminate()
        service.wait(30)
