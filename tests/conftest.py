"""Tests needing the article's data skip, with the reason, only when it is absent."""

from __future__ import annotations

from pathlib import Path

import pytest

from cognition.paths import SOURCES, shared_data_dir


@pytest.fixture(scope="session")
def shared_data() -> Path:
    root = shared_data_dir()
    if root is None:
        pytest.skip(f"../shared/data is absent (the article's data, from {SOURCES})")
    return root


# The JavaScript packages third-party tools read our files and streams with: @mcap/core (the MCAP
# reader Foxglove uses), fzstd (its zstd decompressor) and @foxglove/schemas (the official JSON
# Schemas of Foxglove's message types). Installed once per run into a temporary folder.
NODE_PACKAGES = ("@mcap/core@2", "@foxglove/schemas@2", "fzstd@0.1")


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
