"""Joining what the services see into the reasoner's beliefs, per gesture (P_comb).

A gesture's anticipations need the object seen when it began; its outcome needs its final
belief, its end and its measured effects. All are joined by segment id in whatever order they
arrive, and gestures are emitted strictly in segment order, so the outputs are the same whatever
the inputs' interleaving. The object segmenter always answers (with the reason when it could not
see), so while it is there it is waited for however late; only an absent one is waited out, by a
deadline in stream time. A stream-time deadline alone would lose an answer on its way when stream
time races ahead of a slow link (a replay as fast as possible).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from beyond_self.cognition.bn.model import BayesNet
from beyond_self.cognition.fusion import ACTION, fuse_marginals, fuse_words
from beyond_self.cognition.variables import EFFECTS
from beyond_self.core.errors import InputError

R = TypeVar("R")


@dataclass(frozen=True)
class Prediction:
    action_belief: dict[str, float]
    evidence: dict[str, str]
    effects: dict[str, dict[str, float]]


@dataclass(frozen=True)
class Anticipation(Generic[R]):
    segment_id: int
    frame: int
    ref: R  # of the belief it fuses
    prediction: Prediction


@dataclass(frozen=True)
class Outcome(Generic[R]):
    segment_id: int
    frame: int
    ref: R  # of the final belief
    prediction: Prediction
    words: dict[str, float]
    effects_dropped: str = ""  # why measured effects were left out, if they were


@dataclass(frozen=True)
class Lost:
    """A gesture given up: an input it needs can no longer come (`reason`)."""

    segment_id: int
    reason: str


Output = Anticipation[R] | Outcome[R] | Lost


@dataclass
class _Belief(Generic[R]):
    frame: int
    stamp: int
    ref: R
    belief: dict[str, float]


@dataclass
class _Gesture(Generic[R]):
    start_stamp: int | None = None
    features: dict[str, str] | None = None  # None until the object at the start is known
    pending: list[_Belief[R]] = field(default_factory=list)
    final: _Belief[R] | None = None
    end_stamp: int | None = None
    effects: tuple[dict[str, str], dict[str, str]] | None = None  # (object, effect) labels
    last_seen: int = -1  # latest stamp any of its inputs carried


class FusionJoin(Generic[R]):
    def __init__(
        self, model: BayesNet, *, expect_objects: bool = True, deadline_s: float = 30.0
    ) -> None:
        if not deadline_s >= 0 or deadline_s == float("inf"):
            raise InputError(f"deadline_s {deadline_s} must be a finite number >= 0")
        self.model = model
        self.expect_objects = expect_objects
        self.deadline_ns = round(deadline_s * 1e9)
        self.gestures: dict[int, _Gesture[R]] = {}
        self.finished = Recent()  # gestures told or given up: a repeat about them is ignored
        self.skeleton_time = -1
        # each input stream's own time: a gesture waits for a missing piece until the stream
        # that carries it has moved on (`_abandoned`), whatever the other streams have shown
        self.segment_time = -1  # starts and ends (one publisher, in order)
        self.belief_time = -1  # posteriors (another publisher, in order)
        self.objects_present = False  # the object segmenter is alive (told by the caller)
        # per piece a gesture needs (its final belief, its object, its effects): samples no
        # cache held came before one about this gesture, so the gestures before it still
        # lacking that piece will never have it (`beliefs_missed`, `objects_missed`, ...)
        self.lost_before: dict[str, tuple[int, str]] = {}

    # -- inputs ---------------------------------------------------------------------------

    def started(self, segment_id: int, start_stamp: int) -> list[Output[R]]:
        g = self._gesture(segment_id, start_stamp)
        if g is not None:
            g.start_stamp = start_stamp
        self.segment_time = max(self.segment_time, start_stamp)
        return self._advance(start_stamp)

    def object_seen(self, segment_id: int, labels: Mapping[str, str]) -> list[Output[R]]:
        g = self._gesture(segment_id)
        if g is not None and g.features is None:
            g.features = self.known(labels)
        return self._flush()

    def belief(
        self, segment_id: int, frame: int, stamp: int, belief: Mapping[str, float], ref: R,
        final: bool = False,
    ) -> list[Output[R]]:  # fmt: skip
        g = self._gesture(segment_id, stamp)
        if g is not None:
            item = _Belief(frame, stamp, ref, dict(belief))
            if final:
                g.final = item
            else:
                g.pending.append(item)
        self.belief_time = max(self.belief_time, stamp)
        return self._advance(stamp)

    def ended(self, segment_id: int, start_stamp: int, end_stamp: int) -> list[Output[R]]:
        g = self._gesture(segment_id, end_stamp)
        if g is not None:
            g.start_stamp = start_stamp if g.start_stamp is None else g.start_stamp
            g.end_stamp = end_stamp
        self.segment_time = max(self.segment_time, end_stamp)
        return self._advance(end_stamp)

    def cancelled(self, segment_id: int) -> list[Output[R]]:
        g = self.gestures.get(segment_id)
        if g is not None and g.end_stamp is not None:
            return []  # whole already: a restarted streamer cancels what it did not see end
        self.gestures.pop(segment_id, None)
        self.finished.add(segment_id)
        return self._flush()

    def effects_seen(
        self, segment_id: int, object_labels: Mapping[str, str], effect_labels: Mapping[str, str]
    ) -> list[Output[R]]:
        g = self._gesture(segment_id)
        if g is not None and g.effects is None:
            g.effects = (self.known(object_labels), self.known(effect_labels))
        return self._flush()

    def done(self, segment_ids: set[int]) -> list[Output[R]]:
        """These gestures were completed elsewhere (by a previous instance, whose outcome every
        consumer has): whatever comes about them is a repeat, and they hold nothing back."""
        for segment_id in segment_ids:
            self.gestures.pop(segment_id, None)
            self.finished.add(segment_id)
        return self._flush()

    def beliefs_missed(self, before: int, count: int) -> list[Output[R]]:
        """`count` beliefs were lost for good (no publisher cache held them any more) before
        one about gesture `before`. One publisher's beliefs arrive in order, so a gesture before
        `before` still lacking its final belief will never have it: it is given up (`Lost`) now,
        instead of holding back every gesture after it."""
        return self._missed("final belief", "belief(s)", before, count)

    def objects_missed(self, before: int, count: int) -> list[Output[R]]:
        """As `beliefs_missed`, for the object segmenter's object of each gesture: while the
        segmenter is alive a gesture waits for its object, so one lost would hold back every
        gesture after it for ever."""
        return self._missed("object", "object message(s)", before, count)

    def effects_missed(self, before: int, count: int) -> list[Output[R]]:
        """As `objects_missed`, for the effects measured after each gesture."""
        return self._missed("effects", "effects message(s)", before, count)

    def _missed(self, piece: str, what: str, before: int, count: int) -> list[Output[R]]:
        earlier = self.lost_before.get(piece, (-1, ""))[0]
        why = f"its {piece} was lost ({count} {what} no publisher cache held any more)"
        self.lost_before[piece] = (max(earlier, before), why)
        return self._flush()

    def skeleton_at(self, stamp: int) -> list[Output[R]]:
        return self._advance(stamp)

    def objects_alive(self, present: bool) -> list[Output[R]]:
        """The object segmenter is there (or is gone): while it is, nothing is waited out."""
        self.objects_present = present
        return self._flush()

    # -- internals ------------------------------------------------------------------------

    def known(self, labels: Mapping[str, str]) -> dict[str, str]:
        """Labels the network knows (a clusters file may name values the network lacks)."""
        values = self.model.values
        return {k: v for k, v in labels.items() if k in values and v in values[k]}

    def _gesture(self, segment_id: int, stamp: int = -1) -> _Gesture[R] | None:
        if segment_id in self.finished:
            return None  # a repeat of a finished gesture (recovered from a cache)
        g = self.gestures.setdefault(segment_id, _Gesture())
        g.last_seen = max(g.last_seen, stamp)
        return g

    def _advance(self, stamp: int) -> list[Output[R]]:
        self.skeleton_time = max(self.skeleton_time, stamp)
        return self._flush()

    def _waited_out(self, stamp: int | None) -> bool:
        if not self.expect_objects:
            return True
        if self.objects_present:
            return False
        return stamp is not None and self.skeleton_time >= stamp + self.deadline_ns

    def _lost_piece(self, segment_id: int, g: _Gesture[R]) -> str | None:
        """Why gesture `segment_id` can never be complete (a piece it lacks was lost), or None."""
        if not self.lost_before:  # nothing lost: the common case, checked per belief
            return None
        lacking = {"final belief": g.final, "object": g.features, "effects": g.effects}
        for piece, have in lacking.items():
            before, why = self.lost_before.get(piece, (-1, ""))
            if have is None and segment_id < before:
                return why
        return None

    def _abandoned(self, g: _Gesture[R]) -> bool:
        """Incomplete, and the stream that would complete it has moved on by the deadline: the
        piece is lost. Not any stream's time: a late reasoner gets each stream's history as a
        batch of its own, in no fixed order, and a posterior history running 30 s past a gesture
        whose end event was still to come dropped it (a workstation started late lost gesture 1)."""
        if g.final is not None and g.end_stamp is not None:
            return False  # complete but for the camera, which `_waited_out` handles
        if g.last_seen < 0:
            return False
        after = g.last_seen + self.deadline_ns
        return (g.end_stamp is None and self.segment_time >= after) or (
            g.final is None and self.belief_time >= after
        )

    def _flush(self) -> list[Output[R]]:
        outputs: list[Output[R]] = []
        for segment_id in sorted(self.gestures):
            g = self.gestures[segment_id]
            if (lost := self._lost_piece(segment_id, g)) is not None:
                outputs.append(Lost(segment_id, lost))
                del self.gestures[segment_id]
                self.finished.add(segment_id)
                continue
            if self._abandoned(g):
                # no input about it for a deadline of stream time and still incomplete (its
                # start or end never came): it must not hold back the gestures after it
                del self.gestures[segment_id]
                self.finished.add(segment_id)
                continue
            if g.features is None and self._waited_out(g.start_stamp):
                g.features = {}
            if g.features is None:
                break
            for item in g.pending:
                prediction = self.predict(g.features, item.belief)
                outputs.append(Anticipation(segment_id, item.frame, item.ref, prediction))
            g.pending.clear()
            if g.effects is None and g.end_stamp is not None and self._waited_out(g.end_stamp):
                g.effects = ({}, {})
            if g.final is None or g.end_stamp is None or g.effects is None:
                break
            outputs.append(self._outcome(segment_id, g))
            del self.gestures[segment_id]
            self.finished.add(segment_id)
        return outputs

    def predict(self, observed: Mapping[str, str], belief: Mapping[str, float]) -> Prediction:
        effects = [v for v in EFFECTS if v in self.model.values and v not in observed]
        fused = fuse_marginals(self.model, [ACTION, *effects], observed, belief)
        action = fused.pop(ACTION)
        return Prediction(
            action_belief=_normalised(action),
            evidence=dict(observed),
            effects={k: _normalised(v) for k, v in fused.items()},
        )

    def _outcome(self, segment_id: int, g: _Gesture[R]) -> Outcome[R]:
        assert g.final is not None and g.features is not None and g.effects is not None
        observed = dict(g.features)
        observed.update(g.effects[0])
        observed.update(g.effects[1])
        dropped = ""
        try:
            prediction = self.predict(observed, g.final.belief)
        except InputError as exc:
            # the measured effects contradict the gesture under the network: keep the object's
            # features and the gesture, drop the effects, and say so
            dropped = f"gesture {segment_id}: measured effects left out: {exc}"
            observed = dict(g.features)
            prediction = self.predict(observed, g.final.belief)
        words = fuse_words(self.model, observed, g.final.belief)
        clipped = {w: min(1.0, max(0.0, p)) for w, p in words.items()}
        return Outcome(segment_id, g.final.frame, g.final.ref, prediction, clipped, dropped)


class Recent:
    """A set of the last `size` segment ids added: what a cache can still repeat (it holds the
    last 64 events) is remembered, and a long run does not grow without bound."""

    def __init__(self, size: int = 4096) -> None:
        self.size = size
        self._ids: dict[int, None] = {}

    def add(self, segment_id: int) -> None:
        self._ids.pop(segment_id, None)
        self._ids[segment_id] = None
        if len(self._ids) > self.size:
            del self._ids[next(iter(self._ids))]

    def __contains__(self, segment_id: object) -> bool:
        return segment_id in self._ids


def _normalised(dist: Mapping[str, float]) -> dict[str, float]:
    total = sum(dist.values())
    return {k: v / total for k, v in dist.items()}
