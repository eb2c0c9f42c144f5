"""Chaos acceptance, seeds 0-3 (issue 39; the run is tests/chaos.py): under SIGKILLs and
freezes drawn from the seed, `up` stops cleanly, prints the gesture lines `beyond analyse`
prints, and says each sentence once."""

from __future__ import annotations

from pathlib import Path

import chaos
import pytest


@pytest.fixture(scope="module")
def expected() -> list[str]:
    return chaos.offline_lines()


@pytest.mark.slow
@pytest.mark.timeout(300)
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
async def test_chaos_changes_nothing(seed: int, expected: list[str], tmp_path: Path) -> None:
    chaos.check(seed, await chaos.run(seed, tmp_path), expected)
