"""A restarted service finds its predecessor's record even when its new session does not yet
know the others: under load, a first query ended at once with no answer, and the service took
itself for a first instance (a restarted reasoner stalled the pipeline waiting for a gesture its
predecessor had finished; a restarted speech service said a sentence again)."""

from __future__ import annotations

import logging
from typing import Any

import pytest
from busutil_net import private_config

from beyond_self.monitor import PipelineMonitor
from beyond_self.runtime.bus.delivery import FRAMES, STATUS
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.bus.subscription import Received
from beyond_self.runtime.resilience import ledger
from beyond_self.runtime.resilience.ledger import Keeper, LedgerBook
from beyond_self.schemas import ActionPosterior, Header, Keys, Ledger
from beyond_self.schemas.identity import Identity, identify


def kept(service: str, handled: int) -> Ledger:
    """A ledger of `service` as another service kept it: gesture `handled` said."""
    key = Keys().description
    header = Ledger.original_header(service, 1, 1)
    return Ledger(header=header, service=service, handled={key: {"description": [(handled, 0, 0)]}})


class SlowToMeet:
    """A bus whose first `silent` queries end with no answer, as a session just opened."""

    keys = Keys()

    def __init__(self, silent: int, answers: list[Ledger]) -> None:
        self.silent, self.answers, self.asked = silent, answers, 0

    async def query(self, key: str, cls: type[Ledger], **_: Any) -> list[Received[Ledger]]:
        self.asked += 1
        if self.asked <= self.silent:
            return []
        return [Received(self.keys.ledger(m.service), m, 0) for m in self.answers]


def keeper() -> Keeper:
    return Keeper("speech", lambda cls, seq: Header(version=1, source="speech", seq=0, stamp=0))


async def test_a_restarted_service_asks_until_its_predecessors_record_comes() -> None:
    bus = SlowToMeet(silent=3, answers=[kept("gestures", 0), kept("speech", 5)])
    keep = keeper()
    await keep.ask(bus, logging.getLogger("test"), restarted=True)  # type: ignore[arg-type]
    assert bus.asked == 4
    assert keep.book.handled["speech"].has(Keys().description, _said(5))


async def test_a_first_instance_asks_once() -> None:
    bus = SlowToMeet(silent=3, answers=[kept("speech", 5)])
    keep = keeper()
    await keep.ask(bus, logging.getLogger("test"))  # type: ignore[arg-type]
    assert bus.asked == 1 and "speech" not in keep.book.handled


async def test_a_restart_with_no_record_anywhere_starts_afresh_and_says_so(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setattr(ledger, "ASK_TIMEOUT_S", 0.5)
    bus = SlowToMeet(silent=0, answers=[kept("gestures", 0)])
    keep = keeper()
    with caplog.at_level(logging.WARNING, logger="test"):
        await keep.ask(bus, logging.getLogger("test"), restarted=True)  # type: ignore[arg-type]
    assert bus.asked > 1 and "speech" not in keep.book.handled
    assert "no service kept a record of the previous instance" in caplog.text


def _said(gesture: int) -> Identity:
    return Identity(Keys().robot, gesture, "description")


def test_a_producer_withholds_only_what_the_consumer_alive_now_has() -> None:
    """The object segmenter's instance 0 handled gesture 3's start; instance 1 (replaced with
    the producer, a workstation taken over) has not, and needs it to rebuild its state."""
    key = Keys().gesture_segment
    start = Identity(Keys().robot, 3, "start")

    def objects(instance: int, handled: list[tuple[int, int, int]]) -> Ledger:
        header = Ledger.original_header("objects", instance, 1)
        wire = {key: {"start": handled}}
        return Ledger(header=header, service="objects", instance=instance, handled=wire)

    book = LedgerBook()
    book.heard(objects(0, [(3, 0, 0)]))
    assert book.consumers_have(key, start, "gestures")
    book.heard(objects(1, []))
    assert not book.consumers_have(key, start, "gestures")
    assert book.done(key, "start", "gestures") == {3}, "what was done stays known"
    book.heard(objects(0, [(3, 0, 0)]))  # a copy of the old instance's, kept by another
    assert not book.consumers_have(key, start, "gestures")
    assert book.last["objects"].instance == 1 and book.instance_of("objects") == 1


async def test_a_named_monitor_is_a_consumer_a_restarted_producer_sends_what_it_lacks() -> None:
    """A belief that reached the reasoner but died in the streamer's send queue on its way to
    the monitor: the restarted streamer withheld it (every *service* had it) and the monitor
    printed gesture 2 without its first line (CI). Named, the monitor's ledger says what it
    has, so the belief goes out again until the monitor has it too."""
    config = private_config()
    watching, producing = Bus.open(config), Bus.open(config)
    try:
        key = producing.keys.gesture_posterior
        belief = ActionPosterior(
            header=Header(version=1, source="gestures", seq=7, stamp=46),
            segment_id=2,
            frame=46,
            actions=["grasp", "touch"],
            posterior=[0.48, 0.52],
            log_likelihood=[-3.1, -3.0],
            normalised_log_likelihood=[-0.1, 0.0],
        )
        ident = identify(key, belief)
        assert ident is not None
        reasoner = Keeper("reasoner", lambda cls, _: cls.original_header("reasoner", 0, 1))
        reasoner.handled.add(key, ident)
        book = LedgerBook()  # the restarted streamer's
        book.heard(reasoner.ledger())
        assert book.consumers_have(key, ident, "gestures"), "the services alone: withheld"
        told = producing.subscribe(producing.keys.ledger("monitor"), Ledger, STATUS)
        # the monitor announces its ledger once on start: its session must know `told` by then
        probe = watching.publisher(watching.keys.ledger("monitor"), Ledger, STATUS)
        await probe.wait_matching(timeout=30)
        probe.close()
        monitor = PipelineMonitor(watching, lambda line: None, name="monitor")
        monitor.start()
        book.heard((await told.recv(timeout=10)).message)
        assert key in book.current["monitor"][1].keys
        assert not book.consumers_have(key, ident, "gestures"), "the monitor lacks it"
        beliefs = producing.publisher(key, ActionPosterior, FRAMES)
        beliefs.put(belief)  # its cache gives it to the monitor, whenever they meet
        while not book.consumers_have(key, ident, "gestures"):  # told with its next tick
            book.heard((await told.recv(timeout=10)).message)
        assert monitor.report.gestures[2].best == "touch", "and it reached the report"
        monitor.stop()
    finally:
        watching.close()
        producing.close()
