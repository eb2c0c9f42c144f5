"""Snapshots on the machine (runtime.resilience.snapshots, issue 39): the newest few kept, each
whole, and
the newest one that decodes restored."""

from __future__ import annotations

from pathlib import Path

import msgspec

import beyond_self.schemas as s
from beyond_self.core.restorable import Restorable
from beyond_self.runtime.resilience.ledger import Keeper
from beyond_self.runtime.resilience.resume import InputGate
from beyond_self.runtime.resilience.snapshots import Snapshots, SnapshotStore


class State(msgspec.Struct, frozen=True):
    segments: int
    stamp: int


class Other(msgspec.Struct, frozen=True):
    name: str


def test_the_newest_of_the_last_few_is_restored(tmp_path: Path) -> None:
    store = SnapshotStore(tmp_path, keep=3)
    for i in range(10):
        assert store.save(State(i, 100 * i), {"r/skeleton": 100 * i}) > 0
    assert len(store.numbers()) == 3 and store.numbers()[-1] == 10
    assert list((tmp_path / "snapshots").glob("*.tmp")) == []
    again = SnapshotStore(tmp_path, keep=3)  # a successor
    assert again.newest(State) == (State(9, 900), {"r/skeleton": 900})
    again.save(State(10, 1000), {})
    assert again.numbers()[-1] == 11


def test_a_snapshot_that_does_not_decode_is_passed_over(tmp_path: Path) -> None:
    store = SnapshotStore(tmp_path)
    store.save(State(1, 10), {"k": 10})
    store.save(Other("x"), {})
    (tmp_path / "snapshots" / "0000000003.snap").write_bytes(b"\x00 cut short")
    assert store.newest(State) == (State(1, 10), {"k": 10})
    assert SnapshotStore(tmp_path / "empty").newest(State) is None


class Streamer(Restorable, frozen=True):
    events: int


def test_snapshots_told_with_a_ledger_are_what_a_successor_restores(tmp_path: Path) -> None:
    """The base tells each snapshot in the service's ledger (any successor on the bus finds it)
    and stores it on the machine (a successor with no record on the bus restores that one)."""
    header = lambda cls, stamp: s.Header(version=1, source="gestures", seq=0, stamp=1)  # noqa: E731
    mine = Keeper("gestures", header)
    inputs = ["r/skeleton"]
    snapshots = Snapshots(Streamer, mine, SnapshotStore(tmp_path), "r/description", inputs)
    assert snapshots.chosen(restarted=True) is None  # nothing anywhere: afresh
    for n, stamp in enumerate((100, 200, 300)):
        snapshots.taken(Streamer(stamp, n, 2 * n))
    assert snapshots.stored is not None and snapshots.stored.result(10) > 0  # on the machine
    successor = Keeper("gestures", header)
    successor.book.heard(mine.ledger())
    assert successor.book.needed(inputs) == {"r/skeleton": 300}
    again = Snapshots(Streamer, successor, None, "r/description", inputs)
    assert again.newest == Streamer(300, 2, 4)
    assert sorted(again.history) == [0, 1, 2]
    assert again.chosen(restarted=True) == Streamer(300, 2, 4)  # nobody takes descriptions
    alone = Snapshots(Streamer, Keeper("gestures", header), SnapshotStore(tmp_path), "d", inputs)
    assert alone.chosen(restarted=True) == Streamer(300, 2, 4)  # from the machine
    assert alone.chosen(restarted=False) is None  # a first start takes nothing


def test_the_base_takes_a_snapshot_only_when_the_state_moved(tmp_path: Path) -> None:
    """After every message the base offers the service's state: one that did not move, or
    none yet, is not told again; each that moved is, with its input position on every input."""
    header = lambda cls, stamp: s.Header(version=1, source="objects", seq=0, stamp=1)  # noqa: E731
    keeper = Keeper("objects", header)
    inputs = ["r/camera", "r/camera/compressed"]
    snapshots = Snapshots(Streamer, keeper, None, "r/description", inputs)
    for state in (None, Streamer(0, 0, 0), Streamer(0, 0, 0), None, Streamer(40, 1, 2)):
        snapshots.offer(state)
    assert snapshots.taken_count == 2
    successor = Keeper("objects", header)
    successor.book.heard(keeper.ledger())
    assert successor.book.needed(inputs) == dict.fromkeys(inputs, 40)
    assert Snapshots(Streamer, successor, None, "d", inputs).newest == Streamer(40, 1, 2)


class _At(Restorable, frozen=True):
    pass


class _Msg:
    def __init__(self, stamp: int) -> None:
        self.header = type("H", (), {"stamp": stamp})()


def test_the_input_gate_skips_what_came_before_and_tells_a_gap_once() -> None:
    """Restored at stamp 100: input before it was the predecessor's; the first one after it
    (150) says the frames from 100 on are gone, once; with a newest snapshot at 200, a first
    input at 150 rebuilds from the newest instead and waits for its stamp."""
    gaps: list[tuple[int, int]] = []
    restored: list[_At | None] = []

    def gap(message: _Msg, since: int) -> None:
        gaps.append((message.header.stamp, since))

    gate = InputGate(_At(100, 0), lambda: None, restored.append, gap)
    assert [gate.admits(_Msg(s)) for s in (50, 150, 160, 90)] == [False, True, True, False]
    assert gaps == [(150, 100)] and restored == []
    on_time = InputGate(_At(100, 0), lambda: None, restored.append, gap)
    assert on_time.admits(_Msg(100)) and gaps == [(150, 100)]  # no gap: it starts where it left
    newest = _At(200, 3)
    forward = InputGate(_At(100, 0), lambda: newest, restored.append, gap)
    assert [forward.admits(_Msg(s)) for s in (150, 180, 200, 210)] == [False, False, True, True]
    assert restored == [newest] and gaps == [(150, 100)]
    plain = InputGate(_At(100, 0), lambda: newest, restored.append, None)  # no gap handling
    assert [plain.admits(_Msg(s)) for s in (99, 150)] == [False, True] and restored == [newest]
