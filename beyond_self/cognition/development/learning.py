"""From the robot's own experience to recognising a person: label, train, calibrate, evaluate.

The steps: the network from the robot's exploration; P_BN(A | object, perceived effects, words)
for each watched demonstration; one gesture HMM per action trained on the inferred actions;
evaluation on held-out demonstrations. A demonstration is kept when its posterior reaches
`threshold` and labelled with its most probable action (a wrong label does double damage; a
dropped one only costs data); heard words are soft evidence through a hearing channel
(`word_error`); the gesture evidence is tempered by κ, calibrated by cross-fitting on the robot's
own watched demonstrations, because untempered HMM posteriors are 0 or 1 even when wrong.
docs/science/development.md says why each choice.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from beyond_self.cognition.bn.bag import Dataset
from beyond_self.cognition.bn.model import BayesNet, learn_network
from beyond_self.cognition.development.demonstrations import (
    Demonstration,
    EffectModel,
    ObservationConfig,
    demonstrations_from_gestures,
    effect_model,
    split_demonstrations,
    synthesize_demonstrations,
)
from beyond_self.cognition.fusion import ACTION, action_vector
from beyond_self.cognition.gestures.hmm import GestureModels
from beyond_self.cognition.gestures.streaming import CompiledModels, recognize_sequence
from beyond_self.cognition.gestures.training import TrainingConfig, train_models
from beyond_self.core.errors import InputError

FloatArray = NDArray[np.float64]
SYNTHETIC = "synthetic"
DEFAULT_TRAINING = TrainingConfig(n_states=6, n_mix=1, n_iter=10)
SOURCES: tuple[str, ...] = ("hmm_inferred", "hmm_true", "network", "fused", "fused_untempered")
SOURCE_NAMES: dict[str, str] = {
    "hmm_inferred": "(a) HMMs trained on inferred labels",
    "hmm_true": "(b) HMMs trained on true labels",
    "network": "(c) network alone, P_BN(A | object, effects, words)",
    "fused": "(d) fused, P_comb with tempered P_HMM of (a)",
    "fused_untempered": "(d') fused with the untempered P_HMM of (a)",
}
Progress = Callable[[str, int], None]  # (what is being done, units of work finished)


@dataclass(frozen=True)
class LearningConfig:
    """One learning experiment: sizes, thresholds, HMM training, observation noise, seed."""

    n_per_action: int = 20  # demonstrations watched per action in the main run
    test_per_action: int = 60  # held-out demonstrations per action (synthetic human data)
    sizes: tuple[int, ...] = (5, 10, 20, 50)  # ablation: demonstrations watched per action
    threshold: float = 0.9
    min_per_action: int = 2
    word_error: float = 0.02
    calibrate: bool = True
    training: TrainingConfig = DEFAULT_TRAINING
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    test_fraction: float = 1.0 / 3.0  # held-out share of recorded human data
    seed: int = 0

    def __post_init__(self) -> None:
        if self.n_per_action < 1 or self.test_per_action < 1:
            raise InputError("demonstrations per action must be at least 1 (watched and held out)")
        if any(n < 1 for n in self.sizes):
            raise InputError(f"ablation sizes {self.sizes}; valid: numbers >= 1")
        if not 0.0 <= self.threshold <= 1.0:
            raise InputError(f"threshold {self.threshold}; valid: a probability in [0, 1]")
        if self.min_per_action < 1:
            raise InputError(f"min_per_action {self.min_per_action}; valid: at least 1")
        if not 0.0 < self.word_error < 0.5:
            raise InputError(f"word error {self.word_error}; valid: strictly between 0 and 0.5")

    @property
    def all_sizes(self) -> tuple[int, ...]:
        return tuple(sorted({*self.sizes, self.n_per_action}))

    def to_dict(self) -> dict[str, Any]:
        t = self.training
        return {
            "n_per_action": self.n_per_action,
            "test_per_action": self.test_per_action,
            "sizes": list(self.sizes),
            "threshold": self.threshold,
            "min_per_action": self.min_per_action,
            "word_error": self.word_error,
            "calibrate": self.calibrate,
            "training": {k: getattr(t, k) for k in t.__dataclass_fields__},
            "observation": self.observation.to_dict(),
            "test_fraction": self.test_fraction,
            "seed": self.seed,
        }


# ---------------------------------------------------------------------------------------------
# Step 1: the self phase


def load_robot_data(spec: str | Path) -> Dataset:
    """The robot's exploration data: `synthetic`, a salvi2012-style folder, or a bag file.

    A folder must hold networkDefinition.txt and sent-1-5_lab_aff_bag.txt (or exactly one
    *_bag.txt); a bag file needs networkDefinition.txt beside it.
    """
    from beyond_self.cognition.bn import load_bag, load_definition, synthetic_dataset

    if str(spec) == SYNTHETIC:
        return synthetic_dataset()
    path = Path(spec)
    if not path.exists():
        raise InputError(
            f"robot data {path} does not exist; valid: 'synthetic', a folder with "
            "networkDefinition.txt and a *_bag.txt table, or a bag file"
        )
    if path.is_dir():
        bag = path / "sent-1-5_lab_aff_bag.txt"
        if not bag.is_file():
            bags = sorted(path.glob("*_bag.txt"))
            if len(bags) != 1:
                raise InputError(
                    f"{path} holds {len(bags)} *_bag.txt tables; valid: exactly one, or "
                    "sent-1-5_lab_aff_bag.txt"
                )
            bag = bags[0]
    else:
        bag = path
    definition = bag.parent / "networkDefinition.txt"
    if not definition.is_file():
        raise InputError(f"no networkDefinition.txt beside {bag}; the bag table needs it")
    return load_bag(bag, load_definition(definition))


def self_phase(dataset: Dataset) -> BayesNet:
    """The network the robot learns from its own exploration (K2/BIC, BDeu/ML, as the article)."""
    model = learn_network(dataset)
    if ACTION not in model.variables:
        raise InputError(f"the robot data has no {ACTION} node; the network needs one")
    return model


# ---------------------------------------------------------------------------------------------
# Step 2: the observation phase


def word_evidence(
    model: BayesNet, words: Sequence[str] | None, error: float
) -> dict[str, list[float]]:
    """Soft evidence on every word node for a heard sentence (none when nobody spoke)."""
    if words is None:
        return {}
    heard = set(words)
    return {
        v.name: ([error, 1.0 - error] if v.word in heard else [1.0 - error, error])
        for v in model.definition.words
    }


def network_posteriors(
    model: BayesNet, demos: Sequence[Demonstration], *, use_words: bool, word_error: float
) -> FloatArray:
    """P_BN(A | object, perceived effects[, words]) per demonstration, rows in Action order."""
    out = np.empty((len(demos), len(model.values[ACTION])))
    for i, d in enumerate(demos):
        soft = word_evidence(model, d.words if use_words else None, word_error)
        out[i] = model.query(ACTION, d.observed, soft).table
    return out


@dataclass(frozen=True, eq=False)
class Labelling:
    """Inferred labels (argmax of P_BN), their confidence, and which demonstrations are kept."""

    actions: tuple[str, ...]
    labels: tuple[str, ...]
    confidence: FloatArray
    kept: NDArray[np.bool_]
    threshold: float

    def kept_labels(self) -> dict[str, list[int]]:
        """Indices of the kept demonstrations, by inferred action."""
        return {
            a: [int(i) for i in np.flatnonzero(self.kept) if self.labels[i] == a]
            for a in self.actions
        }

    def summary(self, truth: Sequence[str]) -> dict[str, Any]:
        right = np.array([lab == t for lab, t in zip(self.labels, truth, strict=True)])
        n_kept = int(self.kept.sum())
        return {
            "n": len(self.labels),
            "accuracy": float(right.mean()),
            "threshold": self.threshold,
            "kept": n_kept,
            "kept_accuracy": float(right[self.kept].mean()) if n_kept else math.nan,
            "dropped_wrong": int((~right & ~self.kept).sum()),
            "dropped_right": int((right & ~self.kept).sum()),
            "kept_per_action": {a: len(ix) for a, ix in self.kept_labels().items()},
        }


def infer_labels(
    posteriors: FloatArray, actions: Sequence[str], threshold: float, min_per_action: int
) -> Labelling:
    """The labelling rule of the module docstring: argmax, kept at confidence >= threshold."""
    actions = tuple(actions)
    best = np.argmax(posteriors, axis=1)
    conf = posteriors[np.arange(len(best)), best]
    kept = conf >= threshold
    for k, a in enumerate(actions):
        mine = np.flatnonzero(best == k)
        if len(mine) == 0:
            raise InputError(
                f"the network labelled no demonstration as {a}; give more demonstrations "
                "(or ones with clearer effects) so that every action can be learned"
            )
        missing = min(min_per_action, len(mine)) - int(kept[mine].sum())
        if missing > 0:
            dropped = mine[~kept[mine]]
            kept[dropped[np.argsort(-conf[dropped], kind="stable")[:missing]]] = True
    return Labelling(actions, tuple(actions[k] for k in best), conf, kept, threshold)


# ---------------------------------------------------------------------------------------------
# Step 3: gesture models on the inferred labels, and the tempering of their evidence


def train_on_labels(
    demos: Sequence[Demonstration],
    labels: Sequence[str],
    actions: Sequence[str],
    training: TrainingConfig,
    on_model: Callable[[str], None] | None = None,
) -> GestureModels:
    """One HMM per action from the gestures of the demonstrations given that label."""
    data = {
        a: [d.features for d, lab in zip(demos, labels, strict=True) if lab == a] for a in actions
    }
    empty = [a for a, xs in data.items() if not xs]
    if empty:
        raise InputError(f"no demonstrations labelled {', '.join(empty)}; cannot train its HMM")
    return train_models(data, training, actions=list(actions), on_model=on_model)


def per_frame_loglik(models: GestureModels, demos: Sequence[Demonstration]) -> FloatArray:
    """(1/T) log L(G | A) of each demonstration's whole gesture under each model."""
    compiled = CompiledModels(models)
    out = np.empty((len(demos), len(models.actions)))
    for i, d in enumerate(demos):
        out[i] = recognize_sequence(compiled, d.features).normalized[-1]
    return np.nan_to_num(out, neginf=-1e6)


def tempered_posterior(per_frame: FloatArray, kappa: float) -> FloatArray:
    """P_HMM(A | G) ∝ exp(κ (1/T) log L), rows normalised; κ = T gives the untempered one."""
    z = kappa * per_frame
    z = z - z.max(axis=-1, keepdims=True)
    p = np.exp(z)
    return np.asarray(p / p.sum(axis=-1, keepdims=True))


def fit_kappa(per_frame: FloatArray, labels: Sequence[int]) -> float:
    """κ maximising Σ log P_HMM(label | G) (convex in κ; bounded search on [0.01, 1000])."""
    from scipy.optimize import minimize_scalar

    y = np.asarray(labels)
    rows = np.arange(len(y))

    def nll(log_k: float) -> float:
        z = math.exp(log_k) * per_frame
        m = z.max(axis=1)
        lse = m + np.log(np.exp(z - m[:, None]).sum(axis=1))
        return float((lse - z[rows, y]).sum())

    res = minimize_scalar(nll, bounds=(math.log(0.01), math.log(1000.0)), method="bounded")
    return float(math.exp(res.x))


def calibrate_kappa(
    demos: Sequence[Demonstration],
    labelling: Labelling,
    training: TrainingConfig,
    on_model: Callable[[str], None] | None = None,
) -> float | None:
    """κ from 2-fold cross-fitting on the kept demonstrations and their inferred labels.

    None when some inferred action has fewer than 2 kept demonstrations (a fold would lack it).
    """
    actions = labelling.actions
    groups = labelling.kept_labels()
    if any(len(ix) < 2 for ix in groups.values()):
        return None
    folds: list[list[int]] = [[], []]
    for ix in groups.values():
        for j, i in enumerate(ix):
            folds[j % 2].append(int(i))
    scores: list[FloatArray] = []
    targets: list[int] = []
    for k in (0, 1):
        fit, score = folds[k], folds[1 - k]
        models = train_on_labels(
            [demos[i] for i in fit], [labelling.labels[i] for i in fit], actions, training, on_model
        )
        scores.append(per_frame_loglik(models, [demos[i] for i in score]))
        targets += [actions.index(labelling.labels[i]) for i in score]
    return fit_kappa(np.concatenate(scores), targets)


# ---------------------------------------------------------------------------------------------
# Step 4: evaluation


@dataclass(frozen=True, eq=False)
class Score:
    """Accuracy and confusion (rows: true action, columns: predicted) of one source."""

    actions: tuple[str, ...]
    confusion: NDArray[np.int64]

    @property
    def accuracy(self) -> float:
        return float(np.trace(self.confusion) / max(int(self.confusion.sum()), 1))

    @classmethod
    def of(cls, actions: Sequence[str], truth: Sequence[str], posteriors: FloatArray) -> Score:
        actions = tuple(actions)
        conf = np.zeros((len(actions), len(actions)), dtype=np.int64)
        for t, p in zip(truth, posteriors, strict=True):
            conf[actions.index(t), int(np.argmax(p))] += 1
        return cls(actions, conf)

    def to_dict(self) -> dict[str, Any]:
        return {"accuracy": self.accuracy, "confusion": self.confusion.tolist()}


def fused_posteriors(
    model: BayesNet,
    demos: Sequence[Demonstration],
    p_hmm: FloatArray,
    actions: Sequence[str],
    *,
    use_words: bool,
    word_error: float,
) -> FloatArray:
    """P_comb(A | object, effects, words, G): P_HMM entered as soft evidence on Action."""
    out = np.empty((len(demos), len(model.values[ACTION])))
    for i, d in enumerate(demos):
        soft: dict[str, Sequence[float]] = dict(
            word_evidence(model, d.words if use_words else None, word_error)
        )
        soft[ACTION] = action_vector(model, dict(zip(actions, p_hmm[i], strict=True))).tolist()
        out[i] = model.query(ACTION, d.observed, soft).table
    return out


@dataclass(frozen=True, eq=False)
class Condition:
    """One learning run: N demonstrations per action watched, with or without words."""

    n_per_action: int
    words: bool
    labelling: dict[str, Any]
    kappa: float | None
    scores: dict[str, Score]
    label_accuracy_by_words: dict[str, float]

    def accuracy(self, source: str) -> float:
        return self.scores[source].accuracy

    def to_dict(self) -> dict[str, Any]:
        return {
            "n_per_action": self.n_per_action,
            "words": self.words,
            "labels": {**self.labelling, "accuracy_by_words_heard": self.label_accuracy_by_words},
            "kappa": self.kappa,
            "accuracy": {s: sc.accuracy for s, sc in self.scores.items()},
            "confusion": {s: sc.confusion.tolist() for s, sc in self.scores.items()},
        }


@dataclass(frozen=True, eq=False)
class LearningResults:
    config: LearningConfig
    robot_data: str
    human_data: str
    network: dict[str, Any]
    actions: tuple[str, ...]
    n_watched: dict[int, int]  # size -> demonstrations actually watched
    n_test: int
    main: Condition
    ablation: tuple[Condition, ...]
    seconds: float
    observed_noise: dict[str, float]
    effects: str = ""

    def acceptance(self) -> dict[str, Any]:
        acc = {s: self.main.accuracy(s) for s in SOURCES}
        ratio = acc["hmm_inferred"] / acc["hmm_true"] if acc["hmm_true"] > 0 else math.nan
        return {
            "hmm_inferred_over_true": ratio,
            "inferred_reaches_90_percent": bool(ratio >= 0.9),
            "fused_at_least_hmm": bool(acc["fused"] >= acc["hmm_inferred"]),
            "fused_at_least_network": bool(acc["fused"] >= acc["network"]),
            "fused_at_least_both": bool(
                acc["fused"] >= acc["hmm_inferred"] and acc["fused"] >= acc["network"]
            ),
        }

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": "beyond-self/learning-results",
            "version": 1,
            "robot_data": self.robot_data,
            "human_data": self.human_data,
            "config": self.config.to_dict(),
            "network": self.network,
            "actions": list(self.actions),
            "demonstrations_watched": {str(k): v for k, v in self.n_watched.items()},
            "held_out": self.n_test,
            "effects": self.effects,
            "observed_noise": self.observed_noise,
            "main": self.main.to_dict(),
            "acceptance": self.acceptance(),
            "ablation": [c.to_dict() for c in self.ablation],
            "seconds": self.seconds,
        }


def _prefixed(
    tick: Callable[[str, int], None], prefix: str, suffix: str = ""
) -> Callable[[str], None]:
    """A one-argument progress hook that reports `prefix what suffix` and one unit of work."""

    def hook(what: str) -> None:
        tick(" ".join(p for p in (prefix, what, suffix) if p), 1)

    return hook


def _first_per_action(demos: Sequence[Demonstration], n: int) -> list[Demonstration]:
    seen: dict[str, int] = {}
    out = []
    for d in demos:
        if seen.get(d.action, 0) < n:
            out.append(d)
            seen[d.action] = seen.get(d.action, 0) + 1
    return out


def plan_units(config: LearningConfig, n_sizes: int | None = None) -> int:
    """Units of work `run_learning` reports (one per HMM trained, per gesture made, per test)."""
    sizes = n_sizes if n_sizes is not None else len(config.all_sizes)
    models = 3 * (1 + 2 * (1 + (2 if config.calibrate else 0)))  # true; (inferred + folds) x 2
    synth = 3 * (max(config.all_sizes) + config.test_per_action)
    return synth + sizes * (models + 2)


def run_learning(
    config: LearningConfig | None = None,
    robot_data: str | Path = SYNTHETIC,
    human_data: str | Path = SYNTHETIC,
    progress: Progress | None = None,
) -> LearningResults:
    """The whole experiment: self phase, observation, training, evaluation and ablations."""
    cfg = config or LearningConfig()
    start = time.perf_counter()

    def tick(what: str, units: int = 1) -> None:
        if progress is not None:
            progress(what, units)

    tick("self phase: learning the network from the robot's exploration", 0)
    dataset = load_robot_data(robot_data)
    model = self_phase(dataset)
    actions = model.values[ACTION]

    world = effect_model(cfg.observation, None if str(robot_data) == SYNTHETIC else dataset)
    watched, test = _human_demonstrations(cfg, human_data, world, tick)
    truth_test = [d.action for d in test]
    per_action = {a: sum(d.action == a for d in watched) for a in actions}
    available = min(per_action.values())
    main_n = min(cfg.n_per_action, available)
    sizes = sorted({n for n in cfg.all_sizes if n <= available} | {main_n})

    conditions: dict[tuple[int, bool], Condition] = {}
    n_watched: dict[int, int] = {}
    for n in sizes:
        subset = _first_per_action(watched, n)
        n_watched[n] = len(subset)
        truth = [d.action for d in subset]
        true_models = train_on_labels(
            subset,
            truth,
            actions,
            cfg.training,
            _prefixed(tick, f"N={n}: HMM", "true labels"),
        )
        ll_true = per_frame_loglik(true_models, test)
        for use_words in (True, False):
            tag = f"N={n} {'with' if use_words else 'without'} words"
            conditions[n, use_words] = _condition(
                model,
                subset,
                test,
                truth_test,
                ll_true,
                cfg,
                n,
                use_words,
                actions,
                _prefixed(tick, f"{tag}:"),
            )
            tick(f"{tag}: evaluated")
    main = conditions[main_n, True]
    ablation = tuple(conditions[k] for k in sorted(conditions, key=lambda k: (not k[1], k[0])))
    network = {
        "source": dataset.source,
        "rows": dataset.rows,
        "arcs": [list(a) for a in model.arcs if not model.definition[a[1]].is_word],
        "word_arcs": sum(1 for a in model.arcs if model.definition[a[1]].is_word),
    }
    all_demos = [*watched, *test]
    observed_effects = sum(len(d.effects) for d in all_demos)
    noise = {
        "effects_perceived_fraction": observed_effects / (4 * len(all_demos)),
        "perceived_effects_wrong_fraction": (
            sum(d.effect_errors for d in all_demos) / max(observed_effects, 1)
        ),
        "words_heard_fraction": sum(d.words is not None for d in all_demos) / len(all_demos),
    }
    return LearningResults(
        config=cfg,
        robot_data=str(robot_data),
        human_data=str(human_data),
        network=network,
        actions=tuple(actions),
        n_watched=n_watched,
        n_test=len(test),
        main=main,
        ablation=ablation,
        seconds=time.perf_counter() - start,
        observed_noise=noise,
        effects=world.name,
    )


def _human_demonstrations(
    cfg: LearningConfig,
    human_data: str | Path,
    world: EffectModel,
    tick: Callable[[str, int], None],
) -> tuple[list[Demonstration], list[Demonstration]]:
    if str(human_data) == SYNTHETIC:
        n_watch = max(cfg.all_sizes)
        tick(f"synthesising {3 * n_watch} watched demonstrations", 0)
        watched = synthesize_demonstrations(n_watch, cfg.seed, cfg.observation, effects=world)
        tick("watched demonstrations made", len(watched))
        test = synthesize_demonstrations(
            cfg.test_per_action, cfg.seed + 1, cfg.observation, effects=world
        )
        tick("held-out demonstrations made", len(test))
        return watched, test
    from beyond_self.cognition.gestures.datasets import load_gestures

    tick(f"reading recorded gestures from {human_data}", 0)
    gestures = load_gestures(Path(human_data))
    demos = demonstrations_from_gestures(gestures, cfg.seed, cfg.observation, world)
    watched, test = split_demonstrations(demos, cfg.test_fraction, cfg.seed)
    tick("recorded demonstrations read", 3 * (max(cfg.all_sizes) + cfg.test_per_action))
    return watched, test


def _condition(
    model: BayesNet,
    subset: Sequence[Demonstration],
    test: Sequence[Demonstration],
    truth_test: Sequence[str],
    ll_true: FloatArray,
    cfg: LearningConfig,
    n: int,
    use_words: bool,
    actions: Sequence[str],
    tick: Callable[[str], None],
) -> Condition:
    truth = [d.action for d in subset]
    post = network_posteriors(model, subset, use_words=use_words, word_error=cfg.word_error)
    labelling = infer_labels(post, actions, cfg.threshold, cfg.min_per_action)
    kept = [int(i) for i in np.flatnonzero(labelling.kept)]
    kept_demos = [subset[i] for i in kept]
    kept_labels = [labelling.labels[i] for i in kept]
    inferred = train_on_labels(
        kept_demos, kept_labels, actions, cfg.training, lambda a: tick(f"HMM {a}, inferred labels")
    )
    kappa = (
        calibrate_kappa(subset, labelling, cfg.training, lambda a: tick(f"calibrating, HMM {a}"))
        if cfg.calibrate
        else None
    )
    ll_inf = per_frame_loglik(inferred, test)
    lengths = np.array([len(d.features) for d in test], dtype=np.float64)[:, None]
    p_hmm = tempered_posterior(ll_inf, kappa if kappa is not None else 1.0)
    p_raw = tempered_posterior(ll_inf * lengths, 1.0)  # the plain likelihood ratio
    bn_test = network_posteriors(model, test, use_words=use_words, word_error=cfg.word_error)
    posteriors = {
        "hmm_inferred": p_raw,
        "hmm_true": tempered_posterior(ll_true * lengths, 1.0),
        "network": bn_test,
        "fused": fused_posteriors(
            model, test, p_hmm, actions, use_words=use_words, word_error=cfg.word_error
        ),
        "fused_untempered": fused_posteriors(
            model, test, p_raw, actions, use_words=use_words, word_error=cfg.word_error
        ),
    }
    scores = {s: Score.of(actions, truth_test, posteriors[s]) for s in SOURCES}
    right = np.array([lab == t for lab, t in zip(labelling.labels, truth, strict=True)])
    heard = np.array([d.words is not None for d in subset])
    by_words = {
        "heard": float(right[heard].mean()) if heard.any() else math.nan,
        "not_heard": float(right[~heard].mean()) if (~heard).any() else math.nan,
    }
    return Condition(
        n_per_action=n,
        words=use_words,
        labelling=labelling.summary(truth),
        kappa=kappa,
        scores=scores,
        label_accuracy_by_words=by_words,
    )


def with_training(config: LearningConfig, **changes: Any) -> LearningConfig:
    """A copy of `config` whose HMM training config has these fields changed."""
    return replace(config, training=replace(config.training, **changes))


__all__ = [
    "DEFAULT_TRAINING",
    "SOURCES",
    "SOURCE_NAMES",
    "SYNTHETIC",
    "Condition",
    "Labelling",
    "LearningConfig",
    "LearningResults",
    "Score",
    "calibrate_kappa",
    "fit_kappa",
    "fused_posteriors",
    "infer_labels",
    "load_robot_data",
    "network_posteriors",
    "per_frame_loglik",
    "plan_units",
    "run_learning",
    "self_phase",
    "tempered_posterior",
    "train_on_labels",
    "word_evidence",
]
