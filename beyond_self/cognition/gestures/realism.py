"""How much the simulator's gestures look like people's: the same measures on both, side by side.

The default models are trained on synthetic gestures only, so they recognise people exactly as
far as the simulator's gestures resemble people's. `compare_gestures` measures both sets of
gestures, cut the same way (by the default segmenter), on what a recogniser sees: duration,
speed, the pose the hand starts from, how far it goes in each direction, and the mean
trajectory over normalised time (its distance between the two sets says how far apart the
shapes are). `plot_profiles` draws the trajectories over each other (`beyond gesture
realism`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from beyond_self.cognition.gestures.evaluation import LabelledGesture
from beyond_self.cognition.gestures.features import NOMINAL_FPS, smooth_positions
from beyond_self.cognition.plotting import pyplot, save_figure
from beyond_self.core.errors import InputError

FloatArray = NDArray[np.float64]

# what each measure is, in order: name -> (unit, description)
MEASURES: dict[str, tuple[str, str]] = {
    "duration": ("s", "length of the gesture"),
    "speed": ("u/s", "median hand speed"),
    "peak": ("u/s", "90th percentile of the hand speed"),
    "start_x": ("u", "start pose, right of the torso"),
    "start_y": ("u", "start pose, above the torso"),
    "start_z": ("u", "start pose, behind the torso"),
    "forward": ("u", "farthest forward of the start"),
    "left": ("u", "farthest left of the start"),
    "right": ("u", "farthest right of the start"),
    "up": ("u", "highest above the start"),
    "down": ("u", "lowest below the start"),
}
TIME_POINTS = 50  # samples of the normalised-time mean trajectory


def measure(positions: FloatArray) -> dict[str, float]:
    """The measures of one gesture's positions (T, 3) in body units."""
    if len(positions) < 2:
        raise InputError(f"a gesture of {len(positions)} frames cannot be measured; need 2")
    g = smooth_positions(positions)
    d = g - g[0]
    speed = np.linalg.norm(np.diff(g, axis=0), axis=1) * NOMINAL_FPS
    return {
        "duration": len(g) / NOMINAL_FPS,
        "speed": float(np.median(speed)),
        "peak": float(np.percentile(speed, 90)),
        "start_x": float(g[0, 0]),
        "start_y": float(g[0, 1]),
        "start_z": float(g[0, 2]),
        "forward": float(-d[:, 2].min()),
        "left": float(-d[:, 0].min()),
        "right": float(d[:, 0].max()),
        "up": float(d[:, 1].max()),
        "down": float(-d[:, 1].min()),
    }


def mean_trajectory(gestures: Sequence[LabelledGesture]) -> FloatArray:
    """Displacement from the start (TIME_POINTS, 3), averaged over normalised time."""
    rows = []
    for g in gestures:
        p = smooth_positions(_positions(g))
        idx = np.linspace(0, len(p) - 1, TIME_POINTS)
        rows.append(
            np.stack([np.interp(idx, np.arange(len(p)), p[:, k] - p[0, k]) for k in range(3)], 1)
        )
    mean: FloatArray = np.mean(rows, axis=0)
    return mean


@dataclass(frozen=True)
class Comparison:
    """One action: the measures' mean and spread in both sets, and the trajectories' distance."""

    action: str
    n_recorded: int
    n_synthetic: int
    recorded: dict[str, tuple[float, float]]  # measure -> (mean, sd)
    synthetic: dict[str, tuple[float, float]]
    shape_distance: float  # RMS distance of the mean trajectories, body units


def _positions(g: LabelledGesture) -> FloatArray:
    if g.positions is None:
        raise InputError(f"gesture {g.source} has no positions to measure")
    return g.positions


def _summary(gestures: Sequence[LabelledGesture]) -> dict[str, tuple[float, float]]:
    rows = [measure(_positions(g)) for g in gestures]
    return {
        k: (float(np.mean([r[k] for r in rows])), float(np.std([r[k] for r in rows])))
        for k in MEASURES
    }


def compare_gestures(
    recorded: Sequence[LabelledGesture], synthetic: Sequence[LabelledGesture]
) -> list[Comparison]:
    """Per action present in both sets (in the recorded set's order)."""
    out = []
    actions = list(dict.fromkeys(g.action for g in recorded))
    for a in actions:
        real = [g for g in recorded if g.action == a]
        syn = [g for g in synthetic if g.action == a]
        if not syn:
            continue
        gap = mean_trajectory(real) - mean_trajectory(syn)
        out.append(
            Comparison(
                action=a,
                n_recorded=len(real),
                n_synthetic=len(syn),
                recorded=_summary(real),
                synthetic=_summary(syn),
                shape_distance=float(np.sqrt(np.mean(np.sum(gap**2, axis=1)))),
            )
        )
    if not out:
        raise InputError("the recorded and synthetic gestures share no action to compare")
    return out


def plot_profiles(
    recorded: Sequence[LabelledGesture], synthetic: Sequence[LabelledGesture], path: str | Path
) -> Path:
    """Displacement from the start (x, y, z) and speed over time, recorded over synthetic."""
    plt = pyplot()
    actions = list(dict.fromkeys(g.action for g in recorded))
    fig, axes = plt.subplots(4, len(actions), figsize=(4.5 * len(actions), 10), squeeze=False)
    labels = ("right of start (u)", "above start (u)", "behind start (u)", "speed (u/s)")
    for col, a in enumerate(actions):
        for gestures, colour, width in ((synthetic, "tab:blue", 0.5), (recorded, "tab:red", 1.6)):
            for g in (g for g in gestures if g.action == a):
                p = smooth_positions(_positions(g))
                t = np.arange(len(p)) / NOMINAL_FPS
                speed = np.r_[0.0, np.linalg.norm(np.diff(p, axis=0), axis=1) * NOMINAL_FPS]
                for row, values in enumerate((*(p - p[0]).T, speed)):
                    axes[row, col].plot(t, values, color=colour, lw=width, alpha=0.7)
        axes[0, col].set_title(f"{a}: recorded (red) and synthetic (blue)")
        for row, label in enumerate(labels):
            axes[row, col].set_ylabel(label)
            axes[row, col].grid(alpha=0.3)
        axes[3, col].set_xlabel("time since the gesture began (s)")
        axes[3, col].set_ylim(0, 8)
    fig.tight_layout()
    return save_figure(fig, path, dpi=90)
