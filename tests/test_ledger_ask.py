"""A restarted service finds its predecessor's record even when its new session does not yet
know the others: under load, a first query ended at once with no answer, and the service took
itself for a first instance (a restarted reasoner stalled the pipeline waiting for a gesture its
predecessor had finished; a restarted speech service said a sentence again)."""

from __future__ import annotations

import logging
from typing import Any

import pytest

from beyond_self.runtime import ledger
from beyond_self.runtime.ledger import Keeper, LedgerBook
from beyond_self.runtime.subscription import Received
from beyond_self.schemas import Header, Keys, Ledger
from beyond_self.schemas.identity import Identity


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
