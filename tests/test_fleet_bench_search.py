"""bench/fleet.py's search for a case's limit (issue 51): it doubles until a round is over the
budget, then bisects, with no cap below the limit; its safety caps say why they stopped it; and
the figures beside a limit are the slopes and ratios the docs show. Rounds are made up here
(the bench's measurements are its own, never a test's): what is checked is the search's logic.
"""

from __future__ import annotations

import importlib.util
import sys
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

REPO = Path(__file__).resolve().parent.parent
BUDGET_MS = 1e3 / 30


@pytest.fixture(scope="module")
def fleet() -> ModuleType:
    spec = importlib.util.spec_from_file_location("fleet_bench", REPO / "bench" / "fleet.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def searched(fleet: ModuleType, limit: int, **options: Any) -> list[int]:
    """The rounds a search runs when every round of up to `limit` robots is under the budget
    and every larger one over it. It ends with the largest round under the budget (its limit)
    at most `limit`, and the smallest over it above `limit`, within its resolution of each
    other: the limit it reports is within that resolution below the true one."""
    search = fleet.Search(**options)
    tried: list[int] = []
    while (n := search.next()) is not None:
        assert n not in tried, f"round {n} run twice: {tried}"
        tried.append(n)
        search.record(n, 10.0 if n <= limit else 50.0)
        assert len(tried) < 40, tried
    assert search.lo <= limit < search.hi
    assert search.hi - search.lo <= max(1, int(search.lo * search.resolution))
    return tried


@pytest.mark.parametrize("limit", [0, 1, 3, 24, 63, 64, 100, 500, 1000])
def test_the_search_finds_the_limit_with_no_cap_below_it(fleet: ModuleType, limit: int) -> None:
    tried = searched(fleet, limit)
    first_over = next(k for k, n in enumerate(tried) if n > limit)
    assert tried[: first_over + 1] == [2**k for k in range(first_over + 1)]  # doubling from one
    if limit:  # the limit found: the largest round under the budget, within an eighth
        assert max(n for n in tried if n <= limit) >= limit * 7 / 8


def test_quick_steps_by_four_and_stops_within_a_half(fleet: ModuleType) -> None:
    tried = searched(fleet, 100, factor=4, resolution=1 / 2)
    assert tried[:5] == [1, 4, 16, 64, 256]
    assert max(n for n in tried if n <= 100) >= 100 / 2
    assert len(tried) < len(searched(fleet, 100))


def test_a_noisy_round_over_the_budget_bounds_the_limit_below_it(fleet: ModuleType) -> None:
    """p99 is not monotonic on a shared machine: the limit is the largest round under the budget
    with no smaller round over it."""
    search = fleet.Search()
    for n, p99 in [(1, 9.0), (2, 9.0), (4, 40.0), (8, 12.0)]:
        search.record(n, p99)
    assert (search.lo, search.hi) == (2, 4)
    assert search.next() == 3
    search.record(3, BUDGET_MS)  # reaching the budget is over it
    assert search.next() is None and search.lo == 2


def round_of(robots: int, wall_s: float = 30.0) -> dict[str, Any]:
    return {
        "robots": robots,
        "description_p99_ms": 10.0,
        "rss_mb": 200.0 + 4.0 * robots,
        "pss_mb": 100.0 + 2.0 * robots,
        "cores": 0.04 + 0.01 * robots,
        "sources_cores": 0.01,
        "sources_rss_mb": 50.0,
        "wall_s": wall_s,
    }


def test_the_caps_stop_a_round_and_say_why(fleet: ModuleType) -> None:
    far = time.monotonic() + 3600
    caps = fleet.Caps(deadline=far, memory_mb=10_000.0, most=None)
    assert caps.refuse(1, [], far) is None  # a case's first round always runs
    assert caps.refuse(64, [round_of(32)], far) is None
    why = caps.refuse(64, [round_of(32, wall_s=100.0)], time.monotonic() + 60)
    assert why is not None and why[0].startswith("time") and why[1] == 64
    # the processes' fixed memory does not grow with the robots: 4 MB a robot from 254 MB at 1
    assert fleet.memory_at(64, [round_of(1), round_of(32)]) == pytest.approx(378 + 4 * 32)
    assert fleet.memory_at(64, [round_of(32)]) == pytest.approx(378)  # one round: no slope yet
    small = fleet.Caps(deadline=far, memory_mb=600.0, most=None)
    assert small.refuse(64, [round_of(1), round_of(32)], far) is None
    why = small.refuse(128, [round_of(1), round_of(32)], far)
    assert why is not None and why[0].startswith("memory")
    capped = fleet.Caps(deadline=far, memory_mb=10_000.0, most=48)
    assert capped.refuse(64, [round_of(32)], far) is None  # the search tries --max itself
    why = capped.refuse(96, [round_of(32), round_of(48)], far)
    assert why is not None and why[0] == "--max 48"


def test_beside_a_limit_each_robot_costs_the_slope_and_the_ratios(fleet: ModuleType) -> None:
    search = fleet.Search()
    rounds = [round_of(n) for n in (1, 2, 4, 8)]
    for r in rounds:
        search.record(r["robots"], 10.0)
    search.record(16, 50.0)
    rounds.append(round_of(16) | {"description_p99_ms": 50.0})
    reference = {"cores": 0.05, "rss_mb": 180.0, "pss_mb": 90.0}
    got = fleet.each_robot(rounds, search, reference)
    assert got["robots"] == 8
    assert got["first_over"] == {"robots": 16, "description_p99_ms": 50.0}
    assert got["mb_per_added_robot"] == pytest.approx(4.0)
    assert got["pss_mb_per_added_robot"] == pytest.approx(2.0)
    assert got["cores_per_robot"] == pytest.approx(0.12 / 8, abs=1e-4)
    assert got["cores_per_added_robot"] == pytest.approx(0.01, abs=1e-4)
    assert got["memory_ratio"] == pytest.approx(45.0, abs=0.1)
    assert got["pss_ratio"] == pytest.approx(45.0, abs=0.1)
    assert got["cpu_ratio"] == pytest.approx(0.05 / 0.015, abs=0.01)


def test_a_limit_of_no_robots_names_every_figure(fleet: ModuleType) -> None:
    search = fleet.Search()
    search.record(1, 50.0)
    got = fleet.each_robot([round_of(1)], search, {"cores": 0.05, "rss_mb": 1.0, "pss_mb": 1.0})
    assert got["robots"] == 0 and search.next() is None
    assert got["cores_per_robot"] is None and got["memory_ratio"] is None


def test_a_robots_frames_are_sent_as_the_frames_encoded_at_their_stamps(
    fleet: ModuleType,
) -> None:
    """The bench encodes each frame once and puts the send time's stamp in: what the fleet
    receives is byte for byte the frame encoded with that stamp."""
    import beyond_self.schemas as s
    from beyond_self.schemas.codec import encode

    def frame(number: int, joints: int) -> s.SkeletonFrame:
        positions = {f"j{j}": s.Joint(position=(0.1 * j, -2.5, number / 7)) for j in range(joints)}
        header = s.Header(version=1, source="robot", seq=0, stamp=10**18)
        return s.SkeletonFrame(header=header, frame=number, joints=positions)

    frames = [frame(1, 1), frame(300, 9), frame(70_000, 15)]  # numbers of 1, 3 and 5 bytes
    stream = fleet.encoded_stream(frames, [2])
    for i, stamp in [(0, 2**32), (1, 1_765_000_000_123_456_789), (2, 2**62 + 1), (2, 2**33)]:
        assert stream.payload(i, stamp) == encode(fleet.live_frame(frames[i], i, stamp))
    with pytest.raises(ValueError, match="2\\^32"):
        stream.payload(0, 2**32 - 1)


def test_the_burst_bench_times_each_stages_science_on_one_stream() -> None:
    """bench/burst.py's reference (the science alone, in the bench's own process) runs on the
    fleet bench's streams as they are now: a stream made for the fleet bench once broke it."""
    spec = importlib.util.spec_from_file_location("burst_bench", REPO / "bench" / "burst.py")
    assert spec is not None and spec.loader is not None
    burst = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = burst
    spec.loader.exec_module(burst)
    spent = burst.science_ms(1)
    assert set(spent) == {"gestures", "reasoner", "describer"}
    assert all(ms > 0 for ms in spent.values()), spent
