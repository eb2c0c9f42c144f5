"""Where the real data of the article lives, and where bundled resources are.

The article's data is never copied into the repository (licence and size); it is read from
`../shared/data` beside the checkout, or from the folder named by $BEYOND_DATA.

Bundled resources (the recordings the main job replays) sit inside the `beyond_self` package, in a
checkout and in an installed wheel alike: `ROOT` is that package folder, so no code asks which it
is. In a checkout the article's data is looked for beside the checkout (`ROOT.parent.parent`).
"""

from __future__ import annotations

import os
from pathlib import Path

from beyond_self.core.errors import InputError

ROOT = Path(__file__).resolve().parent.parent
RECORDINGS = ROOT / "recordings"
BESIDE_CHECKOUT = ROOT.parent.parent / "shared" / "data"
DEMO_RECORDING = RECORDINGS / "tap-ball-grasp-box.mcap"
SOURCES = (
    "giampierosalvi/AffordancesAndSpeech (folder bayesian_net/) and "
    "gsaponaro/tcds-gestures (folders src/matlab/ and app/dumps/) on GitHub"
)


POINT_AT_IT = "set BEYOND_DATA to the folder that holds salvi2012/ and saponaro2019/"


def shared_data_dir() -> Path | None:
    """The article's data folder if present: $BEYOND_DATA, else ../shared/data beside the repo."""
    env = os.environ.get("BEYOND_DATA")
    candidates = [Path(env)] if env else []
    candidates.append(BESIDE_CHECKOUT)
    for path in candidates:
        if (path / "salvi2012").is_dir() or (path / "saponaro2019").is_dir():
            return path
    return None


def require_shared_data(relative: str = "") -> Path:
    """A path inside the article's data folder; a clear InputError saying where to get it."""
    root = shared_data_dir()
    if root is None:
        raise InputError(
            "the article's data folder was not found (looked in $BEYOND_DATA and "
            f"{BESIDE_CHECKOUT}); get it from {SOURCES} and {POINT_AT_IT}"
        )
    path = root / relative
    if not path.exists():
        raise InputError(
            f"missing data file {path}; it comes from {SOURCES} ($BEYOND_DATA or "
            f"{BESIDE_CHECKOUT} is the folder that holds it)"
        )
    return path


def data_set(spec: str, keep: tuple[str, ...] = ()) -> str:
    """DATA as a user types it: a name in `keep` (`synthetic`), a file or folder here, or the
    name of a folder of the article's data (`human_data` is saponaro2019/human_data there, as
    the README writes it); else an InputError saying where to get the data and how to point at
    it. A path of the current folder wins over a data set of the same name."""
    if spec in keep:
        return spec
    if Path(spec).expanduser().exists():
        return str(Path(spec).expanduser())
    root = shared_data_dir()
    if root is not None and spec.strip() and not Path(spec).is_absolute():
        found = sorted(p for p in (root / spec, *root.glob(f"*/{spec}")) if p.exists())
        if found:
            return str(found[0])
    where = str(root) if root else f"none in $BEYOND_DATA or {BESIDE_CHECKOUT}"
    valid = "".join(f"'{k}', " for k in keep)
    raise InputError(
        f"{spec} is not a file or folder here, nor a data set of the article's data folder "
        f"({where}); valid: {valid}a path, or a data set name such as human_data with the data "
        f"from {SOURCES} in ../shared/data beside the project or in $BEYOND_DATA"
    )
