"""The restart policy of `beyond up` and every Deployment (issue 21), and `up`'s --skip and
--without, without starting anything."""

from __future__ import annotations

import argparse
import signal
from types import SimpleNamespace

import pytest
from busutil_net import private_config
from rich.console import Console

from beyond_self.commands import up, up_services, up_watch
from beyond_self.core.errors import InputError
from beyond_self.live_view import render
from beyond_self.schemas import Header, ServiceHealth
from beyond_self.services.supervision import RestartPolicy, Restarts, how_it_ended


def test_a_service_that_dies_is_restarted_with_a_doubling_delay_then_given_up_on() -> None:
    restarts = Restarts(RestartPolicy(first_delay_s=0.1, max_delay_s=1.0, burst=5, interval_s=60))
    killed = -signal.SIGKILL
    delays = [restarts.decide(killed, stuck=False, now=t) for t in range(5)]
    assert delays == [0.1, 0.2, 0.4, 0.8, 1.0]  # doubling, capped
    assert restarts.decide(killed, stuck=False, now=10) is None  # a 6th within the minute
    assert "gave up after 5 restarts in 60 s" in restarts.gave_up
    assert restarts.count == 5
    later = Restarts(RestartPolicy(burst=2, interval_s=60))
    assert later.decide(1, stuck=False, now=0) is not None
    assert later.decide(1, stuck=False, now=1) is not None
    assert later.decide(1, stuck=False, now=100) is not None  # the old ones left the window


def test_what_meant_to_stop_or_refused_its_input_is_not_restarted() -> None:
    for code in (0, -signal.SIGTERM, -signal.SIGINT):
        clean = Restarts(RestartPolicy())
        assert clean.decide(code, stuck=False, now=0) is None and not clean.gave_up
    bad = Restarts(RestartPolicy())
    assert bad.decide(2, stuck=False, now=0) is None
    assert bad.gave_up == "exit status 2 (bad input): not restarted"
    stuck = Restarts(RestartPolicy())  # the health watch stopped it: SIGTERM, but restarted
    assert stuck.decide(-signal.SIGTERM, stuck=True, now=0) == 0.1
    assert how_it_ended(-signal.SIGKILL) == "killed by SIGKILL"
    with pytest.raises(InputError, match="restarts in"):
        RestartPolicy(burst=0)


def parsed(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    up.add_arguments(parser)
    return parser.parse_args(list(argv))


def test_skip_means_elsewhere_and_without_means_none() -> None:
    lines = up_watch.EventLines()
    side, _ = up_services.deployment(parsed("--skip", "speech"), private_config(), lines)
    assert "speech" not in side.services
    assert "speech" in side.options["ingest"]["wait_for"]  # the others still expect it
    assert "objects" not in side.options["reasoner"]
    side, _ = up_services.deployment(parsed("--without", "objects,speech"), private_config(), lines)
    assert "objects" not in side.services and "speech" not in side.services
    assert "objects" not in side.options["ingest"]["wait_for"]
    assert side.options["reasoner"]["objects"] is False  # told: no object evidence
    side, _ = up_services.deployment(parsed("--skip", "objects"), private_config(), lines)
    assert "objects" not in side.options["reasoner"]  # runs elsewhere: still waited for
    with pytest.raises(InputError, match="unknown service 'spech'"):
        up_services.deployment(parsed("--without", "spech"), private_config(), lines)


def test_the_live_view_shows_restarts() -> None:
    health = ServiceHealth(
        header=Header(version=ServiceHealth.VERSION, source="gestures", seq=0, stamp=1),
        service="gestures", uptime_s=1.0, messages_in=5, messages_out=4, dropped=0,
        malformed=0, errors=0, restarts=3,
    )  # fmt: skip
    monitor = SimpleNamespace(
        health_reports={"gestures": health},
        posterior=None,
        prediction=None,
        description=None,
        poses=0,
    )
    console = Console(width=120, record=True)
    console.print(render(monitor, ["gestures", "reasoner"]))  # type: ignore[arg-type]
    text = console.export_text().replace("┃", "│")
    rows = [[c.strip() for c in line.split("│")] for line in text.splitlines()]
    header = next(r for r in rows if "restarts" in r)
    gestures = next(r for r in rows if "gestures" in r)
    assert gestures[header.index("restarts")] == "3"
    assert gestures[header.index("in")] == "5"


async def test_up_says_which_skipped_service_it_waits_for_until_it_comes() -> None:
    """Issue 42: `up --skip speech` with no speech service anywhere waited with no hint."""
    import asyncio

    from beyond_self.runtime.bus.session import Bus

    args = parsed("--skip", "speech,objects", "--wait-for", "reasoner")
    awaited = up_services.awaited_elsewhere(args)
    assert awaited == {"reasoner": "--wait-for", "speech": "--skip", "objects": "--skip"}
    config = private_config()
    said: list[str] = []
    with Bus.open(config) as bus, Bus.open(config) as elsewhere:
        hints = asyncio.create_task(
            up_watch.say_what_is_awaited(bus, {"speech": "--skip"}, period=0.05, say=said.append)
        )
        loop = asyncio.get_running_loop()
        deadline = loop.time() + 20
        while not said:
            assert loop.time() < deadline, "no hint"
            await asyncio.sleep(0.02)
        assert said[0] == (
            "waiting for speech (--skip: it runs elsewhere); start it on this bus, e.g. "
            f"`beyond service speech --robot {config.robot}`"
        )
        elsewhere.declare_token(elsewhere.keys.alive("speech"))
        await asyncio.wait_for(hints, 20)  # it has come: the hints end
    assert set(said) == {said[0]}
