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
