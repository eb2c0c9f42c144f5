"""Affordance reasoner: holds the Affordance–Words network and fuses what the other services
see with what the gesture recogniser believes (SPEC.md, P_comb).

While a gesture unfolds, every action posterior gives an anticipation: the fused action belief
and the predicted effects given the object's features. When a gesture is complete (its final
posterior, its "end" event and the measured effects have all arrived, in any order), it
publishes the final belief with the effects observed, and the word probabilities that the
description generator turns into sentences. It also answers ad-hoc queries (`beyond ask`).
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cognition.bn import BayesNet, learn_network, load_model, synthetic_dataset
from cognition.errors import InputError, unknown
from cognition.fusion import ACTION, action_vector, fuse, fuse_words
from cognition.variables import EFFECTS
from runtime.reliable import EVENT_CACHE, FRAME_CACHE
from runtime.service import Service
from schemas import (
    ActionPosterior,
    AffordanceAnswer,
    AffordancePrediction,
    AffordanceQuery,
    AnswerRow,
    DetectedObjects,
    GestureSegment,
    Header,
    Message,
    ObjectEffects,
    WordProbabilities,
)


@dataclass
class _Gesture:
    final: ActionPosterior | None = None
    ended: GestureSegment | None = None
    effects: ObjectEffects | None = None
    done: bool = False
    features: dict[str, str] = field(default_factory=dict)


class AffordanceReasoner(Service):
    name = "reasoner"
    subscribes = ("objects", "gesture_posterior", "gesture_segment", "effects")
    publishes = ("affordance", "words")
    serves = ("ask",)

    def __init__(
        self, *, model: str | None = None, keep: int = 64, effects_wait_s: float = 3.0, **base: Any
    ) -> None:
        super().__init__(**base)
        self.model_path = model
        self.keep = keep
        self.effects_wait_s = effects_wait_s
        self.features: dict[str, str] = {}  # latest object labels seen on the table
        self.gestures: dict[int, _Gesture] = {}

    async def setup(self) -> None:
        self.model: BayesNet = (
            load_model(Path(self.model_path))
            if self.model_path
            else learn_network(synthetic_dataset())
        )
        keys = self.bus.keys
        self.predictions = self.publisher(keys.affordance, AffordancePrediction, cache=FRAME_CACHE)
        self.words_out = self.publisher(keys.words, WordProbabilities, cache=EVENT_CACHE)
        self.subscribe(keys.objects, DetectedObjects, self.on_objects, recover=True)
        self.subscribe(keys.gesture_posterior, ActionPosterior, self.on_posterior, recover=True)
        self.subscribe(keys.gesture_segment, GestureSegment, self.on_segment, recover=True)
        self.subscribe(keys.effects, ObjectEffects, self.on_effects, recover=True)
        self.bus.queryable(keys.ask, self.on_ask)

    # -- inputs ---------------------------------------------------------------------------

    def on_objects(self, msg: DetectedObjects) -> None:
        if msg.objects:
            obj = max(msg.objects, key=lambda o: o.area)  # the object the scene is about
            labels = {"Color": obj.colour_label, "Shape": obj.shape_label, "Size": obj.size_label}
            self.features = self._known(labels)

    def _known(self, labels: dict[str, str]) -> dict[str, str]:
        """Labels the network knows (a clusters file may name values the network lacks)."""
        values = self.model.values
        return {k: v for k, v in labels.items() if k in values and v in values[k]}

    def _gesture(self, segment_id: int) -> _Gesture:
        g = self.gestures.get(segment_id)
        if g is None:
            g = self.gestures[segment_id] = _Gesture(features=dict(self.features))
            for old in sorted(self.gestures)[: -self.keep]:
                del self.gestures[old]
        return g

    def on_posterior(self, msg: ActionPosterior) -> None:
        g = self._gesture(msg.segment_id)
        if msg.final:
            g.final = msg
            self._maybe_finish(msg.segment_id, g)
            return
        belief = dict(zip(msg.actions, msg.posterior, strict=True))
        observed = dict(g.features)
        self.predictions.put(
            self._prediction(msg.header, msg.segment_id, msg.frame, observed, belief)
        )

    def on_segment(self, msg: GestureSegment) -> None:
        g = self._gesture(msg.segment_id)
        if msg.event == "start":
            g.features = dict(self.features)
        else:
            g.ended = msg
            self._maybe_finish(msg.segment_id, g)

    def on_effects(self, msg: ObjectEffects) -> None:
        g = self._gesture(msg.segment_id)
        g.effects = msg
        self._maybe_finish(msg.segment_id, g)

    # -- outputs --------------------------------------------------------------------------

    def _prediction(
        self, header: Header, segment_id: int, frame: int, observed: dict[str, str],
        belief: dict[str, float], final: bool = False,
    ) -> AffordancePrediction:  # fmt: skip
        action = fuse(self.model, ACTION, observed, belief).marginal(ACTION)
        effects = {
            var: fuse(self.model, var, observed, belief).marginal(var)
            for var in EFFECTS
            if var in self.model.values and var not in observed
        }
        return AffordancePrediction(
            header=self.derive(header, AffordancePrediction),
            segment_id=segment_id,
            frame=frame,
            action_belief=_normalised(action),
            evidence=observed,
            effects={k: _normalised(v) for k, v in effects.items()},
            final=final,
        )

    def _maybe_finish(self, segment_id: int, g: _Gesture, without_effects: bool = False) -> None:
        if g.done or g.final is None or g.ended is None:
            return
        if g.effects is None and not without_effects:
            # no object segmenter, or no camera: describe from the gesture and object alone
            asyncio.get_running_loop().call_later(
                self.effects_wait_s, self._finish_without_effects, segment_id, g
            )
            return
        g.done = True
        observed = dict(g.features)
        for effect in g.effects.effects[:1] if g.effects else []:
            observed.update(self._known(effect.object_labels))
            observed.update(self._known(effect.labels))
        belief = dict(zip(g.final.actions, g.final.posterior, strict=True))
        header = g.final.header
        try:
            prediction = self._prediction(header, segment_id, g.final.frame, observed, belief, True)
        except InputError:
            # the measured effects contradict the gesture under the network: keep the object's
            # features and the gesture, drop the effects (logged and counted by the caller)
            observed = dict(g.features)
            prediction = self._prediction(header, segment_id, g.final.frame, observed, belief, True)
        self.predictions.put(prediction)
        words = fuse_words(self.model, observed, belief)
        self.words_out.put(
            WordProbabilities(
                header=self.derive(header, WordProbabilities),
                segment_id=segment_id,
                words={w: min(1.0, max(0.0, p)) for w, p in words.items()},
                evidence=observed,
                action_belief=prediction.action_belief,
                final=True,
            )
        )

    def _finish_without_effects(self, segment_id: int, g: _Gesture) -> None:
        try:
            self._maybe_finish(segment_id, g, without_effects=True)
        except InputError as exc:
            self._failed("timer", exc)

    async def on_ask(self, key: str, payload: bytes | None) -> list[tuple[str, Message]]:
        from schemas.codec import decode

        if payload is None:
            raise InputError("an ask query needs an AffordanceQuery payload")
        q = decode(payload, AffordanceQuery, key)
        soft: dict[str, list[float]] = {}
        for var, dist in q.soft.items():
            if var not in self.model.values:
                raise unknown("soft-evidence variable", var, self.model.variables)
            extra = [v for v in dist if v not in self.model.values[var]]
            if extra:
                raise unknown(f"value of {var}", extra[0], self.model.values[var])
            soft[var] = [dist.get(v, 0.0) for v in self.model.values[var]]
        if q.gesture:
            if ACTION in soft:
                raise InputError("give the action either as gesture evidence or as soft evidence")
            soft[ACTION] = action_vector(self.model, q.gesture).tolist()
            if ACTION in q.evidence:
                raise InputError("the action is never observed with gesture evidence; drop it")
        posterior = self.model.query(q.query, q.evidence, soft)
        answer = AffordanceAnswer(
            header=self.header(AffordanceAnswer),
            variables=list(posterior.variables),
            rows=[AnswerRow(assignment=a, p=p) for a, p in posterior.rows()],
        )
        return [(key, answer)]


def _normalised(dist: dict[str, float]) -> dict[str, float]:
    total = sum(dist.values())
    return {k: v / total for k, v in dist.items()}
