"""Where a burst's CPU goes: per robot and stage, the fleet processes' CPU next to the science's.

    .venv/bin/python bench/burst.py [--robots 16,32] [--gestures 3] [--repeat 1]

The skeleton-only fleet of bench/fleet.py (gesture streamer, reasoner told there is no object
segmenter, describer: one process each) serves N robots fed the same stream (bench/fleet.py's
`aligned` case: every robot's gestures end within one frame, each stage gets N gestures at
once). Per stage, the process's CPU over the stream divided by N (ms per robot) and, as the
reference measured in the same run, the science of that stage alone on the same stream in this
process (ms per robot, one thread's CPU): the gesture tracker (segmenter, streaming HMMs), the
fusion join (every belief fused, each gesture's outcome and words), the N-best search. The ratio
science / stage is the share a faster or batched science could cut; the rest is each message's
path through the runtime (receive, decode, ledger, publish) and each run's start. Also the
description p99 and the per-stage p99 (bench/fleet.py's). Progress to stderr; ends with one line
of JSON.
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
sys.path.insert(0, str(REPO / "bench"))

from fleet import (  # noqa: E402
    LEAVE_ENV,
    OPTIONS,
    SERVICES,
    _with_children,
    process_cost,
    serve,
    streams_for,
)
from pipeline import QUIET, _p, stream_frames  # noqa: E402

from beyond_self.cognition.descriptions import nbest_exact  # noqa: E402
from beyond_self.cognition.episodes import (  # noqa: E402
    Belief,
    Ended,
    FusionJoin,
    GestureTracker,
    Outcome,
    Started,
)
from beyond_self.cognition.episodes.tracker import hand_position  # noqa: E402
from beyond_self.runtime.bus.config import BusConfig  # noqa: E402
from beyond_self.services import shared  # noqa: E402
from beyond_self.services.deployment import Deployment  # noqa: E402


def science_ms(gestures: int, nbest: int = 5) -> dict[str, float]:
    """One robot's stream through the three stages' library calls, in this process: CPU ms per
    stage (this thread's), as the services call them (a tracker and a join per robot)."""
    frames, _ = stream_frames(seed=7, gestures=gestures)
    models, network = shared.gesture_models(None), shared.network(None)
    actions = list(models.actions)
    tracker: GestureTracker[None] = GestureTracker(models)
    join: FusionJoin[None] = FusionJoin(network, expect_objects=False)
    spent = {"gestures": 0.0, "reasoner": 0.0, "describer": 0.0}
    clock = time.thread_time
    for i, frame in enumerate(frames):
        stamp = i + 1
        t0 = clock()
        hand, torso = frame.joints["right_hand"], frame.joints.get("torso")
        x = hand_position(hand.position, torso.position if torso else None, "frame")
        events = tracker.push(stamp, frame.frame, x, None)
        t1 = clock()
        spent["gestures"] += t1 - t0
        for ev in events:
            t0 = clock()
            if isinstance(ev, Belief):
                belief = dict(zip(actions, ev.posterior, strict=True))
                outs = join.belief(ev.segment_id, ev.frame, stamp, belief, None, ev.final)
            elif isinstance(ev, Started):
                outs = join.started(ev.segment_id, ev.stamp)
            elif isinstance(ev, Ended):
                outs = join.ended(ev.segment_id, ev.start_stamp, ev.end_stamp)
            else:
                outs = []
            t1 = clock()
            spent["reasoner"] += t1 - t0
            for out in outs:
                if isinstance(out, Outcome):
                    t0 = clock()
                    nbest_exact(out.words, nbest)
                    spent["describer"] += clock() - t0
    return {k: round(v * 1e3, 2) for k, v in spent.items()}


async def fleet_round(n: int, gestures: int, port: int) -> dict[str, Any]:
    """N robots, the same stream, into one process per stage: CPU per robot per stage."""
    config = BusConfig(robot="ws", robots=f"b{n}-*", port=port)
    robots = [f"b{n}-{k}" for k in range(n)]
    side = Deployment(config, SERVICES, options=OPTIONS, env={**QUIET, LEAVE_ENV: "1"})
    try:
        bus = await side.open()
        await side.start()
        pids = {sp.name: sp.process.pid for sp in side.processes}
        before = {name: process_cost(_with_children([pid]))[2] for name, pid in pids.items()}
        served = await serve(bus, robots, streams_for(n, gestures, True))
        after = {name: process_cost(_with_children([pid]))[2] for name, pid in pids.items()}
    finally:
        await side.stop()
    lat = served["latency_ms"]
    return {
        "robots": n,
        "description_p99_ms": round(_p(lat, 99), 2),
        "stage_p99_ms": {k: round(_p(v, 99), 2) for k, v in served["stages_ms"].items()},
        "cpu_ms_per_robot": {k: round((after[k] - before[k]) * 1e3 / n, 1) for k in pids},
    }


async def main_async(args: argparse.Namespace) -> dict[str, Any]:
    port = 18300 + os.getpid() % 1000
    science = science_ms(args.gestures)  # warm: models loaded, tables compiled
    runs: list[dict[str, Any]] = []
    for _ in range(args.repeat):
        for n in args.robots:
            reference = science_ms(args.gestures)
            print(f"burst: {n} robot(s) ...", file=sys.stderr, flush=True)
            got = await fleet_round(n, args.gestures, port)
            stages = got["cpu_ms_per_robot"]
            got["science_ms_per_robot"] = reference
            got["science_share"] = {
                k: round(reference[k] / stages[k], 3) if stages.get(k) else None for k in reference
            }
            runs.append(got)
            print(json.dumps(got), file=sys.stderr, flush=True)
    return {"gestures": args.gestures, "science_warmup_ms": science, "rounds": runs}


def print_table(result: dict[str, Any]) -> None:
    print(f"{'robots':>6}  {'stage':<10} {'CPU ms/robot':>12} {'science ms':>10} {'share':>6}")
    for r in result["rounds"]:
        for stage, cpu in r["cpu_ms_per_robot"].items():
            sci, share = r["science_ms_per_robot"][stage], r["science_share"][stage]
            print(f"{r['robots']:>6}  {stage:<10} {cpu:>12.1f} {sci:>10.2f} {share:>6.3f}")
        p99 = r["description_p99_ms"]
        print(f"{'':>6}  description p99 {p99} ms; per stage {r['stage_p99_ms']}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", default="16,32", help="robot counts, comma-separated")
    parser.add_argument("--gestures", type=int, default=3, help="gestures per robot")
    parser.add_argument("--repeat", type=int, default=1, help="rounds of each robot count")
    args = parser.parse_args()
    args.robots = [int(x) for x in args.robots.split(",")]
    result = asyncio.run(main_async(args))
    print_table(result)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
