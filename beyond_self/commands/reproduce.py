"""`beyond reproduce`: re-run the article's experiments on its real data and write a report.

    beyond reproduce [--data DIR] -o DIR

--data defaults to $BEYOND_DATA, else the `shared/data` folder beside the project; a folder given
is relative to the current folder. Writes report.md, one PNG per figure and results.json; takes a
few seconds. The experiments run on the default network (unseen word columns: P(absent) = 1);
section 7 of the report re-runs every figure the article prints numbers for under --unseen absent
and zero (the reference toolbox's all-zero columns), checks each against the article and says which
rule it needs (Table II exists only under zero).
"""

from __future__ import annotations

import argparse
import time

from rich.console import Console

from beyond_self.cognition.paths import SOURCES, shared_data_dir
from beyond_self.commands import argtypes
from beyond_self.commands.terminal import progress_bar
from beyond_self.core.errors import InputError

HELP = (
    "re-run the article's experiments 1-6 and check its published figures under each rule for "
    "unseen word columns; write report.md, PNGs, JSON"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--data",
        type=argtypes.data_folder,
        metavar="DIR",
        help="the article's data folder (default: $BEYOND_DATA, else shared/data beside the "
        "project)",
    )
    argtypes.add_output(
        parser,
        "folder to write report.md, results.json and the plots into",
        folder=True,
        required=True,
        old="--out",
    )


def run(args: argparse.Namespace) -> int:
    from beyond_self.cognition.reproduction import run_all, write_report

    data = args.data or shared_data_dir()
    if data is None:
        raise InputError(
            "no data folder: give --data DIR, set BEYOND_DATA=DIR, or put the article's data "
            f"in ../shared/data beside the project; it comes from {SOURCES}"
        )
    if not data.is_dir():
        raise InputError(
            f"data folder {data} does not exist; give --data (or BEYOND_DATA) the folder that "
            f"holds salvi2012/ and saponaro2019/, which come from {SOURCES}"
        )
    console = Console(stderr=True)
    start = time.perf_counter()
    with progress_bar(console) as progress:
        task = progress.add_task("starting", total=None)

        def step(text: str) -> None:  # a step begins: the one before is done
            if progress.tasks[0].description != "starting":
                progress.advance(task)
            progress.update(task, description=text)

        results = run_all(data, progress=step)
        step("writing the report and the plots")
        report = write_report(results, args.output)
    console.print(f"wrote {report}, results.json and plots in {time.perf_counter() - start:.1f} s")
    print(report)
    return 0
