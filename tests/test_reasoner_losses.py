"""The reasoner tells its join what an input lost for good (no publisher cache held it), with
the next message of that input: the gestures lacking the lost piece are given up, not waited
for. Its handlers are called directly, without a bus: the subscription is a stand-in whose
`missed` count is what a recovering subscription reports."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from beyond_self.cognition.episodes import FusionJoin, Lost, Outcome
from beyond_self.schemas import GestureObject
from beyond_self.services import shared
from beyond_self.services.reasoner import AffordanceReasoner


@dataclass
class Counted:
    key: str
    missed: int = 0


def test_a_lost_gesture_object_gives_its_gesture_up_with_the_next_object() -> None:
    reasoner = AffordanceReasoner()
    reasoner.join = join = FusionJoin(shared.network(None))
    reasoner._missed_told = {}
    reasoner.objects = Counted("beyond/r/vision/gesture_object")  # type: ignore[assignment]
    told: list[Any] = []
    reasoner.emit = told.extend  # type: ignore[method-assign]
    belief = {"tap": 0.9, "grasp": 0.05, "touch": 0.05}
    join.objects_alive(True)
    for segment_id, start in ((1, 0), (2, 20)):  # 1's object never comes; 2 is whole
        join.started(segment_id, start)
        join.belief(segment_id, 0, start, belief, None, final=True)
        join.ended(segment_id, start, start + 10)
        join.effects_seen(segment_id, {}, {})
    join.object_seen(2, {"Color": "green1"})

    def gesture_object(segment_id: int) -> GestureObject:
        header = GestureObject.original_header("objects", segment_id, 40 + segment_id)
        return GestureObject(header=header, segment_id=segment_id, frame=1, labels={})

    reasoner.on_object(gesture_object(3))  # no loss reported: 1 still holds 2 back
    assert told == []
    reasoner.objects.missed = 1  # the subscription's count of samples lost for good
    reasoner.on_object(gesture_object(4))
    assert [(type(o).__name__, o.segment_id) for o in told] == [("Lost", 1), ("Outcome", 2)]
    assert isinstance(told[0], Lost) and isinstance(told[1], Outcome)
    reasoner.on_object(gesture_object(5))  # the same loss is told once
    assert len(told) == 2
