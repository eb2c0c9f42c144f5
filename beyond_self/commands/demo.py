"""`beyond demo`: the main job, `beyond up` on the bundled recording of a person tapping a ball and
grasping a box, printing the recognised actions, the anticipated effects and the descriptions.

With --network, a tour of the science alone, no bus: the Affordance–Words network learned from
the bundled synthetic data set, asked the article's kinds of questions (which action explains
the effects, what an action will do, how a gesture's soft evidence changes that, which words
describe a scene). Needs nothing outside the repository.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Mapping, Sequence

from rich.console import Console
from rich.table import Table

from beyond_self.cognition.bn.model import BayesNet, learn_network
from beyond_self.cognition.bn.synthetic import synthetic_dataset
from beyond_self.commands import argtypes

HELP = "the full pipeline on the bundled recording (--network: a tour of the network alone)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--network", action="store_true", help="tour the affordance–words network, no bus"
    )
    parser.add_argument(
        "--top", type=argtypes.count(1, 10_000), default=8, help="with --network: words to list"
    )
    parser.add_argument("--no-live", action="store_true", help="event lines only, no live view")
    from beyond_self.commands.up_options import add_out_dir

    add_out_dir(parser)


def run(args: argparse.Namespace) -> int:
    if args.network:
        return network_tour(args)
    from beyond_self.cognition.paths import DEMO_RECORDING
    from beyond_self.commands import up

    parser = argparse.ArgumentParser(prog="beyond demo")
    up.add_arguments(parser)
    # a show, not a job to finish: each one starts from the beginning
    argv = ["--recording", str(DEMO_RECORDING), "--fresh", *(["--no-live"] if args.no_live else [])]
    if args.out_dir is not None:
        argv += ["--out-dir", str(args.out_dir)]
    return up.run(parser.parse_args(argv))


def _given(evidence: Mapping[str, str], soft: Mapping[str, Sequence[float]] | None = None) -> str:
    parts = [f"{k}={v}" for k, v in evidence.items()]
    parts += [f"{k}~({', '.join(f'{p:g}' for p in ps)})" for k, ps in (soft or {}).items()]
    return ", ".join(parts) or "nothing"


def _distribution_table(
    model: BayesNet, title: str, variable: str, rows: Sequence[tuple[str, dict[str, str]]]
) -> Table:
    table = Table(title=title, title_justify="left")
    table.add_column("given")
    for value in model.values[variable]:
        table.add_column(value, justify="right")
    for label, evidence in rows:
        dist = model.query(variable, evidence).marginal(variable)
        best = max(dist, key=dist.__getitem__)
        table.add_row(
            label,
            *(f"[bold]{p:.3f}[/bold]" if v == best else f"{p:.3f}" for v, p in dist.items()),
        )
    return table


def network_tour(args: argparse.Namespace) -> int:
    console = Console()
    start = time.perf_counter()
    dataset = synthetic_dataset()
    model = learn_network(dataset)
    learned = time.perf_counter() - start
    console.rule("[bold]beyond-self: the Affordance–Words network")
    console.print(
        f"Learned from the bundled synthetic robot-exploration set ({dataset.rows} spoken "
        f"descriptions, {len(model.words)} words) in {learned:.2f} s: "
        f"{len(model.arcs)} arcs found by K2 with the BIC score."
    )
    affordance = [v.name for v in model.definition.affordance]
    console.print(
        "Affordance part: "
        + "; ".join(f"{', '.join(model.parents[n])} → {n}" for n in affordance if model.parents[n])
    )
    word_parents: dict[tuple[str, ...], list[str]] = {}
    for var in model.definition.words:
        word_parents.setdefault(model.parents[var.name], []).append(var.word)
    for parents, words in sorted(word_parents.items(), key=lambda kv: (len(kv[0]), kv[0])):
        console.print(f"  words depending on {', '.join(parents) or 'nothing'}: {' '.join(words)}")

    console.print()
    console.print(
        _distribution_table(
            model,
            "1. Which action explains what happened?  P(Action | effects)",
            "Action",
            [
                ("object inert, short contact", {"ObjVel": "slow", "Contact": "short"}),
                ("long contact", {"Contact": "long"}),
                ("object fast, hand fast", {"ObjVel": "fast", "HandVel": "fast"}),
                ("box slides at medium speed", {"Shape": "box", "ObjVel": "medium"}),
            ],
        )
    )
    console.print(
        _distribution_table(
            model,
            "2. What will a tap do?  P(ObjVel | Shape, Action=tap)",
            "ObjVel",
            [
                (f"Shape={shape}", {"Shape": shape, "Action": "tap"})
                for shape in model.values["Shape"]
            ],
        )
    )

    gesture = {"Action": [0.1, 0.6, 0.3]}  # a gesture recogniser's P(grasp, tap, touch)
    table = Table(
        title="3. With an uncertain gesture: P(ObjVel | Shape, soft Action "
        f"{_given({}, gesture).removeprefix('Action')})",
        title_justify="left",
    )
    table.add_column("given")
    for value in model.values["ObjVel"]:
        table.add_column(value, justify="right")
    for shape in model.values["Shape"]:
        dist = model.query("ObjVel", {"Shape": shape}, gesture).marginal("ObjVel")
        table.add_row(f"Shape={shape}", *(f"{p:.3f}" for p in dist.values()))
    console.print(table)

    scene = {"Color": "yellow", "Size": "big", "Shape": "box", "ObjVel": "medium"}
    before = model.word_probabilities(scene)
    after = model.word_probabilities({**scene, "Action": "tap"})
    table = Table(
        title=f"4. Words for a scene: {_given(scene)}, then also Action=tap",
        title_justify="left",
    )
    for col in ("word", "P(w | scene)", "P(w | scene, tap)", "change"):
        table.add_column(col, justify="left" if col == "word" else "right")
    ranked = sorted(after, key=lambda w: -after[w])[: args.top]
    moved = sorted(after, key=lambda w: before[w] - after[w])
    risers, fallers = moved[: max(3, args.top // 2)], moved[::-1][:3]
    for word in dict.fromkeys([*ranked, *risers, *fallers]):
        change = after[word] - before[word]
        table.add_row(
            word, f"{before[word]:.3f}", f"{after[word]:.3f}", f"[bold]{change:+.3f}[/bold]"
        )
    console.print(table)
    console.print(
        f"Done in {time.perf_counter() - start:.2f} s. Next: `beyond bn learn -o model.json`, "
        "`beyond bn query model.json --query Action --evidence ObjVel=fast`."
    )
    return 0
