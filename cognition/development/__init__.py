"""Developmental learning: from the robot's own experience to recognising a human's actions.

    from cognition.development import LearningConfig, run_learning, write_outputs
    results = run_learning(LearningConfig(), robot_data="synthetic", human_data="synthetic")
    write_outputs(results, "out/")        # learning.md, results.json, PNGs

`demonstrations` makes the human demonstrations the robot watches (gesture, object, effects,
words, each imperfect); `learning` holds the steps (network posteriors, the labelling rule,
training on inferred labels, tempered gesture evidence, fusion, scores); `report` writes the
outputs. The module docstrings say what was chosen and why.
"""

from cognition.development.demonstrations import (
    HUMAN_GESTURES,
    Demonstration,
    EffectModel,
    ObservationConfig,
    RecordedEffects,
    SimulatedEffects,
    demonstrations_from_gestures,
    effect_model,
    split_demonstrations,
    synthesize_demonstrations,
)
from cognition.development.learning import (
    DEFAULT_TRAINING,
    SOURCE_NAMES,
    SOURCES,
    SYNTHETIC,
    Condition,
    Labelling,
    LearningConfig,
    LearningResults,
    Score,
    calibrate_kappa,
    fit_kappa,
    fused_posteriors,
    infer_labels,
    load_robot_data,
    network_posteriors,
    per_frame_loglik,
    plan_units,
    run_learning,
    self_phase,
    tempered_posterior,
    train_on_labels,
    word_evidence,
)
from cognition.development.report import report_markdown, write_outputs

__all__ = [
    "DEFAULT_TRAINING",
    "HUMAN_GESTURES",
    "SOURCES",
    "SOURCE_NAMES",
    "SYNTHETIC",
    "Condition",
    "Demonstration",
    "EffectModel",
    "Labelling",
    "LearningConfig",
    "LearningResults",
    "ObservationConfig",
    "RecordedEffects",
    "Score",
    "SimulatedEffects",
    "calibrate_kappa",
    "demonstrations_from_gestures",
    "effect_model",
    "fit_kappa",
    "fused_posteriors",
    "infer_labels",
    "load_robot_data",
    "network_posteriors",
    "per_frame_loglik",
    "plan_units",
    "report_markdown",
    "run_learning",
    "self_phase",
    "split_demonstrations",
    "synthesize_demonstrations",
    "tempered_posterior",
    "train_on_labels",
    "word_evidence",
    "write_outputs",
]
