"""Where a run leaves what it writes (the speech service's WAVs and `speech.log`, the ROS 2
bridge's `said.log`, the run state of `beyond up`, gesture evaluation plots by default).

The rule of every command: nothing goes into the current folder unless a path given says so
(`-o`, `--out-dir`); what is written without one goes under this folder, a state folder of the
user's: `$BEYOND_OUT_DIR` when set (what `beyond up --out-dir DIR` sets for its services), else
`$XDG_STATE_HOME/beyond`, else `~/.local/state/beyond`. A folder given is made when the command
has something to write into it, so one that fails first leaves none. Each service writes into a
folder of its own name below it (`speech/`); a service's own option (`out_dir`) still wins.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

OUT_DIR_VAR = "BEYOND_OUT_DIR"
DESCRIPTION = "$BEYOND_OUT_DIR, else $XDG_STATE_HOME/beyond, else ~/.local/state/beyond"


def out_dir(env: Mapping[str, str] | None = None) -> Path:
    """The folder a run's outputs go under (absolute; not created here)."""
    env = os.environ if env is None else env
    if env.get(OUT_DIR_VAR):
        return Path(env[OUT_DIR_VAR]).expanduser().resolve()
    state = env.get("XDG_STATE_HOME")
    base = Path(state) if state and Path(state).is_absolute() else Path.home() / ".local/state"
    return base / "beyond"


def service_out_dir(service: str, env: Mapping[str, str] | None = None) -> Path:
    """Service `service`'s own folder below `out_dir`."""
    return out_dir(env) / service
