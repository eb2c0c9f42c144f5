"""`beyond describe`: the N best sentences of the grammar describing what the evidence says.

    beyond describe MODEL [--evidence VAR=VALUE ...] [--soft VAR=value:p,... ...]
                    [--gesture ACTION=p,... | --gesture-log MODELS LOG [--frames A:B] [--scale S]]
                    [--nbest N] [--sentences FILE | --samples N --seed S] [--legacy-offset]
                    [--require REGEX] [--json] [--plot OUT.png]

Word probabilities come from the network (fused with the gesture evidence when given); by default
the N-best list is the exact one over all ~9.3 million sentences of the grammar.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from rich.console import Console
from rich.table import Table

from beyond_self.cognition.bn.model import load_model
from beyond_self.cognition.descriptions import (
    NBEST_MAX,
    SAMPLES_MAX,
    Ranking,
    ScoredSentence,
    nbest_exact,
    nbest_from_file,
    nbest_sampled,
    plot_nbest,
)
from beyond_self.commands import argtypes
from beyond_self.commands.evidence_args import add_evidence_arguments, resolve_evidence

HELP = "N-best sentences describing the evidence (exact search over the grammar by default)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("model", type=Path, metavar="MODEL", help="network model file (.json)")
    add_evidence_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print the sentences as JSON")
    parser.add_argument(
        "--nbest",
        type=argtypes.count(1, NBEST_MAX),
        default=10,
        metavar="N",
        help=f"sentences to list, best first (default 10, at most {NBEST_MAX:,})",
    )
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--sentences", type=Path, metavar="FILE", help="re-score these sentences")
    source.add_argument(
        "--samples",
        type=argtypes.count(1, SAMPLES_MAX),
        metavar="N",
        help="re-score N random sentences",
    )
    argtypes.add_seed(parser, "seed for --samples (default 0)")
    parser.add_argument(
        "--legacy-offset",
        action="store_true",
        help="score (1 + Σ log P)/L as the reference code behind the published tables did",
    )
    parser.add_argument("--require", metavar="REGEX", help="keep only sentences matching REGEX")
    parser.add_argument(
        "--plot", type=argtypes.output_file, metavar="OUT.png", help="also draw the list as PNG"
    )


def describe(args: argparse.Namespace) -> tuple[list[ScoredSentence], str]:
    """The N-best list for parsed arguments, and a label of the evidence behind it."""
    model = load_model(args.model)
    ev = resolve_evidence(args, model)
    words = model.word_probabilities(ev.observed, ev.soft)
    options: Ranking = {"legacy_offset": args.legacy_offset, "require": args.require}
    if args.sentences is not None:
        best = nbest_from_file(args.sentences, words, args.nbest, **options)
    elif args.samples is not None:
        best = nbest_sampled(words, args.samples, args.seed, args.nbest, **options)
    else:
        best = nbest_exact(words, args.nbest, **options)
    return best, ev.label()


def json_score(score: float) -> float | None:
    """Rounded to 5 decimals; a sentence with an impossible word (score −inf) is null in JSON."""
    return round(score, 5) if math.isfinite(score) else None


def run(args: argparse.Namespace) -> int:
    best, label = describe(args)
    if args.plot is not None:
        plot_nbest(best, args.plot, f"{len(best)}-best given {label}")
    if args.json:
        print(json.dumps([{"sentence": s.sentence, "score": json_score(s.score)} for s in best]))
        return 0
    if not best:
        why = f" matches --require {args.require!r}" if args.require else " to rank"
        Console(stderr=True).print(f"no sentence{why}")
        return 0
    table = Table(title=f"{len(best)}-best descriptions", caption=f"given {label}")
    table.add_column("#", justify="right")
    table.add_column("sentence")
    table.add_column("score", justify="right")
    for i, item in enumerate(best, 1):
        table.add_row(str(i), item.sentence, f"{item.score:.5f}")
    Console().print(table)
    return 0
