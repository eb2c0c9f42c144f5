"""Affordance reasoner: holds the Affordance–Words network and fuses what the other services
see with what the gesture recogniser believes (P_comb).

The per-gesture join is `cognition.episodes.FusionJoin`, by segment id: every belief fused with
the gesture's object gives an anticipation; its final belief, end and effects give the final
belief and the word probabilities the describer turns into sentences, strictly in segment order.
With `objects: false` nothing waits for vision; an absent segmenter is waited out by
`deadline_s` of skeleton stream time. It also answers ad-hoc queries (`beyond ask`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from beyond_self.cognition.bn import BayesNet
from beyond_self.cognition.bn.evidence import Evidence, build_evidence
from beyond_self.cognition.episodes import FusionJoin, Lost, Outcome
from beyond_self.cognition.episodes.join import Output, Prediction
from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.delivery import EVENTS, FRAMES
from beyond_self.runtime.bus.subscription import Subscription
from beyond_self.runtime.service import Service
from beyond_self.schemas import (
    ActionPosterior,
    AffordanceAnswer,
    AffordancePrediction,
    AffordanceQuery,
    AnswerRow,
    GestureObject,
    GestureSegment,
    Header,
    Message,
    ObjectEffects,
    WordProbabilities,
)
from beyond_self.services import shared


class AffordanceReasoner(Service):
    name = "reasoner"
    subscribes = ("gesture_object", "gesture_posterior", "gesture_segment", "effects")
    publishes = ("affordance", "words")
    serves = ("ask",)
    fleet = True  # a workstation may serve many robots with one process (runtime.fleet)

    def __init__(
        self,
        *,
        model: str | None = None,
        objects: bool = True,
        deadline_s: float = 30.0,
        **base: Any,
    ) -> None:
        super().__init__(**base)
        self.model_path = model
        self.expect_objects = objects
        self.deadline_s = deadline_s

    @classmethod
    def warm(cls, options: Mapping[str, Any]) -> None:
        shared.warm_fusion(options.get("model"))  # a network file's, or learned (no file)

    async def setup(self) -> None:
        self.model: BayesNet = shared.network(self.model_path)
        self.join: FusionJoin[Header] = FusionJoin(
            self.model, expect_objects=self.expect_objects, deadline_s=self.deadline_s
        )
        keys = self.bus.keys
        # restarted: the gestures whose words every consumer has are done; what comes back
        # about them from the caches is not worked on again, nor waited for
        self.join.done(self.downstream(keys.words).done("words"))
        self.predictions = self.publisher(keys.affordance, AffordancePrediction, FRAMES)
        self.words_out = self.publisher(keys.words, WordProbabilities, EVENTS)
        self.objects = self.subscribe(keys.gesture_object, GestureObject, self.on_object, EVENTS)
        self.beliefs = self.subscribe(
            keys.gesture_posterior, ActionPosterior, self.on_posterior, FRAMES
        )
        self.subscribe(keys.gesture_segment, GestureSegment, self.on_segment, EVENTS)
        self.effects = self.subscribe(keys.effects, ObjectEffects, self.on_effects, EVENTS)
        self._missed_told: dict[str, int] = {}  # per input: samples no cache held, told so far
        self.queryable(keys.ask, AffordanceQuery, self.on_ask)
        self._segmenters: set[str] = set()
        self.watch_tokens(keys.alive("objects"), self.on_objects_alive)

    def on_objects_alive(self, key: str, present: bool) -> None:
        (self._segmenters.add if present else self._segmenters.discard)(key)
        self.emit(self.join.objects_alive(bool(self._segmenters)))

    # -- inputs ---------------------------------------------------------------------------

    def tell_missed(
        self, sub: Subscription[Any], tell: Callable[[int, int], list[Output[Header]]], before: int
    ) -> None:
        """Tell the join what `sub` lost for good since last told, before gesture `before`:
        one publisher's samples arrive in order, so the gestures before it lacking what `sub`
        carries are given up instead of waited for."""
        missed = sub.missed
        told = self._missed_told.get(sub.key, 0)
        if missed > told:
            self._missed_told[sub.key] = missed
            self.emit(tell(before, missed - told))

    def on_object(self, msg: GestureObject) -> None:
        self.tell_missed(self.objects, self.join.objects_missed, msg.segment_id)
        self.emit(self.join.object_seen(msg.segment_id, msg.labels))

    def on_posterior(self, msg: ActionPosterior) -> None:
        self.tell_missed(self.beliefs, self.join.beliefs_missed, msg.segment_id)
        belief = dict(zip(msg.actions, msg.posterior, strict=True))
        self.emit(
            self.join.belief(
                msg.segment_id, msg.frame, msg.header.stamp, belief, msg.header, msg.final
            )
        )

    def on_segment(self, msg: GestureSegment) -> None:
        if msg.event == "start":
            self.emit(self.join.started(msg.segment_id, msg.start_stamp))
        elif msg.event == "cancel":
            self.emit(self.join.cancelled(msg.segment_id))
        elif msg.end_stamp is not None:
            self.emit(self.join.ended(msg.segment_id, msg.start_stamp, msg.end_stamp))

    def on_effects(self, msg: ObjectEffects) -> None:
        self.tell_missed(self.effects, self.join.effects_missed, msg.segment_id)
        first = msg.effects[0] if msg.measured and msg.effects else None
        self.emit(
            self.join.effects_seen(
                msg.segment_id,
                first.object_labels if first else {},
                first.labels if first else {},
            )
        )

    # -- outputs --------------------------------------------------------------------------

    def emit(self, outputs: list[Output[Header]]) -> None:
        for out in outputs:
            if isinstance(out, Lost):  # not described: the watcher counts it lost
                self.report_error("lost", InputError(f"gesture {out.segment_id}: {out.reason}"))
                continue
            final = isinstance(out, Outcome)
            self.predictions.put(
                self._prediction(out.ref, out.segment_id, out.frame, out.prediction, final)
            )
            if isinstance(out, Outcome):
                if out.effects_dropped:
                    self.report_error("effects", InputError(out.effects_dropped))
                self.words_out.put(
                    WordProbabilities(
                        header=self.derive(out.ref, WordProbabilities),
                        segment_id=out.segment_id,
                        words=out.words,
                        evidence=out.prediction.evidence,
                        action_belief=out.prediction.action_belief,
                        final=True,
                    )
                )

    def _prediction(
        self, ref: Header, segment_id: int, frame: int, p: Prediction, final: bool
    ) -> AffordancePrediction:
        return AffordancePrediction(
            header=self.derive(ref, AffordancePrediction),
            segment_id=segment_id,
            frame=frame,
            action_belief=p.action_belief,
            evidence=p.evidence,
            effects=p.effects,
            final=final,
        )

    async def on_ask(self, key: str, q: AffordanceQuery | None) -> list[tuple[str, Message]]:
        if q is None:
            raise InputError("an ask query needs an AffordanceQuery payload")
        ev = build_evidence(self.model, Evidence(q.evidence, q.soft, q.gesture))
        posterior = self.model.query(q.query, ev.observed, ev.soft)
        answer = AffordanceAnswer(
            header=self.header(AffordanceAnswer),
            variables=list(posterior.variables),
            rows=[AnswerRow(assignment=a, p=p) for a, p in posterior.rows()],
        )
        return [(key, answer)]
