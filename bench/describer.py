"""The description generator on its own: final word probabilities in, its description out, next
to two raw Zenoh hops measured in the same run.

    .venv/bin/python bench/describer.py [--load N] [--fleet]

bench/fleet.py times the description stage from the words leaving the reasoner to the
description's arrival; with one robot it was 13 ms, while the N-best search takes 0.5 ms. This
says how much of that is the generator's own path (two bus hops, decoding, the exactly-once
ledger, the search, encoding): it runs the `describer` service alone as a process (`--fleet`: as
a fleet's, serving one robot), publishes a gesture's final words, waits for the description,
and repeats, one at a time, so nothing else competes for the cores but `--load N` spinners.
Ends with one line of JSON.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO / "tests"))

from busutil_net import busy_loops  # noqa: E402
from pipeline import QUIET, _p, raw_hop_us  # noqa: E402

import beyond_self.schemas as s  # noqa: E402
from beyond_self.runtime.bus.config import BusConfig  # noqa: E402
from beyond_self.runtime.bus.delivery import EVENTS  # noqa: E402
from beyond_self.runtime.fleet import LEAVE_ENV  # noqa: E402
from beyond_self.services import shared  # noqa: E402
from beyond_self.services.deployment import Deployment  # noqa: E402

ROUNDS = 200


async def round_trips(config: BusConfig, robot: str, rounds: int) -> list[float]:
    """Milliseconds from publishing final words for `robot` to receiving its description."""
    side = Deployment(config, ["describer"], env={**QUIET, LEAVE_ENV: "1"})
    try:
        bus = await side.open()
        await side.start()
        view = bus.for_robot(robot)
        leave = view.declare_token(view.keys.alive("ingest"))  # a fleet serves robots it sees
        await bus.wait_alive(view.keys.alive("describer"), timeout=60)
        words = shared.network(None).word_probabilities({"Action": "tap", "Shape": "circle"})
        pub = view.publisher(view.keys.words, s.WordProbabilities, EVENTS)
        out = view.subscribe(view.keys.description, s.Description, EVENTS)
        took = []
        for i in range(1, rounds + 1):
            header = s.Header(version=1, source="bench", seq=i, stamp=10**18 + i * 10**9)
            msg = s.WordProbabilities(header=header, segment_id=i, words=words, final=True)
            began = time.perf_counter()
            pub.put(msg)
            got = await out.recv(timeout=30)
            took.append((time.perf_counter() - began) * 1e3)
            assert got.message.segment_id == i, (got.message.segment_id, i)
        leave()
        view.close()
        return took
    finally:
        await side.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--load", type=int, default=0, metavar="N", help="busy-looping processes")
    parser.add_argument("--fleet", action="store_true", help="a fleet's describer, one robot")
    args = parser.parse_args()
    port = 17600 + os.getpid() % 1000
    if args.fleet:
        config, robot = BusConfig(robot="ws", robots="bench-*", port=port), "bench-1"
    else:
        config, robot = BusConfig(robot="bench", port=port), "bench"
    with busy_loops(args.load):
        hop_ms = raw_hop_us(BusConfig(robot="hop", port=port + 1)) / 1e3
        took = asyncio.run(round_trips(config, robot, ROUNDS))
    p50, p99 = _p(took, 50), _p(took, 99)
    print(f"describer round trip ({'fleet, one robot' if args.fleet else 'one robot'}, "
          f"{args.load} busy loops): p50 {p50:.2f} ms, p99 {p99:.2f} ms; two raw Zenoh hops "
          f"{2 * hop_ms:.2f} ms; ratio p50 / two hops {p50 / (2 * hop_ms):.1f}")  # fmt: skip
    figures: dict[str, Any] = {
        "bench": "describer",
        "fleet": args.fleet,
        "load": args.load,
        "rounds": len(took),
        "round_trip_p50_ms": round(p50, 3),
        "round_trip_p99_ms": round(p99, 3),
        "raw_two_hops_ms": round(2 * hop_ms, 3),
        "ratio_p50_to_raw": round(p50 / (2 * hop_ms), 2),
    }
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
