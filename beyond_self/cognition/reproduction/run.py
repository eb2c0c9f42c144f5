"""All the experiments in order, with what the figure checks need of them (`run_all`)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from beyond_self.cognition.reproduction.exp1_conflict import exp1
from beyond_self.cognition.reproduction.exp2_effects import exp2
from beyond_self.cognition.reproduction.exp3_anticipation import by_action, exp3
from beyond_self.cognition.reproduction.exp4_words import exp4
from beyond_self.cognition.reproduction.exp5_descriptions import exp5
from beyond_self.cognition.reproduction.exp6_colours import exp6
from beyond_self.cognition.reproduction.figure_checks import published
from beyond_self.cognition.reproduction.inputs import load_inputs


def run_all(data: Path, progress: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    progress("learning the network and loading the gesture models")
    inputs = load_inputs(data)
    progress("experiment 1: conflicting evidence")
    r1 = exp1(inputs.model)
    progress("experiment 2: effect prediction")
    r2 = exp2(inputs.model)
    progress("experiment 3: effect anticipation on a recorded tap")
    r3 = exp3(inputs)
    progress("experiment 4: word prediction")
    r4 = exp4(inputs.model)
    progress("experiment 5: N-best descriptions")
    r5 = exp5(inputs, by_action(r3["actions"], r3["final_posterior"]))
    progress("experiment 6: object words")
    r6 = exp6(inputs)
    progress("the published figures under each rule for unseen word columns")
    rp = published(inputs, r3)
    return {
        "data": str(data),
        "exp1": r1,
        "exp2": r2,
        "exp3": r3,
        "exp4": r4,
        "exp5": r5,
        "exp6": r6,
        "published": rp,
    }
