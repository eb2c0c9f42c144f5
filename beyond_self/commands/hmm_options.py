"""The gesture HMMs' training options, shared by `beyond gesture` and `beyond learn`, so that a flag
means the same and is checked the same way in both (only the defaults differ: `learn` trains many
model sets and takes smaller ones)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from beyond_self.commands import argtypes

if TYPE_CHECKING:
    from beyond_self.cognition.gestures.training import TrainingConfig


def add_training_options(
    parser: argparse.ArgumentParser, *, mix: int, iterations: int, states: str = "HMM states"
) -> None:
    """--states, --mix and --iter; `states` names what the first counts in its help."""
    for flag, hi, default, what in (
        ("--states", 100, 6, states),
        ("--mix", 50, mix, "Gaussians per state"),
        ("--iter", 100_000, iterations, "EM iterations at most"),
    ):
        parser.add_argument(
            flag, type=argtypes.count(1, hi), default=default, help=f"{what} (default {default})"
        )


def training_config(args: argparse.Namespace, seed: int = 0) -> TrainingConfig:
    """The options `add_training_options` added, as the trainer's config."""
    from beyond_self.cognition.gestures.training import TrainingConfig

    return TrainingConfig(n_states=args.states, n_mix=args.mix, n_iter=args.iter, seed=seed)
