"""Human demonstrations as the robot observes them: a gesture, an object, effects, maybe words.

Watching a person is harder than the robot's own experiments, and each source is imperfect in its
own way so that comparing them means something: gestures vary more than the default generator's
(`HUMAN_GESTURES`), effects are noisier and misperceived or missed, and a narrator speaks with
probability `p_words`; with the article's robot data, `RecordedEffects` draws effects from the
robot's own experiments instead. docs/science/development.md gives the figures and why. The
sources' noises are independent (an assumption, said in the report). Demonstration i of action a
depends only on (seed, a, i), so N per action are the first N of a larger set with the same seed.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from beyond_self.cognition.bn.bag import Dataset
from beyond_self.cognition.bn.synthetic import Narrator
from beyond_self.cognition.gestures.evaluation import LabelledGesture
from beyond_self.cognition.gestures.synthetic import SynthesisConfig, synthesize_gesture
from beyond_self.cognition.variables import ACTIONS, AFFORDANCE_VARIABLES, EFFECTS, OBJECT_FEATURES
from beyond_self.cognition.world import Effects, simulate_effects
from beyond_self.core.errors import InputError, unknown

FloatArray = NDArray[np.float64]

HUMAN_GESTURES = SynthesisConfig(
    speed=(0.55, 1.7),
    phase_jitter=0.35,
    amplitude=(0.4, 1.6),
    hand_noise=(0.015, 0.04),
    drift=0.05,
    glitch_rate=0.015,
)
ROBOT_EFFECT_NOISE = 0.15  # what the robot's own exploration data was generated with


@dataclass(frozen=True)
class ObservationConfig:
    """How imperfectly the robot observes a human demonstration (see the module docstring)."""

    action_noise: float = 0.3
    perception_noise: float = 0.45
    p_effect_missed: float = 0.25
    p_misperceived: float = 0.1  # RecordedEffects only
    p_words: float = 0.5
    gestures: SynthesisConfig = HUMAN_GESTURES

    def __post_init__(self) -> None:
        for name in ("action_noise", "perception_noise"):
            sigma = getattr(self, name)
            if not (math.isfinite(sigma) and sigma >= 0):
                raise InputError(f"{name} {sigma}; valid: a finite number >= 0")
        for name in ("p_effect_missed", "p_misperceived", "p_words"):
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise InputError(f"{name} {p}; valid: a probability in [0, 1]")

    def to_dict(self) -> dict[str, object]:
        g = self.gestures
        return {
            "action_noise": self.action_noise,
            "perception_noise": self.perception_noise,
            "robot_effect_noise": ROBOT_EFFECT_NOISE,
            "p_effect_missed": self.p_effect_missed,
            "p_misperceived": self.p_misperceived,
            "p_words": self.p_words,
            "gestures": {k: getattr(g, k) for k in g.__dataclass_fields__},
        }


@dataclass(frozen=True, eq=False)
class Demonstration:
    """One observed human demonstration. `action` is the truth: only evaluation may read it."""

    action: str
    objects: Mapping[str, str]  # Color, Shape, Size as the robot sees them
    effects: Mapping[str, str]  # the effects the robot perceived (missed ones left out)
    true_effects: Mapping[str, str]  # what happened (for the report, never for inference)
    words: tuple[str, ...] | None  # the sentence heard; None when nobody spoke
    features: FloatArray = field(repr=False)  # gesture features (T, 3)
    source: str = ""

    @property
    def observed(self) -> dict[str, str]:
        """Hard evidence for the network: object features and perceived effects."""
        return {**self.objects, **self.effects}

    @property
    def effect_errors(self) -> int:
        """Perceived effects whose label differs from what happened."""
        return sum(self.effects[e] != self.true_effects[e] for e in self.effects)


def _pick(rng: np.random.Generator, values: Sequence[str]) -> str:
    return values[int(rng.integers(len(values)))]


class EffectModel(Protocol):
    """What happens when a person does `action` on `objects`, and what the robot perceives."""

    @property
    def name(self) -> str: ...

    def draw(
        self, action: str, objects: Mapping[str, str], rng: np.random.Generator
    ) -> tuple[dict[str, str], dict[str, str]]:
        """(what happened, what the robot perceived), both as effect labels."""
        ...


@dataclass(frozen=True)
class SimulatedEffects:
    """The simulated world (`cognition.world`) with the person's and the perception's noise."""

    action_noise: float
    perception_noise: float
    name: str = "simulated (cognition.world)"

    def draw(
        self, action: str, objects: Mapping[str, str], rng: np.random.Generator
    ) -> tuple[dict[str, str], dict[str, str]]:
        happened = simulate_effects(
            action, objects["Shape"], objects["Size"], rng, noise=self.action_noise
        )
        error = np.exp(rng.normal(0.0, self.perception_noise, 4))
        measured = Effects(
            object_speed=happened.object_speed * float(error[0]),
            hand_speed=happened.hand_speed * float(error[1]),
            relative_speed=happened.relative_speed * float(error[2]),
            contact_s=happened.contact_s * float(error[3]),
        )
        return happened.labels(), measured.labels()


@dataclass(frozen=True, eq=False)
class RecordedEffects:
    """Effects of the robot's own experiments (a bag table), misperceived now and then."""

    dataset: Dataset
    p_misperceived: float
    name: str = "recorded (the robot's own experiments)"

    def __post_init__(self) -> None:
        names = self.dataset.definition.names
        missing = [v for v in ("Action", *OBJECT_FEATURES, *EFFECTS) if v not in names]
        if missing:
            raise InputError(
                f"robot data lacks {', '.join(missing)}; effects are drawn from its experiments"
            )

    def _column(self, name: str) -> NDArray[np.int64]:
        return np.asarray(self.dataset.data[:, self.dataset.definition.index(name)])

    def draw(
        self, action: str, objects: Mapping[str, str], rng: np.random.Generator
    ) -> tuple[dict[str, str], dict[str, str]]:
        d = self.dataset.definition
        rows = self._column("Action") == d["Action"].index(action)
        if not rows.any():
            raise InputError(f"the robot never did {action} in its data; cannot simulate it")
        for relax in (("Shape", "Size"), ("Shape",)):
            match = rows.copy()
            for name in relax:
                match &= self._column(name) == d[name].index(objects[name])
            if match.any():
                rows = match
                break
        row = self.dataset.data[int(rng.choice(np.flatnonzero(rows)))]
        truth = {e: d[e].values[int(row[d.index(e)])] for e in EFFECTS}
        perceived = {}
        for e in EFFECTS:
            values = d[e].values
            value = truth[e]
            if rng.random() < self.p_misperceived:
                others = [v for v in values if v != value]
                value = others[int(rng.integers(len(others)))]
            perceived[e] = value
        return truth, perceived


def effect_model(config: ObservationConfig, robot_data: Dataset | None = None) -> EffectModel:
    """The simulator for synthetic robot data (None); the robot's own experiments otherwise."""
    if robot_data is None:
        return SimulatedEffects(config.action_noise, config.perception_noise)
    return RecordedEffects(robot_data, config.p_misperceived)


def _demonstration(
    action: str,
    features: FloatArray,
    source: str,
    rng: np.random.Generator,
    config: ObservationConfig,
    narrator: Narrator,
    effects_model: EffectModel,
) -> Demonstration:
    """A demonstration of `action` with these gesture features, in a simulated scene: the
    object, the effects the robot perceives (some missed) and, sometimes, the words heard."""
    objects = {name: _pick(rng, AFFORDANCE_VARIABLES[name]) for name in OBJECT_FEATURES}
    truth, measured = effects_model.draw(action, objects, rng)
    seen = rng.random(len(EFFECTS)) >= config.p_effect_missed
    words: tuple[str, ...] | None = None
    if rng.random() < config.p_words:
        values = {"Action": action, **objects, **truth}
        words = tuple(narrator.describe(values, rng))
    return Demonstration(
        action=action,
        objects=objects,
        effects={e: measured[e] for e, s in zip(EFFECTS, seen, strict=True) if s},
        true_effects=truth,
        words=words,
        features=features,
        source=source,
    )


def _rng(seed: int, action: str, i: int) -> np.random.Generator:
    return np.random.default_rng([seed, ACTIONS.index(action), i])


def synthesize_demonstrations(
    n_per_action: int,
    seed: int,
    config: ObservationConfig | None = None,
    actions: Sequence[str] = ACTIONS,
    effects: EffectModel | None = None,
) -> list[Demonstration]:
    """n_per_action demonstrations of each action, actions interleaved (grasp, tap, touch, ...).

    `effects` defaults to the simulated world with the config's noise.
    """
    if n_per_action < 1:
        raise InputError(f"demonstrations per action {n_per_action}; valid: at least 1")
    cfg = config or ObservationConfig()
    world = effects or effect_model(cfg)
    narrator = Narrator()
    for a in actions:
        if a not in ACTIONS:
            raise unknown("action", a, ACTIONS)
    out: list[Demonstration] = []
    for i in range(n_per_action):
        for a in actions:
            rng = _rng(seed, a, i)
            gesture_seed = int(rng.integers(2**31 - 1))
            features = synthesize_gesture(a, gesture_seed, cfg.gestures).gesture_features()
            source = f"synthetic seed {seed} {a} #{i}"
            out.append(_demonstration(a, features, source, rng, cfg, narrator, world))
    return out


def demonstrations_from_gestures(
    gestures: Sequence[LabelledGesture],
    seed: int,
    config: ObservationConfig | None = None,
    effects: EffectModel | None = None,
) -> list[Demonstration]:
    """Recorded gestures (e.g. the article's human_data) with a simulated scene for each.

    The recordings hold only the hand; the object, its effects and the words are simulated for
    the recording's labelled action, exactly as for synthetic demonstrations.
    """
    if not gestures:
        raise InputError("no recorded gestures to turn into demonstrations")
    cfg = config or ObservationConfig()
    world = effects or effect_model(cfg)
    narrator = Narrator()
    out = []
    counts: dict[str, int] = {}
    for g in gestures:
        if g.action not in ACTIONS:
            raise unknown("action of a recorded gesture", g.action, ACTIONS)
        i = counts.get(g.action, 0)
        counts[g.action] = i + 1
        features = np.asarray(g.features, dtype=np.float64)
        rng = _rng(seed, g.action, i)
        out.append(_demonstration(g.action, features, g.source, rng, cfg, narrator, world))
    return out


def split_demonstrations(
    demos: Sequence[Demonstration], test_fraction: float, seed: int
) -> tuple[list[Demonstration], list[Demonstration]]:
    """A stratified (per action) random split into (watched, held-out) demonstrations."""
    if not 0.0 < test_fraction < 1.0:
        raise InputError(f"test fraction {test_fraction}; valid: strictly between 0 and 1")
    rng = np.random.default_rng([seed, 7])
    train: list[Demonstration] = []
    test: list[Demonstration] = []
    for a in ACTIONS:
        own = [d for d in demos if d.action == a]
        if not own:
            continue
        if len(own) < 2:
            raise InputError(f"only {len(own)} demonstration of {a}; a split needs at least 2")
        order = rng.permutation(len(own))
        n_test = min(max(1, round(test_fraction * len(own))), len(own) - 1)
        test += [own[i] for i in sorted(order[:n_test])]
        train += [own[i] for i in sorted(order[n_test:])]
    return train, test
