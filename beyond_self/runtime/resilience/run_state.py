"""What `beyond up` keeps of a run on disk, so that the same command after a kill goes on.

A side of a deployment (`up`'s watcher and the services it starts) keeps its state under the
robot's state folder (runtime.resilience.state) in its deployment's own folder (its bus and its
outputs folder: `deployment_folder`): the run's command, and what its watcher has
printed (`printed.jsonl`, one synced line a gesture). The same command again, after a kill of
the whole side, goes on from there: its services take their predecessors' ledgers and
snapshots, its watcher prints only the gestures not printed yet. Another command, or
`--fresh`, clears this side's state first; a run that ends complete clears it too.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import time
from collections.abc import Iterable
from pathlib import Path

import msgspec

from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.outputs import out_dir
from beyond_self.runtime.resilience.state import STATE_DIR_VAR, state_root, write_atomically

RUN_FILE = "run.json"
PRINTED_FILE = "printed.jsonl"


def run_state_root(outputs: Path | None = None) -> Path:
    """Where `up` keeps its runs' state: $BEYOND_STATE_DIR, else `state/` under the outputs
    folder (`outputs`, else runtime.outputs')."""
    return state_root() or (outputs or out_dir()) / "state"


def deployment_folder(bus: BusConfig, outputs: Path) -> str:
    """The name of one deployment's state folder under the state root: its bus (mode, port,
    endpoints, config file, keystore) and its outputs folder, as a short digest after the mode
    and port a person recognises. Two deployments on different buses or folders (a demo on
    another port, a robot in another checkout) never read or clear each other's state; the
    same command again finds its own."""
    listen, connect = bus.endpoints()
    identity = {
        "mode": bus.mode,
        "port": bus.port,
        "listen": listen,
        "connect": connect,
        "config": str(Path(bus.config_file).resolve()) if bus.config_file else "",
        "secure": str(Path(bus.secure).resolve()) if bus.secure else "",
        "outputs": str(outputs.resolve()),
    }
    digest = hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:12]
    return f"{bus.mode}-{bus.port}-{digest}"


class RunRecord(msgspec.Struct, frozen=True):
    """The command a side's state belongs to, and when that run began (UTC, ISO 8601)."""

    command: str
    began: str


class Printed(msgspec.Struct, frozen=True):
    """A gesture the watcher has told: printed (described or not), or cut with `cut`'s reason."""

    gesture: int
    described: bool
    cut: str = ""


class RunState:
    """One side's state: its services' folders and its watcher's, under `root/robot/`."""

    def __init__(self, root: Path, robot: str, watcher: str, services: Iterable[str]) -> None:
        self.robot_folder = root / robot
        self.watcher = self.robot_folder / watcher
        self.folders = [self.robot_folder / name for name in services] + [self.watcher]
        self.root = root
        self.resumed: RunRecord | None = None
        self.before: dict[int, Printed] = {}

    def env(self) -> dict[str, str]:
        """What the side's services are started with: the state root."""
        return {STATE_DIR_VAR: str(self.root)}

    def begin(self, command: str, *, fresh: bool) -> str:
        """Take this side's state for `command`: go on from a run of the same command that did
        not end, or clear it. One line saying which (empty: nothing was there)."""
        record = self._record()
        said = ""
        if record is not None and record.command == command and not fresh:
            self.resumed = record
            self.before = {p.gesture: p for p in self._printed()}
            said = (
                f"going on with the run begun {record.began}, which did not end "
                f"({len(self.before)} gesture(s) told then); --fresh starts it over"
            )
        elif record is not None or any(f.exists() for f in self.folders):
            why = (
                "--fresh" if record is not None and record.command == command else "another command"
            )
            said = f"the state of an unfinished run is cleared ({why})"
            self.clear()
        began = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        if self.resumed is None:
            self.watcher.mkdir(parents=True, exist_ok=True)
            data = msgspec.json.encode(RunRecord(command, began))
            write_atomically(self.watcher / RUN_FILE, data, sync=True)
        return said

    def told(self, printed: Printed) -> None:
        """`printed` is on the terminal: one line appended and synced."""
        self.before[printed.gesture] = printed
        fd = os.open(self.watcher / PRINTED_FILE, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, msgspec.json.encode(printed) + b"\n")
            os.fsync(fd)
        finally:
            os.close(fd)

    def clear(self) -> None:
        """Forget this side's state (its services' folders and its watcher's)."""
        for folder in self.folders:
            shutil.rmtree(folder, ignore_errors=True)
        for folder in (self.robot_folder, self.root):  # only when no other side keeps anything
            with contextlib.suppress(OSError):
                folder.rmdir()

    def _record(self) -> RunRecord | None:
        with contextlib.suppress(OSError, msgspec.DecodeError, msgspec.ValidationError):
            return msgspec.json.decode((self.watcher / RUN_FILE).read_bytes(), type=RunRecord)
        return None

    def _printed(self) -> list[Printed]:
        path = self.watcher / PRINTED_FILE
        out: list[Printed] = []
        with contextlib.suppress(OSError):
            for line in path.read_bytes().split(b"\n")[:-1]:  # the last piece: not a whole line
                with contextlib.suppress(msgspec.DecodeError, msgspec.ValidationError):
                    out.append(msgspec.json.decode(line, type=Printed))
        return out
