"""Description generator: word probabilities in, the exact N-best sentences of the grammar out.

Final word probabilities (a completed gesture) always give a description; with `unfolding` on,
intermediate ones do too (marked not final), for a robot that comments while it watches.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from beyond_self.cognition.descriptions import nbest_exact
from beyond_self.runtime.bus.delivery import EVENTS
from beyond_self.runtime.service import Service
from beyond_self.schemas import Description, Evidence, ScoredSentence, WordProbabilities
from beyond_self.services import shared


class DescriptionGenerator(Service):
    name = "describer"
    subscribes = ("words",)
    publishes = ("description",)
    serves = ()
    fleet = True  # a workstation may serve many robots with one process (runtime.fleet)

    def __init__(
        self, *, nbest: int = 5, legacy_offset: bool = False, unfolding: bool = False, **base: Any
    ) -> None:
        super().__init__(**base)
        self.nbest = nbest
        self.legacy_offset = legacy_offset
        self.unfolding = unfolding

    @classmethod
    def warm(cls, options: Mapping[str, Any]) -> None:
        shared.warm_descriptions(options.get("nbest", 5))

    async def setup(self) -> None:
        keys = self.bus.keys
        self.out = self.publisher(keys.description, Description, EVENTS)
        # once: a restarted describer does not describe again what its predecessor described
        self.subscribe(keys.words, WordProbabilities, self.on_words, EVENTS, once=True)

    def on_words(self, msg: WordProbabilities) -> None:
        if not msg.final and not self.unfolding:
            return
        best = nbest_exact(msg.words, self.nbest, legacy_offset=self.legacy_offset)
        self.out.put(
            Description(
                header=self.derive(msg.header, Description),
                segment_id=msg.segment_id,
                sentences=[ScoredSentence(text=s.sentence, score=round(s.score, 6)) for s in best],
                evidence=Evidence(
                    hard=dict(msg.evidence), soft={"Action": dict(msg.action_belief)}
                ),
                final=msg.final,
            )
        )
