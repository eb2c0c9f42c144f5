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
from beyond_self.cognition.gestures.hmm import (
    GestureModels,
    TrainingConfig,
    train_hmm,
    train_models,
)
from beyond_self.cognition.gestures.streaming import (
    CompiledModels,
    SequenceResult,
    recognize_sequence,
)
from beyond_self.cognition.variables import ACTIONS
from beyond_self.core.errors import InputError

FloatArray = NDArray[np.float64]
FRACTIONS: tuple[float, ...] = tuple(round(0.1 * i, 1) for i in range(1, 11))


@dataclass(frozen=True, eq=False)
class LabelledGesture:
    """One gesture's features (T, D) and its true action; `source` says where it came from."""

    action: str
    features: FloatArray
    source: str = ""


@dataclass(frozen=True)
class Prediction:
    source: str
    action: str
    predicted: str
    posterior: tuple[float, ...]
    early: tuple[str, ...]  # predicted action at each fraction


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

    def to_dict(self) -> dict[str, Any]:
        return {
            "actions": list(self.actions),
            "n": self.n,
            "accuracy": self.accuracy,
            "confusion": self.confusion.tolist(),
            "early": {
                "fractions": list(self.fractions),
                "accuracy": list(self.early_accuracy),
            },
            "predictions": [
                {
                    "source": p.source,
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
    res: SequenceResult = recognize_sequence(compiled, g.features, priors)
    actions = compiled.actions
    rows = _prefix_rows(len(res), fractions)
    return Prediction(
        source=g.source,
        action=g.action,
        predicted=res.final.best,
        posterior=tuple(float(v) for v in res.final.posterior),
        early=tuple(actions[int(np.argmax(res.posterior[r]))] for r in rows),
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


def cross_validate(
    gestures: Sequence[LabelledGesture],
    config: TrainingConfig | None = None,
    *,
    actions: Sequence[str] | None = None,
    fractions: Sequence[float] = FRACTIONS,
    on_fold: Callable[[], None] | None = None,
) -> EvaluationReport:
    """Leave-one-gesture-out cross-validation (for repetitions: leave-one-repetition-out).

    Each gesture is recognised by models none of which saw it: its own action's model is
    retrained without it, the other actions' models are trained once on all their gestures
    (which never include it), exactly as retraining everything without it.
    """
    cfg = config or TrainingConfig()
    present = {g.action for g in gestures}
    if actions is None:
        actions = [a for a in ACTIONS if a in present] + sorted(present - set(ACTIONS))
    order = tuple(actions)
    _check_labels(gestures, order)
    by_action = {a: [g for g in gestures if g.action == a] for a in order}
    small = [a for a, gs in by_action.items() if len(gs) < 2]
    if small:
        raise InputError(
            f"cross-validation needs at least 2 gestures per action; {', '.join(small)} has fewer"
        )
    full = train_models(
        {a: [g.features for g in gs] for a, gs in by_action.items()}, cfg, actions=order
    )
    preds = []
    for a_i, action in enumerate(order):
        own = by_action[action]
        for i, g in enumerate(own):
            rest = [o.features for j, o in enumerate(own) if j != i]
            hmm = train_hmm(rest, replace(cfg, seed=cfg.seed + a_i), what=action)
            hmms = tuple(hmm if a == action else full[a] for a in order)
            fold = GestureModels(actions=order, hmms=hmms)
            preds.append(_predict(CompiledModels(fold), g, fractions, None))
            if on_fold is not None:
                on_fold()
    meta = {
        "protocol": "leave-one-gesture-out cross-validation",
        "config": {k: getattr(cfg, k) for k in cfg.__dataclass_fields__},
    }
    return _report(order, preds, fractions, meta)


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
