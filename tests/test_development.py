"""Developmental learning: demonstrations, the labelling rule, tempering, fusion, the whole run."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from beyond_self.cli import main as cli
from beyond_self.cognition.bn import learn_network, synthetic_dataset
from beyond_self.cognition.bn.model import BayesNet
from beyond_self.cognition.development.demonstrations import (
    Demonstration,
    ObservationConfig,
    RecordedEffects,
    synthesize_demonstrations,
)
from beyond_self.cognition.development.learning import (
    LearningConfig,
    LearningResults,
    fit_kappa,
    fused_posteriors,
    infer_labels,
    load_robot_data,
    network_posteriors,
    run_learning,
    tempered_posterior,
    word_evidence,
)
from beyond_self.cognition.development.report import write_outputs
from beyond_self.cognition.fusion import fuse
from beyond_self.cognition.gestures.training import TrainingConfig
from beyond_self.cognition.grammar import DEFAULT_GRAMMAR
from beyond_self.cognition.variables import ACTIONS, EFFECTS
from beyond_self.cognition.world import simulate_effects
from beyond_self.core.errors import InputError

SMALL = LearningConfig(
    n_per_action=8,
    test_per_action=15,
    sizes=(4, 8),
    training=TrainingConfig(n_states=4, n_mix=1, n_iter=4),
    seed=3,
)


@pytest.fixture(scope="module")
def model() -> BayesNet:
    return learn_network(synthetic_dataset())


@pytest.fixture(scope="module")
def small_run() -> LearningResults:
    return run_learning(SMALL)


# -- demonstrations ---------------------------------------------------------------------------


def test_demonstrations_are_seeded_and_nested() -> None:
    cfg = ObservationConfig()
    a = synthesize_demonstrations(2, 5, cfg)
    b = synthesize_demonstrations(3, 5, cfg)
    c = synthesize_demonstrations(2, 6, cfg)
    assert [d.action for d in a] == ["grasp", "tap", "touch"] * 2
    for x, y in zip(a, b[:6], strict=True):  # the first 2 per action of a larger set
        assert x.action == y.action and x.objects == y.objects and x.effects == y.effects
        assert x.words == y.words
        assert np.array_equal(x.features, y.features)
    assert not np.array_equal(a[0].features, c[0].features)


def test_noise_free_observation_sees_the_world() -> None:
    cfg = ObservationConfig(action_noise=0.0, perception_noise=0.0, p_effect_missed=0.0, p_words=0)
    rng = np.random.default_rng(0)
    for d in synthesize_demonstrations(2, 1, cfg):
        exact = simulate_effects(d.action, d.objects["Shape"], d.objects["Size"], rng, 0.0)
        assert d.effects == exact.labels() == d.true_effects
        assert d.words is None
        assert d.effect_errors == 0
        assert d.features.ndim == 2 and d.features.shape[1] == 7  # the "motion" features


def test_observation_noise_parameters_take_effect() -> None:
    cfg = ObservationConfig(perception_noise=1.5, p_effect_missed=1.0, p_words=1.0)
    demos = synthesize_demonstrations(3, 2, cfg)
    vocabulary = set(DEFAULT_GRAMMAR.vocabulary)
    for d in demos:
        assert d.effects == {}  # every effect missed
        assert set(d.true_effects) == set(EFFECTS)
        assert d.words is not None and set(d.words) <= vocabulary
    noisy = ObservationConfig(perception_noise=1.5, p_effect_missed=0.0)
    errors = sum(d.effect_errors for d in synthesize_demonstrations(10, 2, noisy))
    assert errors > 0
    with pytest.raises(InputError):
        ObservationConfig(p_words=1.5)


def test_recorded_effects_come_from_the_robots_experiments() -> None:
    data = synthetic_dataset()
    d = data.definition
    rows = {tuple(d.variables[i].values[r[i]] for i in range(8)) for r in data.data[:, :8].tolist()}
    exact = RecordedEffects(data, p_misperceived=0.0)
    flipped = RecordedEffects(data, p_misperceived=1.0)
    rng = np.random.default_rng(4)
    objects = {"Color": "blue", "Shape": "box", "Size": "big"}
    for action in ACTIONS:
        truth, seen = exact.draw(action, objects, rng)
        assert seen == truth
        key = (action, "blue", "box", "big", *(truth[e] for e in EFFECTS))
        combos = {r[:1] + r[2:] for r in rows}  # colour aside: any colour matches
        assert key[:1] + key[2:] in combos
        truth, seen = flipped.draw(action, objects, rng)
        assert all(seen[e] != truth[e] for e in EFFECTS)


# -- labelling, tempering, fusion -------------------------------------------------------------


def test_labelling_rule_threshold_and_floor() -> None:
    post = np.array(
        [
            [0.95, 0.03, 0.02],  # grasp, kept
            [0.60, 0.30, 0.10],  # grasp, dropped
            [0.10, 0.85, 0.05],  # tap, below 0.9 but the only tap: kept by the floor of 1
            [0.01, 0.01, 0.98],  # touch, kept
            [0.05, 0.05, 0.90],  # touch, kept (>= threshold)
        ]
    )
    lab = infer_labels(post, ACTIONS, threshold=0.9, min_per_action=1)
    assert lab.labels == ("grasp", "grasp", "tap", "touch", "touch")
    assert lab.kept.tolist() == [True, False, True, True, True]
    assert lab.kept_labels() == {"grasp": [0], "tap": [2], "touch": [3, 4]}
    floor2 = infer_labels(post, ACTIONS, threshold=0.9, min_per_action=2)
    assert floor2.kept.tolist() == [True, True, True, True, True]
    summary = lab.summary(["grasp", "tap", "tap", "touch", "grasp"])
    assert summary["accuracy"] == pytest.approx(3 / 5)
    assert summary["kept_accuracy"] == pytest.approx(3 / 4)
    assert summary["dropped_wrong"] == 1 and summary["dropped_right"] == 0
    with pytest.raises(InputError, match="no demonstration as tap"):
        infer_labels(post[[0, 1, 3]], ACTIONS, 0.9, 1)


def test_tempered_posterior_with_kappa_t_is_the_likelihood_ratio() -> None:
    loglik = np.array([[-310.0, -300.0, -305.0]])
    t = 50.0
    expected = np.exp(loglik - loglik.max())
    expected /= expected.sum()
    assert np.allclose(tempered_posterior(loglik / t, t), expected)
    flat = tempered_posterior(loglik / t, 0.0)
    assert np.allclose(flat, 1 / 3)


def test_fit_kappa_recovers_a_known_temperature() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 1.0, (4000, 3))
    for kappa in (0.5, 3.0):
        p = np.exp(kappa * x)
        p /= p.sum(axis=1, keepdims=True)
        y = [int(rng.choice(3, p=row)) for row in p]
        assert fit_kappa(x, y) == pytest.approx(kappa, rel=0.12)


def test_fusion_without_words_is_pcomb(model: BayesNet) -> None:
    demos = synthesize_demonstrations(2, 9, ObservationConfig(p_words=0.0))
    p_hmm = np.random.default_rng(1).dirichlet(np.ones(3), len(demos))
    ours = fused_posteriors(model, demos, p_hmm, ACTIONS, use_words=True, word_error=0.02)
    for d, p, row in zip(demos, p_hmm, ours, strict=True):
        ref = fuse(
            model, "Action", d.observed, dict(zip(ACTIONS, p, strict=True)), method="formula"
        )
        assert np.allclose(row, ref.table, atol=1e-12)


def test_heard_words_approach_hard_evidence(model: BayesNet) -> None:
    said = ("he", "is", "tapping", "the", "ball")
    demo = Demonstration(
        action="tap",
        objects={"Color": "blue", "Shape": "circle", "Size": "small"},
        effects={"ObjVel": "fast"},
        true_effects={},
        words=said,
        features=np.zeros((10, 3)),
    )
    soft = word_evidence(model, said, 0.02)
    assert soft["tapping"] == [0.02, 0.98] and soft["grasping"] == [0.98, 0.02]
    near_hard = network_posteriors(model, [demo], use_words=True, word_error=1e-12)[0]
    hard = {v.name: (v.word if v.word in said else "-") for v in model.definition.words}
    ref = model.query("Action", {**demo.observed, **hard}).table
    assert np.allclose(near_hard, ref, atol=1e-8)
    without = network_posteriors(model, [demo], use_words=False, word_error=0.02)[0]
    assert np.allclose(without, model.query("Action", demo.observed).table)


# -- the whole run ----------------------------------------------------------------------------


def test_small_run_meets_the_acceptance_criteria(small_run: LearningResults) -> None:
    main = small_run.main
    assert main.n_per_action == 8 and main.words
    acc = {s: main.accuracy(s) for s in ("hmm_inferred", "hmm_true", "network", "fused")}
    # the acceptance (>= 90% of true labels) is the main run's (`beyond learn`: 100%);
    # with 8 demonstrations per action and 45 held out, one gesture is 2 points of accuracy
    assert acc["hmm_inferred"] >= 0.85 * acc["hmm_true"]
    assert acc["fused"] >= acc["hmm_inferred"] and acc["fused"] >= acc["network"]
    assert acc["fused"] > 1 / 3 + 0.3  # far above chance
    assert main.labelling["accuracy"] >= 0.8
    for score in main.scores.values():  # every held-out demonstration once, by true action
        assert score.confusion.sum(axis=1).tolist() == [15, 15, 15]
    assert {(c.n_per_action, c.words) for c in small_run.ablation} == {
        (4, True),
        (8, True),
        (4, False),
        (8, False),
    }


def test_outputs_hold_the_numbers(small_run: LearningResults, tmp_path: Path) -> None:
    paths = write_outputs(small_run, tmp_path)
    for key in ("results", "confusions", "curves", "report"):
        assert paths[key].is_file() and paths[key].stat().st_size > 0
    assert paths["confusions"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    data = json.loads(paths["results"].read_text())
    main = data["main"]
    for source, conf in main["confusion"].items():
        c = np.array(conf)
        assert main["accuracy"][source] == pytest.approx(np.trace(c) / c.sum())
    ratio = main["accuracy"]["hmm_inferred"] / main["accuracy"]["hmm_true"]
    assert data["acceptance"]["hmm_inferred_over_true"] == pytest.approx(ratio)
    assert data["acceptance"]["fused_at_least_both"] is True
    assert len(data["ablation"]) == 4
    assert data["config"]["seed"] == 3
    text = paths["report"].read_text()
    assert "Labelling rule" in text and "confusions.png" in text
    assert f"{100 * main['accuracy']['fused']:.1f}%" in text


def test_same_seed_same_results(small_run: LearningResults) -> None:
    cfg = LearningConfig(
        n_per_action=4,
        test_per_action=15,
        sizes=(4,),
        training=SMALL.training,
        seed=3,
    )
    again = run_learning(cfg)
    first = next(c for c in small_run.ablation if c.n_per_action == 4 and c.words)
    assert again.main.to_dict() == first.to_dict()


def test_cli_writes_outputs_and_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["learn", "-o", str(tmp_path), "--json", "--demos", "3", "--test", "4"]
    args += ["--sizes", "3", "--states", "3", "--iter", "2", "--seed", "1"]
    assert cli(args) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["format"] == "beyond-self/learning-results"
    assert data["held_out"] == 12
    assert (tmp_path / "learning.md").is_file()
    assert (tmp_path / "accuracy_vs_demonstrations.png").is_file()


@pytest.mark.parametrize(
    "extra",
    [
        ["--robot-data", "/nonexistent/bag.txt"],
        ["--threshold", "1.5"],
        ["--human-data", "/nonexistent/folder"],
    ],
)
def test_cli_bad_input_exits_2(
    extra: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli(["learn", "-o", str(tmp_path), "--sizes", "3", "--demos", "3", *extra]) == 2
    err = capsys.readouterr().err
    assert "error" in err and "Traceback" not in err


def test_real_robot_data_with_recorded_effects(shared_data: Path) -> None:
    dataset = load_robot_data(shared_data / "salvi2012")
    assert dataset.rows == 1270
    cfg = LearningConfig(
        n_per_action=6,
        test_per_action=6,
        sizes=(6,),
        training=TrainingConfig(n_states=4, n_mix=1, n_iter=3),
        seed=2,
    )
    results = run_learning(cfg, robot_data=shared_data / "salvi2012")
    assert results.effects.startswith("recorded")
    # effects drawn from the real experiments: the real network labels them far above chance
    assert results.main.labelling["accuracy"] > 0.6
    assert not math.isnan(results.main.accuracy("fused"))
