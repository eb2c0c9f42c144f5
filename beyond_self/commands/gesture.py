"""`beyond gesture`: train, run and evaluate the per-action gesture HMMs.

    beyond gesture train [--data synthetic|DIR] -o MODELS.json
    beyond gesture stream MODELS LOG [--frames A:B] [--scale S] [--json]
    beyond gesture evaluate MODELS|cv DATA [--json] [-o DIR]

MODELS is a model file written by `train` or one of the article's MATLAB files. DATA is
`synthetic` (the seeded generator), a folder of hand recordings named <action><n>... (the
article's human_data/: grasp1_hand, tap1_hand, touch1_hand), cut into repetitions by the
segmenter, or MCAP recordings (a .mcap file or a folder of them) of skeleton frames on
beyond/<robot>/sensors/skeleton with joints `right_hand` (and `torso`). An MCAP recording's
labels come from its "beyond" metadata, `gesture_actions` = "grasp,tap,..." (one per gesture, in
order) and optionally `gesture_frames` = "start:stop,..." (0-based, over its skeleton frames;
otherwise the segmenter cuts it), or else from its file name (tap_1.mcap: every gesture a tap).
`evaluate cv DATA` runs leave-one-gesture-out cross-validation instead of testing a model set.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

from beyond_self.cognition.gestures.datasets import (
    SYNTHETIC,
    action_from_name,
    load_gestures,
    skeleton_gestures,
)
from beyond_self.cognition.gestures.evaluation import LabelledGesture
from beyond_self.cognition.gestures.features import LOG_SCALE, extract_features
from beyond_self.cognition.gestures.hmm import load_models, save_models, train_models
from beyond_self.cognition.gestures.logs import parse_frames, read_hand_log
from beyond_self.commands import argtypes
from beyond_self.commands.hmm_options import add_training_options, training_config
from beyond_self.commands.terminal import progress_bar
from beyond_self.core.errors import InputError

HELP = "train, run (frame by frame) and evaluate the gesture HMMs"

TRAIN_SEED = 0
EVAL_SEED = 1  # evaluate's synthetic default: held-out gestures, never seen by `train`


def _progress(console: Console) -> Progress:
    return progress_bar(console)


def _data_args(p: argparse.ArgumentParser, seed: int) -> None:
    p.add_argument(
        "--count",
        type=argtypes.count(1, 100_000),
        default=30,
        help="synthetic gestures per action (default 30)",
    )
    argtypes.add_seed(p, f"synthetic data seed (default {seed})", default=seed)
    p.add_argument(
        "--push-as",
        choices=("grasp", "tap", "touch"),
        default=None,
        help="count push recordings as this action (default: leave them out)",
    )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="gesture_command", metavar="SUBCOMMAND", required=True)

    train = sub.add_parser("train", help="train one left-to-right GMM-HMM per action")
    train.add_argument(
        "--data",
        default=SYNTHETIC,
        help="'synthetic' (default), a folder of hand recordings (grasp1_hand/ ...), "
        "or MCAP recordings (a .mcap file or a folder of them)",
    )
    argtypes.add_output(train, "model file to write (.json)", required=True, old="--out")
    add_training_options(train, mix=3, iterations=30, states="HMM states per action")
    _data_args(train, TRAIN_SEED)

    stream = sub.add_parser("stream", help="run the streaming recogniser over a hand log")
    stream.add_argument("models", type=Path, help="model file (.json) or the article's .mat")
    stream.add_argument("log", type=Path, help="recording folder or its data.log")
    stream.add_argument("--frames", default=None, help="A:B, 1-based inclusive (default: all)")
    stream.add_argument(
        "--scale",
        type=argtypes.number(float, lo=0, hi=1e6, lo_open=True),
        default=LOG_SCALE,
        help=f"multiply logged positions by S (default {LOG_SCALE}: logs -> model units)",
    )
    stream.add_argument("--json", action="store_true", help="print JSON instead of a table")
    stream.add_argument("--priors", default=None, help="action priors, comma separated")
    stream.add_argument(
        "--garbage", action="store_true", help="add the garbage model as a class, if loaded"
    )
    stream.add_argument(
        "--plot", type=argtypes.output_file, default=None, help="also write a PNG plot here"
    )

    ev = sub.add_parser("evaluate", help="accuracy, confusion and early recognition")
    ev.add_argument("models", help="model file, or 'cv' for leave-one-gesture-out cross-validation")
    ev.add_argument("data", help="'synthetic', a folder of hand recordings, or MCAP recordings")
    ev.add_argument("--json", action="store_true", help="print the report as JSON")
    argtypes.add_output(
        ev,
        "folder for the PNG plots (default ./gesture-evaluation)",
        folder=True,
        default=Path("gesture-evaluation"),
        old="--out",
    )
    add_training_options(ev, mix=3, iterations=30, states="HMM states per action")
    _data_args(ev, EVAL_SEED)


def run(args: argparse.Namespace) -> int:
    handlers = {"train": _train, "stream": _stream, "evaluate": _evaluate}
    return handlers[args.gesture_command](args)


def _mcap_gestures(path: Path, push_as: str | None) -> list[LabelledGesture]:
    """Labelled gestures of one MCAP recording (labels: see the module docstring)."""
    from beyond_self.runtime.recording import inspect_recording, read_recording
    from beyond_self.schemas.keys import STREAMS
    from beyond_self.schemas.messages import SkeletonFrame

    suffix = "/" + STREAMS["skeleton"][0]
    meta = inspect_recording(path).metadata.get("beyond", {})
    frames = [
        msg
        for item in read_recording(path)
        if item.key.endswith(suffix) and isinstance(msg := item.message(), SkeletonFrame)
    ]
    if not frames:
        raise InputError(f"{path} holds no skeleton frames (keys ending in {suffix})")
    names = set.intersection(*(set(f.joints) for f in frames))
    if "right_hand" not in names:
        raise InputError(f"{path}: the joint 'right_hand' is not in every skeleton frame")
    joints: dict[str, np.ndarray] = {
        n: np.array([f.joints[n].position for f in frames], dtype=np.float64)
        for n in ("right_hand", "torso")
        if n in names
    }
    if meta.get("gesture_actions"):
        actions = [a.strip() for a in meta["gesture_actions"].split(",")]
    else:
        label = action_from_name(path.name, push_as)
        if label is None:
            raise InputError(
                f"{path}: no gesture labels; add metadata gesture_actions or name the file "
                "<action>....mcap"
            )
        actions = [label]
    bounds = None
    if meta.get("gesture_frames"):
        try:
            bounds = [
                (int(a), int(b))
                for a, b in (p.split(":") for p in meta["gesture_frames"].split(","))
            ]
        except ValueError:
            raise InputError(
                f"{path}: metadata gesture_frames {meta['gesture_frames']!r}; valid: 'a:b,c:d'"
            ) from None
    return skeleton_gestures(joints, actions, bounds=bounds, source=path.name)


def _gestures(args: argparse.Namespace, spec: str) -> list[LabelledGesture]:
    """DATA as labelled gestures: synthetic, recording folders, or MCAP recordings."""
    path = Path(spec)
    mcaps = [path] if path.suffix.lower() == ".mcap" else []
    if not mcaps and spec != SYNTHETIC and path.is_dir() and not (path / "data.log").exists():
        mcaps = sorted(path.glob("*.mcap"))
    if not mcaps:
        return load_gestures(spec, n_per_action=args.count, seed=args.seed, push_as=args.push_as)
    out: list[LabelledGesture] = []
    for p in mcaps:
        if not p.is_file():
            raise InputError(f"{p} does not exist; valid: an MCAP recording")
        out.extend(_mcap_gestures(p, args.push_as))
    return out


def _train(args: argparse.Namespace) -> int:
    console = Console(stderr=True)
    if args.output.suffix.lower() != ".json":
        raise InputError(f"--output {args.output} must end in .json")
    cfg = training_config(args)
    with console.status(f"loading gestures from {args.data}"):
        gestures = _gestures(args, args.data)
    data: dict[str, list[Any]] = {}
    for g in gestures:
        data.setdefault(g.action, []).append(g.features)
    with _progress(console) as progress:
        task = progress.add_task("training HMMs", total=len(data))
        models = train_models(
            data,
            cfg,
            meta={"data": str(args.data), "seed": args.seed if args.data == SYNTHETIC else None},
            on_model=lambda a: progress.advance(task),
        )
    save_models(models, args.output)
    counts = ", ".join(f"{a} {len(data[a])}" for a in models.actions)
    console.print(f"wrote {args.output}: {len(models.actions)} models ({counts} gestures)")
    return 0


def _parse_priors(text: str | None, n: int) -> list[float] | None:
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"--priors {text!r}; valid: {n} comma-separated numbers") from None
    if len(values) != n:
        raise InputError(f"--priors has {len(values)} values; valid: {n}, one per action")
    return values


def _stream(args: argparse.Namespace) -> int:
    from beyond_self.cognition.gestures.streaming import StreamingRecognizer

    models = load_models(args.models, include_garbage=args.garbage)
    log = read_hand_log(args.log)
    span = parse_frames(args.frames, len(log))
    feats = extract_features(log.xyz[span], scale=args.scale)
    rec = StreamingRecognizer(models, priors=_parse_priors(args.priors, len(models.actions)))
    results = [rec.push(x) for x in feats]
    first = span.start + 1
    if args.json:
        out = {
            "actions": list(models.actions),
            "first_frame": first,
            "frames": [r.to_dict() for r in results],
        }
        json.dump(out, sys.stdout)
        sys.stdout.write("\n")
    else:
        console = Console(width=None if sys.stdout.isatty() else 200)  # a table is never cut
        table = Table(title=f"{args.log} frames {first}-{span.stop}, scale {args.scale:g}")
        table.add_column("frame", justify="right")
        table.add_column("t", justify="right")
        for a in models.actions:
            table.add_column(f"P({a})", justify="right")
        for a in models.actions:
            table.add_column(f"log L {a}", justify="right")
        for r in results:
            best = int(np.argmax(r.posterior))
            cells = [
                f"[bold]{p:.3f}[/bold]" if i == best else f"{p:.3f}"
                for i, p in enumerate(r.posterior)
            ]
            table.add_row(str(first + r.t - 1), str(r.t), *cells, *(f"{v:.2f}" for v in r.loglik))
        console.print(table)
        console.print(f"most probable action after {len(results)} frames: [bold]{results[-1].best}")
    if args.plot is not None:
        from beyond_self.cognition.gestures.evaluation import plot_stream
        from beyond_self.cognition.gestures.streaming import recognize_sequence

        plot_stream(recognize_sequence(rec.compiled, feats), args.plot, str(args.log), first)
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from beyond_self.cognition.gestures.evaluation import cross_validate, evaluate, plot_report

    console = Console(stderr=True)
    with console.status(f"loading gestures from {args.data}"):
        gestures = _gestures(args, args.data)
    with _progress(console) as progress:
        if args.models == "cv":
            task = progress.add_task("cross-validation folds", total=len(gestures))
            report = cross_validate(
                gestures, training_config(args), on_fold=lambda: progress.advance(task)
            )
        else:
            models = load_models(args.models)
            task = progress.add_task("recognising gestures", total=len(gestures))
            report = evaluate(models, gestures, on_gesture=lambda: progress.advance(task))
    report.meta["data"] = str(args.data)
    report.meta["models"] = str(args.models)
    plots = plot_report(report, args.output, title=Path(str(args.data)).name)
    if args.json:
        out = report.to_dict()
        out["plots"] = [str(p) for p in plots]
        json.dump(out, sys.stdout)
        sys.stdout.write("\n")
        return 0
    console = Console()
    console.print(
        f"{report.meta['protocol']}: {report.n} gestures, accuracy [bold]{report.accuracy:.1%}"
    )
    conf = Table(title="confusion (rows: true, columns: predicted)")
    conf.add_column("")
    for a in report.actions:
        conf.add_column(a, justify="right")
    for a, row in zip(report.actions, report.confusion, strict=True):
        conf.add_row(a, *(str(int(v)) for v in row))
    console.print(conf)
    early = Table(title="early recognition: accuracy after seeing part of each gesture")
    for f in report.fractions:
        early.add_column(f"{f:.0%}", justify="right")
    early.add_row(*(f"{a:.0%}" for a in report.early_accuracy))
    console.print(early)
    console.print(
        f"accuracy at 60%: {report.accuracy_at(0.6):.1%}; plots: {', '.join(map(str, plots))}"
    )
    return 0
