"""How well gesture models recognise labelled gestures: accuracy, confusion, early recognition.

Early recognition is the point of streaming: the accuracy when only the first 10%, 20%, ..., 100%
of each gesture has been seen (the decision is the most probable action after the last frame
seen). One forward pass per gesture gives every prefix at once.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from beyond_self.cognition import plotting
from beyond_self.cognition.gestures.features import MOTION, POSITION
from beyond_self.cognition.gestures.hmm import GestureHMM, GestureModels
from beyond_self.cognition.gestures.streaming import (
    CompiledModels,
    SequenceResult,
    recognize_sequence,
)
from beyond_self.cognition.gestures.training import TrainingConfig, train_hmm
from beyond_self.cognition.variables import ACTIONS
from beyond_self.core.errors import InputError

FloatArray = NDArray[np.float64]
FRACTIONS: tuple[float, ...] = tuple(round(0.1 * i, 1) for i in range(1, 11))


@dataclass(frozen=True, eq=False)
class LabelledGesture:
    """One gesture's features (T, D) and its true action; `source` says where it came from.

    `positions`: the same frames in the "position" space (the article's models read those);
    `recording`: the recording it was cut from, so a cross-validation can leave out whole
    recordings (empty: the gesture is its own recording).
    """

    action: str
    features: FloatArray
    source: str = ""
    positions: FloatArray | None = None
    recording: str = ""

    def in_space(self, space: str) -> FloatArray:
        """The gesture's frames in feature space `space` (the models' `features`)."""
        if space == MOTION:
            return self.features
        if space == POSITION and self.positions is not None:
            return self.positions
        raise InputError(
            f"gesture {self.source or self.action} has no {space!r} features; valid: "
            + ", ".join([MOTION] + ([POSITION] if self.positions is not None else []))
        )


@dataclass(frozen=True)
class Prediction:
    source: str
    action: str
    predicted: str
    posterior: tuple[float, ...]
    early: tuple[str, ...]  # predicted action at each fraction
    recording: str = ""


@dataclass(frozen=True)
class RecordingScore:
    """How one recording's gestures were recognised."""

    recording: str
    action: str  # the true action of its gestures (the first one's, if they differ)
    n: int
    correct: int
    predicted: dict[str, int]  # action -> how many gestures were called it


@dataclass(frozen=True, eq=False)
class EvaluationReport:
    """Accuracy, confusion matrix (rows: true action, columns: predicted) and the early curve."""

    actions: tuple[str, ...]
    confusion: NDArray[np.int64]
    fractions: tuple[float, ...]
    early_accuracy: tuple[float, ...]
    predictions: tuple[Prediction, ...]
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(self.confusion.sum())

    @property
    def accuracy(self) -> float:
        return float(np.trace(self.confusion) / max(self.n, 1))

    def accuracy_at(self, fraction: float) -> float:
        """Accuracy after seeing this fraction of each gesture (one of `fractions`)."""
        for f, acc in zip(self.fractions, self.early_accuracy, strict=True):
            if math.isclose(f, fraction):
                return acc
        raise InputError(
            f"no early accuracy at {fraction}; valid: {', '.join(map(str, self.fractions))}"
        )

    def per_recording(self) -> list[RecordingScore]:
        """One row per recording, in the order recordings first appear."""
        rows: dict[str, RecordingScore] = {}
        for p in self.predictions:
            key = p.recording or p.source
            row = rows.get(key) or RecordingScore(key, p.action, 0, 0, {})
            predicted = dict(row.predicted)
            predicted[p.predicted] = predicted.get(p.predicted, 0) + 1
            rows[key] = RecordingScore(
                key, row.action, row.n + 1, row.correct + (p.predicted == p.action), predicted
            )
        return list(rows.values())

    def to_dict(self) -> dict[str, Any]:
        return {
            "actions": list(self.actions),
            "n": self.n,
            "accuracy": self.accuracy,
            "recordings": [
                {
                    "recording": r.recording,
                    "action": r.action,
                    "n": r.n,
                    "correct": r.correct,
                    "predicted": r.predicted,
                }
                for r in self.per_recording()
            ],
            "confusion": self.confusion.tolist(),
            "early": {
                "fractions": list(self.fractions),
                "accuracy": list(self.early_accuracy),
            },
            "predictions": [
                {
                    "source": p.source,
                    "recording": p.recording,
                    "action": p.action,
                    "predicted": p.predicted,
                    "posterior": list(p.posterior),
                }
                for p in self.predictions
            ],
            "meta": self.meta,
        }


def _prefix_rows(n_frames: int, fractions: Sequence[float]) -> list[int]:
    return [max(1, math.ceil(f * n_frames - 1e-9)) - 1 for f in fractions]


def _predict(
    compiled: CompiledModels,
    g: LabelledGesture,
    fractions: Sequence[float],
    priors: ArrayLike | None,
) -> Prediction:
    res: SequenceResult = recognize_sequence(compiled, g.in_space(compiled.models.features), priors)
    actions = compiled.actions
    rows = _prefix_rows(len(res), fractions)
    return Prediction(
        source=g.source,
        action=g.action,
        predicted=res.final.best,
        posterior=tuple(float(v) for v in res.final.posterior),
        early=tuple(actions[int(np.argmax(res.posterior[r]))] for r in rows),
        recording=g.recording,
    )


def _check_labels(gestures: Sequence[LabelledGesture], actions: Sequence[str]) -> None:
    if not gestures:
        raise InputError("no labelled gestures to evaluate on")
    unknown_labels = sorted({g.action for g in gestures} - set(actions))
    if unknown_labels:
        raise InputError(
            f"gestures labelled {', '.join(unknown_labels)} have no model; "
            f"valid labels: {', '.join(actions)}"
        )


def _report(
    actions: tuple[str, ...],
    preds: list[Prediction],
    fractions: Sequence[float],
    meta: dict[str, Any],
) -> EvaluationReport:
    index = {a: i for i, a in enumerate(actions)}
    conf = np.zeros((len(actions), len(actions)), dtype=np.int64)
    for p in preds:
        conf[index[p.action], index[p.predicted]] += 1
    early = tuple(
        float(np.mean([p.early[i] == p.action for p in preds])) for i in range(len(fractions))
    )
    return EvaluationReport(
        actions=actions,
        confusion=conf,
        fractions=tuple(fractions),
        early_accuracy=early,
        predictions=tuple(preds),
        meta=meta,
    )


def evaluate(
    models: GestureModels,
    gestures: Sequence[LabelledGesture],
    *,
    fractions: Sequence[float] = FRACTIONS,
    priors: ArrayLike | None = None,
    on_gesture: Callable[[], None] | None = None,
) -> EvaluationReport:
    """Recognise every gesture with `models` and tabulate the results."""
    _check_labels(gestures, models.actions)
    compiled = CompiledModels(models)
    preds = []
    for g in gestures:
        preds.append(_predict(compiled, g, fractions, priors))
        if on_gesture is not None:
            on_gesture()
    return _report(models.actions, preds, fractions, {"protocol": "held-out"})


FOLDS = ("recording", "gesture")


def cross_validate(
    gestures: Sequence[LabelledGesture],
    config: TrainingConfig | None = None,
    *,
    folds: str = "recording",
    also_train_on: Sequence[LabelledGesture] = (),
    actions: Sequence[str] | None = None,
    fractions: Sequence[float] = FRACTIONS,
    on_fold: Callable[[], None] | None = None,
) -> EvaluationReport:
    """Cross-validation in which no model ever sees what it is tested on.

    `folds="recording"`: leave one recording out (every gesture of it, so a person's other
    repetitions of the same movement never help); `"gesture"`: leave one gesture out.
    `also_train_on`: gestures every fold trains on and none is tested on (the robot's own
    synthetic experience, mixed with the recordings).

    In each fold only the models of the actions in the held-out part are retrained; the
    others are trained once on all their gestures (which never include the held-out ones),
    exactly as retraining everything. An action left with no training gesture in a fold has no
    model there: its gestures are recognised as one of the others (and counted wrong), which is
    what a robot that never saw that action would do.
    """
    if folds not in FOLDS:
        raise InputError(f"folds {folds!r}; valid: {', '.join(FOLDS)}")
    cfg = config or TrainingConfig()
    present = {g.action for g in (*gestures, *also_train_on)}
    if actions is None:
        actions = [a for a in ACTIONS if a in present] + sorted(present - set(ACTIONS))
    order = tuple(actions)
    _check_labels(gestures, order)
    _check_labels(also_train_on or gestures, order)
    if len({g.features.shape[1] for g in (*gestures, *also_train_on)}) != 1:
        raise InputError("the gestures do not all have the same features; use one feature space")
    extra = {a: [g.features for g in also_train_on if g.action == a] for a in order}

    def group(g: LabelledGesture, i: int) -> str:
        return (g.recording or g.source or str(i)) if folds == "recording" else str(i)

    parts: dict[str, list[int]] = {}
    for i, g in enumerate(gestures):
        parts.setdefault(group(g, i), []).append(i)

    def data(action: str, without: set[int]) -> list[FloatArray]:
        own = [
            g.features for j, g in enumerate(gestures) if g.action == action and j not in without
        ]
        return own + extra[action]

    def hmm(action: str, without: set[int]) -> GestureHMM | None:
        seqs = data(action, without)
        if not seqs:
            return None
        return train_hmm(seqs, replace(cfg, seed=cfg.seed + order.index(action)), what=action)

    full = {a: hmm(a, set()) for a in order}
    preds: list[Prediction | None] = [None] * len(gestures)
    missing: dict[str, list[str]] = {}
    for name, members in parts.items():
        held = set(members)
        retrain = {gestures[i].action for i in members}
        fold = {a: (hmm(a, held) if a in retrain else full[a]) for a in order}
        kept = tuple(a for a in order if fold[a] is not None)
        absent = [a for a in order if fold[a] is None]
        if absent:
            missing[name] = absent
        models = GestureModels(
            actions=kept,
            hmms=tuple(h for h in fold.values() if h is not None),
            features=MOTION,
        )
        compiled = CompiledModels(models)
        for i in members:
            preds[i] = _predict(compiled, gestures[i], fractions, None)
        if on_fold is not None:
            on_fold()
    meta = {
        "protocol": f"leave-one-{folds}-out cross-validation",
        "folds": len(parts),
        "also_trained_on": len(also_train_on),
        "without_a_model": missing,
        "config": {k: getattr(cfg, k) for k in cfg.__dataclass_fields__},
    }
    return _report(order, [p for p in preds if p is not None], fractions, meta)


# ---------------------------------------------------------------------------------------------
# Plots


def plot_report(report: EvaluationReport, out_dir: str | Path, title: str = "") -> list[Path]:
    """Confusion matrix and early-recognition curve as PNGs in `out_dir`; returns their paths."""
    plt = plotting.pyplot()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    k = len(report.actions)
    fig, ax = plt.subplots(figsize=(1.6 + 1.1 * k, 1.2 + 1.0 * k))
    ax.imshow(report.confusion, cmap="Blues")
    for i in range(k):
        for j in range(k):
            v = int(report.confusion[i, j])
            ax.text(
                j,
                i,
                str(v),
                ha="center",
                va="center",
                color="white" if v > report.confusion.max() / 2 else "black",
            )
    ax.set_xticks(range(k), report.actions)
    ax.set_yticks(range(k), report.actions)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    ax.set_title(f"{title} accuracy {report.accuracy:.1%} (n={report.n})".strip())
    fig.tight_layout()
    confusion = out / "confusion.png"
    fig.savefig(confusion, dpi=120)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    ax.plot([100 * f for f in report.fractions], [100 * a for a in report.early_accuracy], "o-")
    ax.axhline(100.0 / k, color="grey", lw=0.8, ls="--", label="chance")
    ax.set_xlabel("part of each gesture seen (%)")
    ax.set_ylabel("accuracy (%)")
    ax.set_ylim(0, 102)
    ax.set_xlim(5, 102)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    ax.set_title(f"{title} early recognition".strip())
    fig.tight_layout()
    early = out / "early_recognition.png"
    fig.savefig(early, dpi=120)
    plt.close(fig)
    return [confusion, early]


def plot_stream(
    result: SequenceResult, path: str | Path, title: str = "", first_frame: int = 1
) -> Path:
    """(1/t) log L(G_1^t | A) and P_HMM(A | G_1^t) over the frames of one gesture, as a PNG."""
    plt = plotting.pyplot()
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    frames = np.arange(first_frame, first_frame + len(result))
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    for i, a in enumerate(result.actions):
        top.plot(frames, result.normalized[:, i], label=a)
        bottom.plot(frames, result.posterior[:, i], label=a)
    top.set_ylabel(plotting.math(plotting.NORM_LOGLIK))
    lo = float(np.nanpercentile(result.normalized[np.isfinite(result.normalized)], 5))
    hi = float(np.nanmax(result.normalized[np.isfinite(result.normalized)]))
    top.set_ylim(lo - 0.5, hi + 0.5)
    bottom.set_ylabel(plotting.p_hmm())
    bottom.set_ylim(-0.03, 1.03)
    bottom.set_xlabel("frame")
    top.legend(title="action A", loc="lower right")
    top.grid(alpha=0.3)
    bottom.grid(alpha=0.3)
    if title:
        top.set_title(title)
    fig.tight_layout()
    fig.savefig(p, dpi=120)
    plt.close(fig)
    return p
