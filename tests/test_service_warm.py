"""A service process makes the science's once-per-process tables before it joins the bus
(`Service.warm`), so the first robot to end a gesture does not wait for them: the reasoner's
compiled network (its first query), the describer's grammar positions (its first search)."""

from __future__ import annotations

from beyond_self.cognition.descriptions.space import SentenceSpace
from beyond_self.services import shared
from beyond_self.services.describer import DescriptionGenerator
from beyond_self.services.reasoner import AffordanceReasoner


def test_the_reasoner_compiles_its_network_before_any_belief() -> None:
    model = shared.network(None)
    model.__dict__.pop("compiled", None)  # as a process that has queried nothing yet
    shared.warm_fusion.cache_clear()
    AffordanceReasoner.warm({})
    assert "compiled" in model.__dict__


def test_the_describer_lays_out_its_grammar_before_any_words() -> None:
    space = SentenceSpace.of()
    space.__dict__.pop("positions", None)
    shared.warm_descriptions.cache_clear()
    DescriptionGenerator.warm({"nbest": 3})
    assert "positions" in space.__dict__
