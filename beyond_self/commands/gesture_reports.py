"""What `beyond gesture evaluate` and `beyond gesture realism` print and plot.

Tables a person reads (accuracy, confusion, per recording, early recognition), the same numbers
as JSON with `--json`, and the PNGs (confusion matrix, early-recognition curve, trajectories)
in `--out`.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

from rich.console import Console
from rich.table import Table

from beyond_self.cognition.gestures.evaluation import EvaluationReport, LabelledGesture
from beyond_self.cognition.gestures.hmm import GestureModels
from beyond_self.commands.hmm_options import training_config
from beyond_self.commands.terminal import progress_bar

Gestures = Callable[[argparse.Namespace, str], list[LabelledGesture]]
Models = Callable[..., GestureModels]


def evaluate_command(args: argparse.Namespace, gestures: Gestures, models_from: Models) -> int:
    from beyond_self.cognition.gestures.evaluation import cross_validate, evaluate, plot_report

    if args.models == "compare":
        return _compare(args, models_from)
    console = Console(stderr=True)
    with console.status(f"loading gestures from {args.data}"):
        data = gestures(args, args.data)
        extra = [g for spec in args.also for g in gestures(args, spec)]
    with progress_bar(console) as progress:
        if args.models == "cv":
            groups = {g.recording or g.source for g in data} if args.folds == "recording" else data
            task = progress.add_task("cross-validation folds", total=len(groups))
            report = cross_validate(
                data,
                training_config(args),
                folds=args.folds,
                also_train_on=extra,
                on_fold=lambda: progress.advance(task),
            )
        else:
            models = models_from(args.models)
            task = progress.add_task("recognising gestures", total=len(data))
            report = evaluate(models, data, on_gesture=lambda: progress.advance(task))
    report.meta["data"] = str(args.data)
    report.meta["models"] = str(args.models)
    plots = plot_report(report, args.output, title=Path(str(args.data)).name)
    if args.json:
        out = report.to_dict()
        out["plots"] = [str(p) for p in plots]
        json.dump(out, sys.stdout)
        sys.stdout.write("\n")
        return 0
    show_report(Console(), report)
    Console().print(f"plots: {', '.join(map(str, plots))}")
    return 0


def show_report(console: Console, report: EvaluationReport, title: str = "") -> None:
    """Accuracy, confusion, per recording and early recognition, as tables."""
    console.print(
        f"{title or report.meta['protocol']}: {report.n} gestures, "
        f"accuracy [bold]{report.accuracy:.1%}"
    )
    conf = Table(title="confusion (rows: true, columns: predicted)")
    conf.add_column("")
    for a in report.actions:
        conf.add_column(a, justify="right")
    for a, row in zip(report.actions, report.confusion, strict=True):
        conf.add_row(a, *(str(int(v)) for v in row))
    console.print(conf)
    logs = Table(title="per recording")
    for name in ("recording", "action", "gestures", "right", "recognised as"):
        logs.add_column(name, justify="left" if name in ("recording", "recognised as") else "right")
    for r in report.per_recording():
        calls = ", ".join(f"{n} × {a}" for a, n in sorted(r.predicted.items()))
        logs.add_row(r.recording, r.action, str(r.n), str(r.correct), calls)
    console.print(logs)
    early = Table(title="early recognition: accuracy after seeing part of each gesture")
    for f in report.fractions:
        early.add_column(f"{f:.0%}", justify="right")
    early.add_row(*(f"{a:.0%}" for a in report.early_accuracy))
    console.print(early)


def _compare(args: argparse.Namespace, models_from: Models) -> int:
    from beyond_self.cognition.gestures.benchmark import ARTICLE_MODELS, compare_on_recordings
    from beyond_self.cognition.gestures.evaluation import plot_report
    from beyond_self.cognition.paths import data_set
    from beyond_self.core.errors import InputError

    folder = Path(data_set(args.data))
    if not folder.is_dir():
        raise InputError(f"{folder} is not a folder; 'compare' needs a folder of hand recordings")
    article_path = args.article or folder / ARTICLE_MODELS
    article = models_from(str(article_path)) if article_path.is_file() else None
    console = Console(stderr=True)
    with progress_bar(console) as progress:
        task = progress.add_task("evaluations", total=6 if article is not None else 5)
        entries = compare_on_recordings(
            folder,
            default=models_from("default"),
            article=article,
            config=training_config(args),
            n_synthetic=args.count,
            seed=args.seed,
            push_as=args.push_as or "touch",
            on_step=lambda name: progress.advance(task),
        )
    plots = {e.name: plot_report(e.report, args.output / e.name, title=e.name) for e in entries}
    if args.json:
        out = {e.name: {"what": e.what, **e.report.to_dict()} for e in entries}
        for name, paths in plots.items():
            out[name]["plots"] = [str(p) for p in paths]
        json.dump(out, sys.stdout)
        sys.stdout.write("\n")
        return 0
    out_console = Console(width=None if sys.stdout.isatty() else 120)
    summary = Table(title=f"gesture models on {folder}")
    for name in ("evaluation", "what", "gestures", "accuracy", "at 60%"):
        summary.add_column(name, justify="right" if name not in ("evaluation", "what") else "left")
    for e in entries:
        r = e.report
        summary.add_row(e.name, e.what, str(r.n), f"{r.accuracy:.1%}", f"{r.accuracy_at(0.6):.1%}")
    out_console.print(summary)
    for e in entries:
        show_report(out_console, e.report, title=e.name)
    out_console.print(f"plots in {args.output}/<evaluation>/")
    return 0


def realism_command(args: argparse.Namespace, gestures: Gestures) -> int:
    from beyond_self.cognition.gestures.datasets import synthetic_gestures
    from beyond_self.cognition.gestures.realism import MEASURES, compare_gestures, plot_profiles

    console = Console(stderr=True)
    with console.status("measuring recorded and synthetic gestures"):
        recorded = gestures(args, args.data)
        synthetic = synthetic_gestures(args.count, args.seed)
        rows = compare_gestures(recorded, synthetic)
    plot = plot_profiles(recorded, synthetic, args.output / "realism.png")
    out = Console(width=None if sys.stdout.isatty() else 140)
    table = Table(title="recorded vs synthetic gestures (mean ± sd; u = body units)")
    table.add_column("measure", no_wrap=True)
    for r in rows:
        table.add_column(f"{r.action} recorded ({r.n_recorded})", justify="right")
        table.add_column(f"{r.action} synthetic ({r.n_synthetic})", justify="right")
    for key, (unit, what) in MEASURES.items():
        cells = []
        for r in rows:
            for side in (r.recorded, r.synthetic):
                mean, sd = side[key]
                cells.append(f"{mean:.2f} ± {sd:.2f}")
        table.add_row(f"{what} ({unit})", *cells)
    table.add_row(
        "trajectory distance (u)", *[c for r in rows for c in (f"{r.shape_distance:.2f}", "")]
    )
    out.print(table)
    out.print(f"trajectories: {plot}")
    return 0
