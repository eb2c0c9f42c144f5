"""Small things a newcomer trips on (issue 42, point 5), each as the user met it.

`keys show DIR` as `keys init DIR` spells it, and a workstation's robots as typed; `router
--zenoh-config` naming the file's endpoints; `replay --start-paused` with no terminal; the
Foxglove bridge naming only the port a user can open; the run's outputs under a state folder,
never the current folder.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
from pathlib import Path

import pytest
from busutil_net import REPO, env_for, free_port, private_config

from beyond_self.runtime.bus.config import describe, load_config
from beyond_self.runtime.outputs import OUT_DIR_VAR, out_dir
from beyond_self.runtime.recording.reader import inspect_recording, read_recording
from beyond_self.runtime.security import keystore
from beyond_self.services import registry
from beyond_self.services.launcher import BEYOND
from beyond_self.services.speech import SpeechSynthesizer

RECORDING = REPO / "recordings" / "touch-box.mcap"


def beyond(
    *args: str, env: dict[str, str] | None = None, stdin: int | None = subprocess.DEVNULL
) -> subprocess.CompletedProcess[str]:
    clean = {k: v for k, v in os.environ.items() if not k.startswith("BEYOND_")}
    return subprocess.run(
        [*BEYOND, *args],
        env=env if env is not None else clean,
        cwd=REPO,
        stdin=stdin,
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("keys") / "keys"
    keystore.init(directory, registry.identities())
    keystore.add(directory, "ws-1", role="workstation", robots="lab-*")
    return directory


def test_keys_show_takes_the_keystore_as_keys_init_does(store: Path) -> None:
    positional = beyond("keys", "show", str(store))
    assert positional.returncode == 0, positional.stderr
    assert positional.stdout == beyond("keys", "show", "--dir", str(store)).stdout
    assert re.search(r"^speech\s+valid", positional.stdout, re.M)
    both = beyond("keys", "show", str(store), "--dir", str(store.parent))
    assert both.returncode == 2 and "two keystores given" in both.stderr
    rules = beyond("keys", "acl", str(store))
    assert (
        rules.returncode == 0 and rules.stdout == beyond("keys", "acl", "--dir", str(store)).stdout
    )
    assert '"ws-1"' in rules.stdout  # the rules of this keystore, not the default ones


def test_keys_show_prints_a_workstation_s_robots_as_typed(store: Path) -> None:
    shown = beyond("keys", "show", str(store)).stdout
    line = next(x for x in shown.splitlines() if x.startswith("ws-1 "))
    assert "workstation of lab-* " in line and "$" not in line


def test_the_router_names_the_endpoints_of_its_config_file(tmp_path: Path) -> None:
    port = free_port()
    file = tmp_path / "router.json5"
    file.write_text(
        f'{{ mode: "router", listen: {{ endpoints: ["tcp/127.0.0.1:{port}"] }}, '
        'connect: { endpoints: ["tcp/127.0.0.1:1"] } }'
    )
    config = load_config({}, config_file=file, mode="router")
    line = describe(config)
    assert f"listen=tcp/127.0.0.1:{port} " in line and "connect=tcp/127.0.0.1:1 " in line
    # an option still overrides the file, and the line says so
    given = load_config({}, config_file=file, mode="router", listen=["tcp/127.0.0.1:2"])
    assert "listen=tcp/127.0.0.1:2 " in describe(given)


@pytest.mark.parametrize("stdin", ["devnull", "file"])
def test_replay_start_paused_without_a_terminal_reads_stdin(stdin: str, tmp_path: Path) -> None:
    env = env_for(private_config())
    if stdin == "devnull":
        done = beyond("replay", str(RECORDING), "--start-paused", "--rate", "0", env=env)
    else:  # three steps, then the file ends: it plays on
        keys = tmp_path / "keys"
        keys.write_text("s\ns\ns\n")
        with keys.open("rb") as f:
            done = beyond("replay", str(RECORDING), "--start-paused", "--rate", "0", env=env,
                          stdin=f.fileno())  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "stdin ended: playing on" in done.stderr
    assert re.search(r"^replayed 342 messages", done.stderr, re.M), done.stderr


def test_the_foxglove_bridge_logs_only_the_port_a_user_opens() -> None:
    ws = free_port()
    env = {**env_for(private_config()), "BEYOND_LOG_FORMAT": "text"}
    proc = subprocess.Popen(
        [*BEYOND, "foxglove", "--ws-port", str(ws)],
        env=env,
        cwd=REPO,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stderr is not None
        lines = []
        for line in proc.stderr:
            lines.append(line)
            if "serving" in line:
                break
        proc.send_signal(signal.SIGINT)
        _, rest = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    logged = "".join(lines) + rest
    assert f"ws://127.0.0.1:{ws}" in logged, logged
    ports = {int(p) for p in re.findall(r"(?:127\.0\.0\.1|localhost):(\d+)", logged)}
    assert ports == {ws}, logged


def test_outputs_go_under_a_state_folder_never_the_current_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.delenv(OUT_DIR_VAR, raising=False)
    monkeypatch.delenv("XDG_STATE_HOME", raising=False)
    assert SpeechSynthesizer().out_dir == tmp_path / "home/.local/state/beyond/speech"
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    assert out_dir() == tmp_path / "state/beyond"
    monkeypatch.setenv("XDG_STATE_HOME", "relative")  # not absolute: ignored, as XDG says
    assert out_dir() == tmp_path / "home/.local/state/beyond"
    monkeypatch.setenv(OUT_DIR_VAR, "runs")
    assert SpeechSynthesizer().out_dir == tmp_path / "runs/speech"
    assert SpeechSynthesizer(out_dir="mine").out_dir == Path("mine")


def test_up_out_dir_is_handed_to_the_services(tmp_path: Path) -> None:

    from beyond_self.commands.up_options import add_out_dir, out_dir_env

    parser = argparse.ArgumentParser()
    add_out_dir(parser)
    args = parser.parse_args(["--out-dir", str(tmp_path / "runs")])
    assert out_dir_env(args) == {OUT_DIR_VAR: str(tmp_path / "runs")}
    assert not (tmp_path / "runs").exists()  # made by what writes there, not by parsing
    assert out_dir_env(parser.parse_args([])) == {}


@pytest.mark.slow
def test_export_of_a_shipped_recording_fills_the_layout_s_views(tmp_path: Path) -> None:
    """The shipped recording holds sensor streams only: the export adds what the pipeline
    publishes for it (`beyond analyse`'s analysis), with the views the layout's panels show,
    and says in one line why a view stays empty. Exported again, nothing is derived twice."""
    out = tmp_path / "views.mcap"
    done = beyond("foxglove", "--export", str(RECORDING), "-o", str(out))
    assert done.returncode == 0, done.stderr
    assert "view pose is empty: the recording has no person pose" in done.stdout
    assert not re.search(r"view (scene|objects|posterior|affordance|log) is empty", done.stdout)
    counts = {c.topic: c.count for c in inspect_recording(out).channels}
    root = "beyond/robot/foxglove"
    for view in ("objects", "posterior", "affordance", "log"):
        assert counts.get(f"{root}/{view}", 0) > 0, (view, counts)
    cameras = counts["beyond/robot/sensors/camera/compressed"]
    assert counts[f"{root}/objects"] == counts["beyond/robot/vision/objects"] == cameras
    described = [
        f'gesture {r.message().segment_id}: "{r.message().sentences[0].text}"'
        for r in read_recording(out)
        if r.key.endswith("/language/description")
    ]
    analysed = beyond("analyse", str(RECORDING))
    assert described and described == [
        line for line in analysed.stdout.splitlines() if line.endswith('"')
    ]
    again = tmp_path / "again.mcap"
    assert beyond("foxglove", "--export", str(out), "-o", str(again)).returncode == 0
    twice = {c.topic: c.count for c in inspect_recording(again).channels}
    assert twice == counts


@pytest.mark.skipif(not (REPO / ".git").exists(), reason="not a git checkout")
def test_what_python_m_build_leaves_is_ignored() -> None:
    leftovers = ["dist/beyond_self-0.tar.gz", "build/lib/x.py", "beyond_self.egg-info/PKG-INFO"]
    done = subprocess.run(
        ["git", "check-ignore", "--no-index", *leftovers],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.stdout.split() == leftovers, done.stderr
