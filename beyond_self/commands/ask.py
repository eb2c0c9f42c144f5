"""`beyond ask`: ask the running affordance reasoner a question over the bus.

beyond ask --query VAR [VAR ...] [--evidence VAR=VALUE ...] [--soft VAR=value:p,value:p ...]
           [--gesture ACTION=p,...] [--json] [bus options]

The evidence options are those of `beyond bn query` (beyond/commands/evidence_args.py), less
--gesture-log: the recogniser runs in the pipeline, not here.
"""

from __future__ import annotations

import argparse
import asyncio
import json

from rich.console import Console
from rich.table import Table

from beyond_self.commands import argtypes
from beyond_self.commands.evidence_args import add_evidence_arguments, parse_evidence_args
from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.bus.subscription import Received
from beyond_self.schemas import AffordanceAnswer, AffordanceQuery, Header

HELP = "query the running affordance reasoner (exact posterior, with optional gesture evidence)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--query", nargs="+", required=True, metavar="VAR", help="variables to ask about (joint)"
    )
    add_evidence_arguments(parser, gesture_log=False)
    parser.add_argument(
        "--timeout",
        type=argtypes.seconds(),
        default=3.0,
        help="seconds to wait for the reasoner's answer (default 3)",
    )
    parser.add_argument("--json", action="store_true", help="print the answer as JSON")
    add_bus_arguments(parser)


def build_query(args: argparse.Namespace) -> AffordanceQuery:
    """The question as the reasoner takes it: evidence by name, checked against its network
    by the same `cognition.bn.evidence.build_evidence` that `beyond bn query` runs."""
    evidence = parse_evidence_args(args)
    header = Header(version=AffordanceQuery.VERSION, source="ask", seq=0, stamp=0)
    return AffordanceQuery(
        header=header,
        query=list(args.query),
        evidence=dict(evidence.hard),
        soft={name: dict(dist) for name, dist in evidence.soft.items()},
        gesture=dict(evidence.gesture),
    )


async def ask(args: argparse.Namespace) -> AffordanceAnswer:
    query = build_query(args)
    with Bus.open(config_from_args(args)) as bus:
        replies = await _ask_until(bus, query, args.timeout)
    if not replies:
        raise InputError(
            f"no affordance reasoner answered on {bus.keys.ask} within {args.timeout} s; "
            "start one with `beyond service reasoner` or `beyond up`"
        )
    return replies[0].message


async def _ask_until(
    bus: Bus, query: AffordanceQuery, timeout: float
) -> list[Received[AffordanceAnswer]]:
    """Ask until a reasoner answers or `timeout` is over.

    A session just opened has not yet learnt of the reasoner's queryable: a query then finds no
    one and ends at once with no reply (7 times out of 12, asked right away). So ask again, a
    little later each time, for as long as the user allowed."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    pause = 0.02
    while True:
        remaining = deadline - loop.time()
        replies = await bus.query(
            bus.keys.ask, AffordanceAnswer, payload=query, timeout=max(remaining, 0.01)
        )
        remaining = deadline - loop.time()
        if replies or remaining <= 0:
            return replies
        await asyncio.sleep(min(pause, remaining))
        pause = min(2 * pause, 0.25)


def run(args: argparse.Namespace) -> int:
    answer = asyncio.run(ask(args))
    if args.json:
        rows = [{"assignment": r.assignment, "p": r.p} for r in answer.rows]
        print(json.dumps({"variables": answer.variables, "rows": rows}))
        return 0
    table = Table(title=f"P({', '.join(answer.variables)} | evidence)")
    for v in answer.variables:
        table.add_column(v)
    table.add_column("p", justify="right")
    for row in answer.rows:
        table.add_row(*(row.assignment[v] for v in answer.variables), f"{row.p:.6f}")
    Console().print(table)
    return 0
