"""Gesture models side by side on recordings of people (`beyond gesture evaluate compare`).

On a folder of the article's hand recordings: our default models on every execution the
segmenter finds (what `beyond up --log` describes); leave-one-recording-out cross-validation on
the recordings alone and mixed with synthetic gestures; leave-one-gesture-out on the recordings
alone; and the article's HMMs and ours on the article's own hand-picked ranges
(`ARTICLE_RANGES`), the only gestures the article tested its models on.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from beyond_self.cognition.gestures.datasets import (
    article_gestures,
    load_gestures,
    synthetic_gestures,
)
from beyond_self.cognition.gestures.evaluation import (
    EvaluationReport,
    LabelledGesture,
    cross_validate,
    evaluate,
)
from beyond_self.cognition.gestures.hmm import GestureModels
from beyond_self.cognition.gestures.training import TrainingConfig

ARTICLE_MODELS = "HMM_M3_Q6_mixsplit.mat"


@dataclass(frozen=True, eq=False)
class Entry:
    """One line of the comparison: which models, on which gestures, and how they did."""

    name: str
    what: str
    report: EvaluationReport


def compare_on_recordings(
    folder: Path,
    *,
    default: GestureModels,
    article: GestureModels | None,
    config: TrainingConfig,
    synthetic: list[LabelledGesture] | None = None,
    n_synthetic: int = 30,
    seed: int = 0,
    push_as: str | None = "touch",
    on_step: Callable[[str], None] | None = None,
) -> list[Entry]:
    """Every evaluation of the module docstring, in that order (the article's models only when
    given). `synthetic`: the robot's own gestures the mixed cross-validation trains on (default:
    `n_synthetic` per action from `seed`)."""

    recorded = load_gestures(folder, push_as=push_as)
    ranged = article_gestures(folder, push_as=push_as)
    mixed = synthetic if synthetic is not None else synthetic_gestures(n_synthetic, seed)
    plan: list[tuple[str, str, Callable[[], EvaluationReport]]] = [
        (
            "default",
            "our default models (synthetic training only), every execution the segmenter finds",
            lambda: evaluate(default, recorded),
        ),
        (
            "loro",
            "leave-one-recording-out, trained on the other recordings",
            lambda: cross_validate(recorded, config, folds="recording"),
        ),
        (
            "loro+synthetic",
            f"leave-one-recording-out, trained on the other recordings and {len(mixed)} "
            "synthetic gestures",
            lambda: cross_validate(recorded, config, folds="recording", also_train_on=mixed),
        ),
        (
            "logo",
            "leave-one-gesture-out, trained on every other execution (same recordings)",
            lambda: cross_validate(recorded, config, folds="gesture"),
        ),
    ]
    if article is not None:
        plan.append(
            (
                "article",
                "the article's HMM_M3_Q6 models on the article's own ranges",
                lambda: evaluate(article, ranged),
            )
        )
    plan.append(
        (
            "default@ranges",
            "our default models on the article's own ranges",
            lambda: evaluate(default, ranged),
        )
    )
    out = []
    for name, what, run in plan:
        out.append(Entry(name, what, run()))
        if on_step is not None:
            on_step(name)
    return out
