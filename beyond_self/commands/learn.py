"""`beyond learn -o DIR`: the robot learns to recognise gestures from its own affordances.

Self phase on the robot's exploration data (the bundled synthetic set by default), then human
demonstrations labelled by the network, gesture HMMs trained on those labels, and everything
evaluated on held-out demonstrations, with ablations over words and the number of
demonstrations. Writes learning.md, results.json and PNG plots; --json also prints the results.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from rich.console import Console

from beyond_self.cognition.paths import data_set
from beyond_self.commands import argtypes
from beyond_self.commands.hmm_options import add_training_options, training_config
from beyond_self.commands.terminal import progress_bar
from beyond_self.core.errors import InputError

HELP = "learn gesture models from human demonstrations labelled by the affordance network"


def _sizes(text: str) -> tuple[int, ...]:
    try:
        sizes = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a list of numbers; valid: e.g. 5,10,20,50"
        ) from None
    if not sizes or any(n < 1 for n in sizes):
        raise argparse.ArgumentTypeError(f"{text!r}: valid: positive numbers, e.g. 5,10,20,50")
    return sizes


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--robot-data",
        default="synthetic",
        help="'synthetic' (default), a salvi2012 folder or a bag table with "
        "networkDefinition.txt beside it (a name such as salvi2012 is also looked up in the "
        "article's data folder, $BEYOND_DATA)",
    )
    parser.add_argument(
        "--human-data",
        default="synthetic",
        help="'synthetic' (default) or a folder of hand recordings (grasp1_hand/ ...); a name "
        "such as human_data is also looked up in the article's data folder ($BEYOND_DATA)",
    )
    argtypes.add_output(
        parser,
        "folder to write learning.md, results.json and the plots into",
        folder=True,
        required=True,
        old="--out",
    )
    parser.add_argument("--json", action="store_true", help="also print results.json on stdout")
    for flag, default, what in (
        ("--demos", 20, "demonstrations watched per action"),
        ("--test", 60, "held-out demonstrations per action"),
    ):
        parser.add_argument(
            flag,
            type=argtypes.count(1, 100_000),
            default=default,
            help=f"{what} (default {default})",
        )
    parser.add_argument(
        "--sizes",
        type=_sizes,
        default=(5, 10, 20, 50),
        help="ablation: demonstrations per action, comma separated (default 5,10,20,50)",
    )
    parser.add_argument(
        "--threshold",
        type=argtypes.number(float, lo=0, hi=1, what="a probability"),
        default=0.9,
        help="keep a demonstration when max P_BN(A | ...) is at least this (default 0.9)",
    )
    add_training_options(parser, mix=1, iterations=10)
    parser.add_argument(
        "--no-calibrate",
        action="store_true",
        help="do not calibrate the gesture evidence's temper (use kappa = 1)",
    )
    argtypes.add_seed(parser, "seed of everything synthetic")


def run(args: argparse.Namespace) -> int:
    from beyond_self.cognition.development.learning import LearningConfig, plan_units, run_learning
    from beyond_self.cognition.development.report import write_outputs

    if not 0.0 <= args.threshold <= 1.0:
        raise InputError(f"--threshold {args.threshold}; valid: a probability in [0, 1]")
    config = LearningConfig(
        n_per_action=args.demos,
        test_per_action=args.test,
        sizes=args.sizes,
        threshold=args.threshold,
        calibrate=not args.no_calibrate,
        training=training_config(args),
        seed=args.seed,
    )
    console = Console(stderr=True)
    start = time.perf_counter()
    with progress_bar(console) as progress:
        task = progress.add_task("starting", total=plan_units(config))

        def report(what: str, units: int) -> None:
            progress.update(task, description=what, advance=units)

        robot_data = data_set(args.robot_data, keep=("synthetic",))
        human_data = data_set(args.human_data, keep=("synthetic",))
        results = run_learning(config, robot_data, human_data, progress=report)
        progress.update(task, description="writing report and plots")
        paths = write_outputs(results, args.output)
    acc = {s: results.main.accuracy(s) for s in ("hmm_inferred", "hmm_true", "network", "fused")}
    check = results.acceptance()
    console.print(
        f"{results.main.n_per_action} demos/action: labels "
        f"{results.main.labelling['accuracy']:.1%} right; held-out accuracy: HMM on inferred "
        f"labels {acc['hmm_inferred']:.1%}, on true labels {acc['hmm_true']:.1%}, network "
        f"{acc['network']:.1%}, fused {acc['fused']:.1%} "
        f"(inferred/true {check['hmm_inferred_over_true']:.2f}; fused >= both: "
        f"{'yes' if check['fused_at_least_both'] else 'NO'}) "
        f"in {time.perf_counter() - start:.1f} s"
    )
    if args.json:
        json.dump(json.loads(paths["results"].read_text(encoding="utf-8")), sys.stdout, indent=1)
        print()
    else:
        print(paths["report"])
    return 0
