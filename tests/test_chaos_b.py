"""Chaos acceptance, seeds 4-7 (issue 39; the run is tests/chaos.py): under SIGKILLs and
freezes drawn from the seed, `up` stops cleanly, prints the gesture lines `beyond analyse`
prints, and says each sentence once."""

from __future__ import annotations

from typing import Any

import chaos
import pytest

SEEDS = [4, 5, 6, 7]


@pytest.fixture(scope="module")
def expected() -> list[str]:
    return chaos.offline_lines()


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[int, dict[str, Any]]:
    """Every seed's run, chaos.AT_ONCE at a time; each test checks its own seed's."""
    return chaos.run_seeds(SEEDS, tmp_path_factory.mktemp("chaos"))


@pytest.mark.slow
@pytest.mark.timeout(600)  # the first test's set-up runs every seed
@pytest.mark.parametrize("seed", SEEDS)
def test_chaos_changes_nothing(
    seed: int, expected: list[str], runs: dict[int, dict[str, Any]]
) -> None:
    chaos.check(seed, runs[seed], expected)
