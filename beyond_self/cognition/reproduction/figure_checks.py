"""The figures the article prints numbers for, re-run under each rule for unseen word columns
(UNSEEN_COMPARED) and checked against the article (cognition.published), so the report says
which rule each figure needs; the two it only plots (3, 5) by how much the rules change them."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from beyond_self.cognition.bn.model import BayesNet
from beyond_self.cognition.descriptions import ScoredSentence, nbest_from_file
from beyond_self.cognition.published import (
    FIG4,
    FIG7_BARS,
    FIG7A,
    FIG7B,
    FIG8,
    TABLE_II,
    Check,
    check_sentences,
    check_table,
    check_values,
    check_word_bars,
)
from beyond_self.cognition.reproduction.exp1_conflict import exp1
from beyond_self.cognition.reproduction.exp2_effects import exp2
from beyond_self.cognition.reproduction.exp3_anticipation import anticipate, by_action
from beyond_self.cognition.reproduction.exp4_words import EXP4_OBSERVED, exp4
from beyond_self.cognition.reproduction.exp5_descriptions import EXP5_GRASP, exp5
from beyond_self.cognition.reproduction.exp6_colours import exp6
from beyond_self.cognition.reproduction.inputs import UNSEEN_COMPARED, Inputs


def table2(model: BayesNet, sentences: Path) -> list[ScoredSentence]:
    """Table II: the 10-best of the article's list for EXP4_OBSERVED, no action evidence."""
    return nbest_from_file(
        sentences, model.word_probabilities(EXP4_OBSERVED), 10, legacy_offset=True
    )


def published(inputs: Inputs, r3: Mapping[str, Any]) -> dict[str, Any]:
    """Every figure the article prints numbers for, re-run under each rule in UNSEEN_COMPARED and
    checked against the article; the two figures it only plots (3, 5) by how much the rules
    change them. `r3` is experiment 3's result (its gesture posterior is reused)."""
    gesture = (r3["actions"], np.array(r3["posterior"]), r3["steps"])
    ours: dict[str, dict[str, Any]] = {}
    for rule, model in inputs.networks.items():
        rerun = replace(inputs, model=model)
        e5 = exp5(rerun, by_action(r3["actions"], r3["final_posterior"]))
        ours[rule] = {
            "table2": table2(model, inputs.sentences),
            "fig7": {conj: e5[conj]["file"] for conj in EXP5_GRASP},
            "fig7_bars": {conj: (e5[conj]["p_and"], e5[conj]["p_but"]) for conj in EXP5_GRASP},
            "fig4": {
                f"{shape} {k}": v for shape, rows in exp2(model).items() for k, v in rows.items()
            },
            "fig6": exp4(model),
            "fig8": {k: v["file"] for k, v in exp6(rerun).items()},
            "fig3": np.array(exp1(model)["pcomb"]),
            "fig5": np.array([*anticipate(model, *gesture).values()]),
        }
    fig4 = {f"{shape} {k}": v for shape, rows in FIG4.items() for k, v in rows.items()}
    checks: dict[str, Callable[[Mapping[str, Any]], Check]] = {
        "Table II": lambda o: check_table(TABLE_II, o["table2"]),
        "Fig. 7a (list)": lambda o: check_table(FIG7A, o["fig7"]["and"]),
        "Fig. 7b (list)": lambda o: check_table(FIG7B, o["fig7"]["but"]),
        "Fig. 7a/7b (bars)": lambda o: check_values(FIG7_BARS, o["fig7_bars"]),
        "Fig. 4": lambda o: check_values(fig4, o["fig4"]),
        "Fig. 6": lambda o: check_word_bars(o["fig6"]),
        "Fig. 8": lambda o: check_sentences(FIG8, o["fig8"]),
    }
    figures: dict[str, dict[str, Any]] = {}
    for name, check in checks.items():
        by_rule = {rule: check(o) for rule, o in ours.items()}
        figures[name] = {
            "checks": {rule: c.as_dict() for rule, c in by_rule.items()},
            "needs": [rule for rule, c in by_rule.items() if c.reproduced],
        }
    a, z = (ours[rule] for rule in UNSEEN_COMPARED)
    for name, key in (("Fig. 3", "fig3"), ("Fig. 5", "fig5")):
        figures[name] = {
            "checks": {},
            "rules_differ_by": float(np.max(np.abs(a[key] - z[key]))),
        }
    return {"figures": figures, "lists": {rule: _lists(o) for rule, o in ours.items()}}


def _lists(o: Mapping[str, Any]) -> dict[str, list[ScoredSentence]]:
    return {"Table II": o["table2"], "Fig. 7a": o["fig7"]["and"], "Fig. 7b": o["fig7"]["but"]}
