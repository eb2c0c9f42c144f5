"""The distribution as a new user gets it: built with `python -m build`, installed from the wheel
into a fresh virtual environment outside the repository, run from an empty folder.

What a checkout hides: files the wheel forgets (the demo's recording was missing once), a layer
installed as a top-level package another distribution also owns, the current folder shadowing
our modules. Each assertion below failed on the code before issue 26.
"""

from __future__ import annotations

import re
import subprocess
import sys
import tarfile
import venv
import zipfile
from email.parser import Parser
from pathlib import Path

import pytest
from busutil_net import REPO, env_for, private_config

import beyond_self
from beyond_self.runtime.outputs import OUT_DIR_VAR

LAYERS = ("cognition", "core", "runtime", "schemas", "services")
DECOYS = (*LAYERS, "beyond", "beyond_self")
BUNDLED = (
    "beyond_self/recordings/tap-ball-grasp-box.mcap",
    "beyond_self/recordings/three-actions.mcap",
    "beyond_self/recordings/touch-box.mcap",
    "beyond_self/cognition/gestures/data/synthetic_models.json",
    "beyond_self/cognition/bn/data/synthetic_bag.txt",
    "beyond_self/cognition/bn/data/synthetic_networkDefinition.txt",
    "beyond_self/cognition/bn/data/synthetic_sentences.txt",
    "beyond_self/cognition/vision/clusters_default.json",
    "beyond_self/deploy/foxglove/beyond-demo.layout.json",
    "beyond_self/deploy/zenoh/robot.json5",
    "beyond_self/deploy/services.yaml",
    "beyond_self/py.typed",
)

# pytest-timeout counts the fixtures too: building and installing the distribution took 262 s
# of the 300 s default in a run of three workers beside three busy loops, leaving the demo 38 s
pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]


def readme_demo_lines() -> list[str]:
    """The gesture lines the README promises `make demo` prints."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    blocks = [part.split("```", 1)[0] for part in text.split("```text")[1:]]
    block = next(b for b in blocks if "\ngesture " in b)  # the demo's output, after the picture
    return [line for line in block.splitlines() if line.startswith("gesture ")]


# session-scoped: under xdist a module-scoped fixture was built twice (160 and 141 s of pip),
# torn down between two tests of the same worker
@pytest.fixture(scope="session")
def dist(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """sdist and wheel, as a release builds them (the wheel is built from the sdist), with the
    backend and versions [build-system] asks for, installed by the dev extra. Not isolated:
    an isolated build downloads and installs that backend twice (sdist, then wheel), 121 s of
    waiting on the registry for 4 s of building, and the files come out the same."""
    out = tmp_path_factory.mktemp("dist")
    done = subprocess.run(
        [sys.executable, "-m", "build", "--no-isolation", "--outdir", str(out), str(REPO)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return out


@pytest.fixture(scope="session")
def installed(dist: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh virtual environment with the wheel and its dependencies, and nothing else.
    Without byte-compiling every module of every dependency (84 s of pip instead of 33 s):
    the tests import a small part, compiled as it is imported."""
    env_dir = tmp_path_factory.mktemp("venv") / "env"
    venv.create(env_dir, with_pip=True, clear=True)
    wheel = next(dist.glob("*.whl"))
    pip = [str(env_dir / "bin" / "python"), "-m", "pip", "install", "--quiet", "--no-compile"]
    done = subprocess.run(
        [*pip, str(wheel)],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return env_dir


def test_the_wheel_holds_one_import_package_and_what_the_demo_needs(dist: Path) -> None:
    wheel = next(dist.glob("*.whl"))
    assert wheel.name.startswith(f"beyond_self-{beyond_self.__version__}-py3-none-any")
    with zipfile.ZipFile(wheel) as zf:
        names = zf.namelist()
        tops = {name.split("/", 1)[0] for name in names}
        meta_name = next(n for n in names if n.endswith(".dist-info/METADATA"))
        metadata = Parser().parsestr(zf.read(meta_name).decode())
        entry_points = zf.read(meta_name.replace("METADATA", "entry_points.txt")).decode()
    assert tops == {"beyond_self", f"beyond_self-{beyond_self.__version__}.dist-info"}, tops
    for path in BUNDLED:
        assert path in names, f"the wheel lacks {path}"
    for layer in LAYERS:
        assert f"beyond_self/{layer}/__init__.py" in names
    assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc")]
    assert metadata["Name"] == "beyond-self"
    assert metadata["Version"] == beyond_self.__version__
    assert metadata["License-Expression"] == "GPL-3.0-or-later"
    assert metadata["Description-Content-Type"] == "text/markdown"
    assert "Programming Language :: Python :: 3.11" in metadata.get_all("Classifier", [])
    # `pip install beyond-self[camera]`: the pose model, at the one version that bundles it
    assert "camera" in metadata.get_all("Provides-Extra", [])
    assert 'mediapipe==0.10.14; extra == "camera"' in metadata.get_all("Requires-Dist", [])
    assert "beyond = beyond_self.cli:entry" in entry_points
    assert "# beyond-self" in metadata.get_payload()  # the README, rendered on the index


def test_the_sdist_builds_the_same_package(dist: Path) -> None:
    """The sdist is what a distribution packager rebuilds from: plain folders, no links."""
    sdist = next(dist.glob("*.tar.gz"))
    with tarfile.open(sdist) as tf:
        members = tf.getmembers()
    assert not [m.name for m in members if m.issym() or m.islnk()]
    names = {m.name.split("/", 1)[1] for m in members if "/" in m.name}
    for path in BUNDLED:
        assert path in names, f"the sdist lacks {path}"


def test_the_installed_demo_runs_from_an_empty_folder(installed: Path, tmp_path: Path) -> None:
    """`beyond demo` after `pip install`, in a folder that holds nothing but decoys of every
    package name we use: the README's gesture lines, word for word."""
    work = tmp_path / "empty"
    work.mkdir()
    for name in DECOYS:
        (work / name).mkdir()
        (work / name / "__init__.py").write_text("raise ImportError('decoy imported')\n")
    env = {**env_for(private_config()), "BEYOND_LOG_FORMAT": "text", "PYTHONPATH": ""}
    env.pop(OUT_DIR_VAR, None)  # the demo's outputs go to the user's state folder
    env["XDG_STATE_HOME"] = str(tmp_path / "state")
    beyond = str(installed / "bin" / "beyond")
    version = subprocess.run([beyond, "--version"], capture_output=True, text=True, cwd=work)
    assert version.stdout.strip() == f"beyond-self {beyond_self.__version__}"
    done = subprocess.run(
        [beyond, "demo", "--no-live"],
        env=env,
        cwd=work,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    printed = [line for line in done.stdout.splitlines() if line.startswith("gesture ")]
    assert printed == readme_demo_lines()
    # nothing written into the folder it ran from: what it said is in the state folder
    assert sorted(p.name for p in work.iterdir()) == sorted(DECOYS)
    said = (tmp_path / "state" / "beyond" / "speech" / "speech.log").read_text().splitlines()
    described = [line.split(': "', 1)[1][:-1] for line in printed if ': "' in line]
    assert [line.split("\t")[-1] for line in said] == described


def test_our_package_imports_beside_decoy_layers(installed: Path, tmp_path: Path) -> None:
    """Packages called `runtime`, `schemas`, `services`, ... on the path (PyPI has them) do not
    replace ours, and ours does not replace them."""
    decoys = tmp_path / "decoys"
    for name in LAYERS:
        (decoys / name).mkdir(parents=True)
        (decoys / name / "__init__.py").write_text(f"DECOY = {name!r}\n")
    probe = (
        "import beyond_self, beyond_self.services.registry, beyond_self.runtime.bus.session, "
        "beyond_self.schemas, beyond_self.cognition.bn\n"
        "import runtime, schemas, services, cognition, core\n"
        "print(beyond_self.__file__)\n"
        "print(beyond_self.runtime.bus.session.__file__)\n"
        "print(runtime.DECOY, schemas.DECOY, services.DECOY, cognition.DECOY, core.DECOY)\n"
    )
    done = subprocess.run(
        [str(installed / "bin" / "python"), "-c", probe],
        env={"PYTHONPATH": str(decoys), "PATH": "/usr/bin:/bin"},
        cwd=decoys,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    package, bus, decoy_names = done.stdout.splitlines()
    site = re.escape(str(installed))
    assert re.match(site + r"/lib/python3\.\d+/site-packages/beyond_self/__init__\.py$", package)
    installed_bus = r"/lib/python3\.\d+/site-packages/beyond_self/runtime/bus/session\.py$"
    assert re.match(site + installed_bus, bus)
    assert decoy_names == "runtime schemas services cognition core"
