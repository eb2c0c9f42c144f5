"""Trained on synthetic gestures, recognising held-out ones, early; real-data cross-validation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from beyond_self.cognition.gestures.datasets import load_gestures, synthetic_gestures
from beyond_self.cognition.gestures.default_models import default_models
from beyond_self.cognition.gestures.evaluation import (
    EvaluationReport,
    cross_validate,
    evaluate,
    plot_report,
)
from beyond_self.cognition.gestures.training import TrainingConfig

# these figures are computed again under a second OpenBLAS kernel (Makefile: numeric)
pytestmark = pytest.mark.numeric


@pytest.fixture(scope="module")
def held_out_report() -> EvaluationReport:
    """The shipped models (trained on synthetic seed 0) on gestures they never saw."""
    return evaluate(default_models(), synthetic_gestures(10, seed=1))


def test_held_out_accuracy_and_early_recognition(held_out_report: EvaluationReport) -> None:
    r = held_out_report
    assert r.n == 30
    assert r.accuracy >= 0.95
    assert r.accuracy_at(0.6) >= 0.75
    assert r.fractions == (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
    assert r.early_accuracy[-1] == pytest.approx(r.accuracy)
    assert r.early_accuracy[0] < r.early_accuracy[-1]  # a few frames say little: the curve rises
    assert r.confusion.sum(axis=1).tolist() == [10, 10, 10]


def test_default_models_are_left_to_right_motion_models_with_a_floor() -> None:
    models = default_models()
    assert models.actions == ("grasp", "tap", "touch")
    assert models.features == "motion" and models.floor is not None
    for h in models.hmms:
        assert (h.n_states, h.n_mix, h.n_features) == (6, 3, 7)
        assert h.is_left_to_right
    assert models.meta["sequences"] == {"grasp": 60, "tap": 60, "touch": 60}
    # trained on synthetic gestures only: no recording of a person
    assert models.meta["data"] == "synthetic" and models.meta["seed"] == 0


def test_plots_are_written(held_out_report: EvaluationReport, tmp_path: Path) -> None:
    paths = plot_report(held_out_report, tmp_path / "plots", title="synthetic")
    for p in paths:
        assert p.suffix == ".png" and p.stat().st_size > 5000
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cross_validation_never_tests_on_training_data(monkeypatch: pytest.MonkeyPatch) -> None:
    import dataclasses

    import beyond_self.cognition.gestures.evaluation as ev

    # three recordings, each holding one gesture of every action
    gestures = [
        dataclasses.replace(g, recording=f"r{i % 3}")
        for i, g in enumerate(synthetic_gestures(3, seed=5))
    ]
    extra = synthetic_gestures(1, seed=6)  # trained on in every fold, never tested
    seen: list[list[np.ndarray]] = []
    real_train = ev.train_hmm

    def spy(seqs, config, *, what="action"):  # type: ignore[no-untyped-def]
        seen.append(list(seqs))
        return real_train(seqs, config, what=what)

    monkeypatch.setattr(ev, "train_hmm", spy)
    config = TrainingConfig(n_states=3, n_mix=1, n_iter=2)
    report = cross_validate(gestures, config, also_train_on=extra)
    assert report.n == 9 and report.meta["folds"] == 3
    assert {p.source for p in report.predictions} == {g.source for g in gestures}
    folds = seen[3:]  # after the three full models: per recording, one model per action
    assert len(folds) == 9
    for k, fold in enumerate(folds):
        held = [g for g in gestures if g.recording == f"r{k // 3}"]
        assert len(fold) == 3  # the two other recordings' gesture of the action, and extra's
        assert not any(np.array_equal(g.features, x) for g in held for x in fold)
        assert any(np.array_equal(e.features, x) for e in extra for x in fold)
    by_gesture = cross_validate(gestures, config, folds="gesture")
    assert by_gesture.meta["folds"] == 9


@pytest.mark.slow
def test_real_recordings_cross_validated(shared_data: Path) -> None:
    """Leave one recording out on the article's recordings alone: grasp is in one recording
    only, so the fold that holds it out has no grasp model (its four grasps cannot be right);
    leaving one execution out instead, every action has training data."""
    gestures = load_gestures(shared_data / "saponaro2019/human_data", push_as="touch")
    config = TrainingConfig(n_states=4, n_mix=1, n_iter=10)
    loro = cross_validate(gestures, config)
    assert loro.n == 16 and loro.confusion.sum(axis=1).tolist() == [4, 5, 7]
    assert loro.meta["without_a_model"] == {"grasp1_hand": ["grasp"]}
    assert loro.confusion[0, 0] == 0
    logo = cross_validate(gestures, config, folds="gesture")
    assert logo.accuracy >= 0.75
