"""`beyond bn learn|show|query|words`: the Affordance–Words Bayesian network.

The evidence options are the same for every command that takes evidence (evidence_args.py).
JSON goes to stdout; tables for people go through rich. Bad input is an InputError (exit 2).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from beyond_self.cognition.bn.bag import load_bag
from beyond_self.cognition.bn.definition import load_definition
from beyond_self.cognition.bn.model import BayesNet, learn_network, load_model, save_model
from beyond_self.cognition.bn.parameters import UNSEEN_RULES
from beyond_self.cognition.bn.structure import DEFAULT_MAX_PARENTS, DEFAULT_ROOTS
from beyond_self.cognition.bn.synthetic import synthetic_paths
from beyond_self.commands import argtypes
from beyond_self.commands.evidence_args import add_evidence_arguments, resolve_evidence
from beyond_self.commands.terminal import progress_bar
from beyond_self.core.errors import InputError

HELP = "learn, show and query the Affordance–Words Bayesian network"


MODEL_HELP = "network model file (.json, from `beyond bn learn`)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="bn_command", metavar="SUBCOMMAND", required=True)

    learn = sub.add_parser("learn", help="learn structure (K2/BIC) and parameters from a bag table")
    learn.add_argument(
        "bag",
        nargs="?",
        type=Path,
        metavar="BAG",
        help="bag-of-words table (default: the bundled synthetic data set)",
    )
    learn.add_argument(
        "--network",
        type=Path,
        metavar="DEF",
        help="network definition (default: networkDefinition.txt beside BAG if there is one, "
        "else the bundled synthetic definition)",
    )
    learn.add_argument(
        "-o",
        "--output",
        type=argtypes.output_file,
        required=True,
        metavar="MODEL",
        help="model file to write (.json)",
    )
    learn.add_argument(
        "--unseen",
        choices=UNSEEN_RULES,
        default="absent",
        help="word CPT for parent configurations never seen in training: absent (default: "
        "P(absent) = 1, the configuration stays possible), zero (the reference toolbox's "
        "all-zero column: the configuration leaves the joint; the article's Table II), uniform, "
        "dirichlet",
    )
    learn.add_argument(
        "--max-parents",
        type=argtypes.count(0, 64),
        default=DEFAULT_MAX_PARENTS,
        help=f"most parents K2 gives a node (default {DEFAULT_MAX_PARENTS})",
    )
    learn.add_argument(
        "--scorer",
        choices=("counts", "pgmpy"),
        default="counts",
        help="BIC by our counting (fast) or by pgmpy's BIC (reference, slow)",
    )

    show = sub.add_parser("show", help="nodes, values, arcs and per-node log-likelihood")
    show.add_argument("model", type=Path, metavar="MODEL", help=MODEL_HELP)
    show.add_argument("--json", action="store_true", help="print the model as JSON")

    query = sub.add_parser("query", help="exact posterior of one or more variables")
    query.add_argument("model", type=Path, metavar="MODEL", help=MODEL_HELP)
    query.add_argument(
        "--query", nargs="+", required=True, metavar="VAR", help="variables to ask about (joint)"
    )
    add_evidence_arguments(query)
    query.add_argument("--json", action="store_true", help="print the posterior as JSON")

    words = sub.add_parser("words", help="P(word present) for every word")
    words.add_argument("model", type=Path, metavar="MODEL", help=MODEL_HELP)
    add_evidence_arguments(words)
    words.add_argument("--json", action="store_true", help="print the probabilities as JSON")


def run(args: argparse.Namespace) -> int:
    handler = {"learn": _learn, "show": _show, "query": _query, "words": _words}[args.bn_command]
    return handler(args)


def _learn(args: argparse.Namespace) -> int:
    console = Console(stderr=True)
    default_def, default_bag = synthetic_paths()
    bag = args.bag or default_bag
    network = args.network
    if network is None:
        beside = bag.parent / "networkDefinition.txt"
        network = beside if args.bag is not None and beside.exists() else default_def
    if args.max_parents < 0:
        raise InputError(f"--max-parents must be >= 0; got {args.max_parents}")
    start = time.perf_counter()
    with progress_bar(console, transient=False) as progress:
        reading = progress.add_task("reading data", total=2)
        definition = load_definition(network)
        progress.advance(reading)
        dataset = load_bag(bag, definition)
        progress.advance(reading)
        search = progress.add_task("structure (K2, BIC)", total=len(definition.variables))
        model = learn_network(
            dataset,
            max_parents=args.max_parents,
            unseen=args.unseen,
            scorer=args.scorer,
            on_node=lambda name, parents: progress.advance(search),
        )
    save_model(model, args.output)
    seconds = time.perf_counter() - start
    console.print(
        f"learned {len(model.variables)} nodes, {len(model.arcs)} arcs from {dataset.rows} rows "
        f"of {bag} (definition {network}) in {seconds:.2f} s; training log-likelihood over "
        f"non-root nodes {model.training_log_likelihood():.6f}"
    )
    print(args.output)
    return 0


def _show(args: argparse.Namespace) -> int:
    model = load_model(args.model)
    if args.json:
        print(json.dumps(show_json(model)))
        return 0
    console = Console()
    table = Table(title=f"{args.model}: {len(model.variables)} nodes, {len(model.arcs)} arcs")
    for col in ("node", "values", "parents", "log-likelihood"):
        table.add_column(col, justify="right" if col == "log-likelihood" else "left")
    for name in model.variables:
        ll = model.node_log_likelihood.get(name)
        table.add_row(
            name,
            " ".join(model.values[name]),
            " ".join(model.parents[name]) or "-",
            f"{ll:.4f}" if ll is not None else "",
        )
    console.print(table)
    roots = [r for r in DEFAULT_ROOTS if r in model.variables]
    console.print(
        f"training log-likelihood without {', '.join(roots)}: "
        f"{model.training_log_likelihood(roots):.8f}"
    )
    if model.zero_columns:
        console.print(
            "all-zero word columns (parent configurations ruled out of the joint): "
            + ", ".join(f"{w} {n}" for w, n in model.zero_columns.items())
            + f"; prior mass ruled out {model.compiled.removed_mass:.6f}"
        )
    return 0


def show_json(model: BayesNet) -> dict[str, Any]:
    return {
        "nodes": [{"name": n, "values": list(model.values[n])} for n in model.variables],
        "arcs": [list(a) for a in model.arcs],
        "node_log_likelihood": dict(model.node_log_likelihood),
        "zero_columns": model.zero_columns,
        "removed_mass": model.compiled.removed_mass,
    }


def _query(args: argparse.Namespace) -> int:
    model = load_model(args.model)
    ev = resolve_evidence(args, model)
    posterior = model.query(args.query, ev.observed, ev.soft)
    if args.json:
        print(json.dumps(posterior.as_dict()))
        return 0
    table = Table(title=f"P({', '.join(args.query)} | {ev.label()})")
    for name in posterior.variables:
        table.add_column(name)
    table.add_column("p", justify="right")
    for assignment, p in posterior.rows():
        table.add_row(*assignment.values(), f"{p:.6f}")
    Console().print(table)
    return 0


def _words(args: argparse.Namespace) -> int:
    model = load_model(args.model)
    ev = resolve_evidence(args, model)
    probs = model.word_probabilities(ev.observed, ev.soft)
    if args.json:
        print(json.dumps(probs))
        return 0
    table = Table(title=f"P(word present | {ev.label()})")
    table.add_column("word")
    table.add_column("p", justify="right")
    for word, p in sorted(probs.items(), key=lambda kv: -kv[1]):
        table.add_row(word, f"{p:.6f}")
    Console().print(table)
    return 0
