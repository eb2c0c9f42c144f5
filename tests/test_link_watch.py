"""The link watch of a split's side (services/link_watch.py): a link that carries the other
side's presence but none of its data is found broken, a cut link or a quiet one is not."""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from busutil_net import health_report, private_config

from beyond_self.runtime.bus.delivery import STATUS
from beyond_self.runtime.bus.session import Bus
from beyond_self.schemas import ServiceHealth
from beyond_self.services.link_watch import LinkSilence, LinkWatch

REMOTE = ("ingest", "gestures", "objects")


def test_presence_without_data_is_broken_once_per_silence() -> None:
    silence = LinkSilence(REMOTE, silent_s=10)
    assert silence.check(100) is None  # nobody there: nothing to decide
    silence.token("gestures", True, now=0)
    assert silence.check(9.9) is None
    why = silence.check(10)
    assert why is not None and "gestures present" in why and "for 10 s" in why
    assert silence.check(15) is None  # counted again from the alarm: one restart per silence
    assert silence.check(20) is not None and silence.broken == 2


def test_health_from_the_other_side_keeps_the_link_judged_alive() -> None:
    silence = LinkSilence(REMOTE, silent_s=10)
    silence.token("ingest", True, now=0)
    for t in range(0, 60, 5):
        silence.heard("objects", now=t)  # any remote service's health counts
        assert silence.check(t + 9) is None
    silence.heard("reasoner", now=60)  # our own side's health says nothing of the link
    assert silence.check(65) is not None


def test_a_cut_link_is_not_a_broken_one_and_local_names_do_not_count() -> None:
    silence = LinkSilence(REMOTE, silent_s=10)
    silence.token("reasoner", True, now=0)  # a service of this side
    assert silence.check(50) is None
    silence.token("gestures", True, now=50)
    silence.token("objects", True, now=55)
    silence.token("gestures", False, now=56)
    silence.token("objects", False, now=57)  # the other side gone: a cut link, Zenoh's to handle
    assert silence.check(100) is None
    silence.token("objects", True, now=100)  # back: the silence counts from its return
    assert silence.check(109) is None and silence.check(110) is not None


async def test_on_the_bus_a_silent_remote_service_is_reported_and_its_health_heard() -> None:
    config = private_config()
    with Bus.open(config) as ours, Bus.open(config) as theirs:
        broken: list[str] = []
        watch = LinkWatch(ours, REMOTE, broken.append, silent_s=0.5, check_s=0.05)
        hearing = LinkWatch(ours, REMOTE, broken.append, silent_s=1e6, check_s=0.05)
        watch.start()
        hearing.start()
        loop = asyncio.get_running_loop()
        deadline = loop.time() + 20

        async def until(condition: Callable[[], bool]) -> None:
            while not condition() and loop.time() < deadline:
                await asyncio.sleep(0.05)

        try:
            undeclare = theirs.declare_token(theirs.keys.alive("gestures"))
            await until(lambda: bool(broken))
            assert broken and "gestures present" in broken[0]
            assert watch.silence.present == {"gestures"}
            pub = theirs.publisher(theirs.keys.health("gestures"), ServiceHealth, STATUS)
            await pub.wait_matching(timeout=10)
            put_at = loop.time()
            pub.put(health_report("gestures"))
            await until(lambda: (hearing.silence.since or 0) >= put_at)
            assert (hearing.silence.since or 0) >= put_at  # the health arrived and was counted
            assert hearing.silence.broken == 0
            undeclare()
            await until(lambda: not watch.silence.present)
            assert watch.silence.present == set() and watch.silence.since is None
        finally:
            await watch.stop()
            await hearing.stop()
