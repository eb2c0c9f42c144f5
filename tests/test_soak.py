"""A short run of bench/soak.py (issue 21): a looped recording as fast as possible while services
are SIGKILLed, one after each gesture described; no description lost, none published or said
twice, every gesture told as `beyond analyse` tells it, every process stopped cleanly, memory
bounded. The 10-minute run is bench/soak.py's."""

from __future__ import annotations

import importlib.util
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import pytest
from busutil_net import free_port

REPO = Path(__file__).resolve().parent.parent


def soak_module() -> ModuleType:
    spec = importlib.util.spec_from_file_location("soak", REPO / "bench" / "soak.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
@pytest.mark.timeout(600)  # it runs until it has seen enough: longer on a loaded machine
async def test_a_short_soak_loses_and_repeats_nothing(
    tmp_path: Path, show: Callable[[str], None]
) -> None:
    said: list[str] = []
    figures = await soak_module().soak(
        duration_s=5.0,
        kill_every_s=None,  # a kill after each gesture described: as many however loaded
        at_least=(5, 4),  # gestures described, services killed
        rate=0.0,
        recording=REPO / "recordings" / "touch-box.mcap",
        seed=21,
        out=tmp_path,
        port=free_port(),
        say=said.append,
    )
    assert figures["kills"] >= 4 and sum(figures["restarts"].values()) == figures["kills"]
    assert figures["gestures_ended"] >= 5, figures  # the loop went on through the kills
    assert figures["described"] >= figures["gestures_ended"]
    assert figures["lost"] == [] and figures["described_twice"] == [], figures
    assert figures["said_twice"] == [] and figures["not_said"] == [], figures
    assert figures["blocks_unlike_analyse"] == [], figures
    assert figures["clean_stop"], figures["unclean"]
    assert 0 < figures["rss_max_mb"] < 3000, figures  # seven processes, bounded
    show("\n".join(said))
