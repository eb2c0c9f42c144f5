"""How well the vision pipeline recovers the simulated truth: confusion matrices per variable.

Object labels (Color, Shape, Size) are scored per object, effect labels per experiment. Stills
with several objects score the object labels cheaply; experiments score everything.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from beyond_self.cognition.variables import AFFORDANCE_VARIABLES, EFFECTS, OBJECT_FEATURES
from beyond_self.cognition.vision.clusters import ClusterModel
from beyond_self.cognition.vision.pipeline import analyse_experiment, describe_frame
from beyond_self.cognition.vision.tabletop import Camera, Experiment, random_object, render_still

VARIABLES = (*OBJECT_FEATURES, *EFFECTS)


@dataclass
class Evaluation:
    """Truth and prediction per variable (prediction "?" when nothing was measured)."""

    truth: dict[str, list[str]] = field(default_factory=lambda: {v: [] for v in VARIABLES})
    predicted: dict[str, list[str]] = field(default_factory=lambda: {v: [] for v in VARIABLES})
    failures: list[str] = field(default_factory=list)

    def add(self, variable: str, truth: str, predicted: str | None) -> None:
        self.truth[variable].append(truth)
        self.predicted[variable].append(predicted if predicted is not None else "?")

    def count(self, variable: str) -> int:
        return len(self.truth[variable])

    def accuracy(self, variable: str) -> float:
        t, p = self.truth[variable], self.predicted[variable]
        return float(np.mean([a == b for a, b in zip(t, p, strict=True)])) if t else float("nan")

    def confusion(self, variable: str) -> tuple[np.ndarray, list[str]]:
        """Counts [true value, predicted value]; a last "?" column if anything was unmeasured."""
        values = list(AFFORDANCE_VARIABLES[variable])
        cols = [*values, "?"] if "?" in self.predicted[variable] else values
        m = np.zeros((len(values), len(cols)), dtype=np.int64)
        for t, p in zip(self.truth[variable], self.predicted[variable], strict=True):
            m[values.index(t), cols.index(p) if p in cols else len(cols) - 1] += 1
        return m, cols

    def summary(self) -> dict[str, dict[str, float]]:
        return {
            v: {"n": self.count(v), "accuracy": round(self.accuracy(v), 4)}
            for v in VARIABLES
            if self.count(v)
        }

    def format(self) -> str:
        """Confusion matrices as text (rows: truth, columns: predicted)."""
        lines = []
        for v in VARIABLES:
            if not self.count(v):
                continue
            m, cols = self.confusion(v)
            rows = AFFORDANCE_VARIABLES[v]
            w = max(7, *(len(c) for c in cols), *(len(r) for r in rows))
            lines.append(f"{v}: accuracy {self.accuracy(v):.3f} over {self.count(v)}")
            lines.append(" " * (w + 2) + " ".join(c.rjust(w) for c in cols))
            for r, row in zip(rows, m, strict=True):
                lines.append(f"  {r.ljust(w)}" + " ".join(str(x).rjust(w) for x in row))
        return "\n".join(lines)

    def plot(self, path: str | Path, title: str = "") -> Path:
        """All confusion matrices in one PNG."""
        from beyond_self.cognition.plotting import pyplot

        plt = pyplot()
        present = [v for v in VARIABLES if self.count(v)]
        ncol = min(4, len(present))
        nrow = -(-len(present) // ncol)
        fig, axes = plt.subplots(nrow, ncol, figsize=(3.4 * ncol, 3.2 * nrow), squeeze=False)
        for ax in axes.ravel()[len(present) :]:
            ax.axis("off")
        for ax, v in zip(axes.ravel(), present, strict=False):
            m, cols = self.confusion(v)
            rows = AFFORDANCE_VARIABLES[v]
            ax.imshow(m / np.maximum(m.sum(axis=1, keepdims=True), 1), cmap="Blues", vmin=0, vmax=1)
            for i in range(m.shape[0]):
                for j in range(m.shape[1]):
                    ax.text(j, i, str(m[i, j]), ha="center", va="center", fontsize=9)
            ax.set_xticks(range(len(cols)), cols, rotation=45, fontsize=8)
            ax.set_yticks(range(len(rows)), rows, fontsize=8)
            ax.set_xlabel("predicted", fontsize=8)
            ax.set_ylabel("true", fontsize=8)
            ax.set_title(f"{v}  acc {self.accuracy(v):.3f}  n={self.count(v)}", fontsize=9)
        if title:
            fig.suptitle(title, fontsize=10)
        fig.tight_layout()
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(p, dpi=100)
        plt.close(fig)
        return p


def evaluate_experiments(
    experiments: Iterable[Experiment],
    clusters: ClusterModel,
    evaluation: Evaluation | None = None,
    progress: Callable[[int], None] | None = None,
    use_skeleton: bool = True,
) -> Evaluation:
    """Score object and effect labels on simulated experiments."""
    ev = evaluation or Evaluation()
    for i, exp in enumerate(experiments):
        a = analyse_experiment(exp, clusters, use_skeleton=use_skeleton)
        for v in VARIABLES:
            if v in exp.labels:
                ev.add(v, exp.labels[v], a.labels.get(v))
        if progress:
            progress(i + 1)
    return ev


def still_scenes(
    n: int, seed: int, per_scene: int = 3, camera: Camera | None = None
) -> Iterable[tuple[np.ndarray, list[tuple[tuple[float, float], dict[str, str]]]]]:
    """n frames, each with `per_scene` objects of random labels placed apart; yields the frame and
    each object's projected centre and labels."""
    cam = camera or Camera()
    rng = np.random.default_rng(seed)
    slots = np.array(
        [[-0.3, 0.14], [0.0, 0.14], [0.3, 0.14], [-0.3, -0.14], [0.0, -0.14], [0.3, -0.14]]
    )
    for _ in range(n):
        chosen = rng.choice(len(slots), size=min(per_scene, len(slots)), replace=False)
        placed, truth = [], []
        for j in chosen:
            labels = {
                v: str(rng.choice(AFFORDANCE_VARIABLES[v])) for v in ("Color", "Shape", "Size")
            }
            obj = random_object(labels["Color"], labels["Shape"], labels["Size"], rng)
            xy = slots[j] + rng.uniform(-0.04, 0.04, 2)
            placed.append((obj, xy))
            top = obj.height_m / 2 if obj.shape == "circle" else obj.height_m
            c = cam.project(np.array([xy[0], xy[1], top]))
            truth.append(((float(c[0]), float(c[1])), labels))
        yield render_still(placed, rng, cam), truth


def evaluate_stills(
    n: int, seed: int, clusters: ClusterModel, per_scene: int = 3, camera: Camera | None = None
) -> Evaluation:
    """Score Color, Shape and Size on still scenes; an object not found counts as "?"."""
    ev = Evaluation()
    for k, (frame, truth) in enumerate(still_scenes(n, seed, per_scene, camera)):
        found = describe_frame(frame, clusters, require_objects=False).objects
        for centre, labels in truth:
            match = min(
                found,
                key=lambda o: np.hypot(
                    o.features.centroid[0] - centre[0], o.features.centroid[1] - centre[1]
                ),
                default=None,
            )
            ok = (
                match is not None
                and np.hypot(
                    match.features.centroid[0] - centre[0], match.features.centroid[1] - centre[1]
                )
                < 6.0
            )
            if not ok:
                ev.failures.append(f"scene {k}: object at {centre} not found")
            for v in ("Color", "Shape", "Size"):
                ev.add(v, labels[v], match.labels.get(v) if ok and match is not None else None)
    return ev
