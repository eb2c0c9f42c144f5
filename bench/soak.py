"""Soak: the pipeline looping a recording for minutes while its services are killed one after
another, as `beyond up` runs it: resident memory stays flat, and no description is lost or
repeated (issue 21).

What runs: the six services as processes on a private loopback bus (services.deployment, with
its restart policy: what dies is started again), the ingest replaying a shipped recording with
`loop: true` (each pass restamped after the last, so it plays for ever), a PipelineMonitor
printing the gesture lines (as `beyond up`), and a subscriber counting every Description on the
bus. Every `--kill-every` seconds one service, the next of a seeded order of all six, is killed
with SIGKILL. Every 5 s the resident memory (VmRSS) of every service process and of this
process is read from /proc.

What is checked, at the end (after the last gesture that ended is described):
- lost: a gesture that ended without a description; repeated: a description published more
  than once, or a sentence said more than once (the speech service's log);
- the lines: every gesture's block equals the block `beyond analyse` prints for the same
  gesture of the recording (a looped recording repeats its gestures: checked offline first);
- memory: the sum over the processes of their resident memory, its median over the first and
  the last fifth of the run, and its least-squares slope in MB per minute (the processes killed
  restart small, so the sum is over what is alive at each sample; the reference measured in the
  same run is the first fifth). A service that kept something per gesture without bound would
  grow by its size per gesture, pass after pass.

    .venv/bin/python bench/soak.py [--duration 600] [--kill-every 30] [--rate 1]

Prints the figures and ends with one line of JSON holding all of them.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import random
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import beyond_self.schemas as s  # noqa: E402
from beyond_self.commands.analyse import default_run, looped_inputs  # noqa: E402
from beyond_self.monitor import PipelineMonitor  # noqa: E402
from beyond_self.runtime.bus.config import BusConfig  # noqa: E402
from beyond_self.runtime.bus.delivery import FRAMES  # noqa: E402
from beyond_self.services.deployment import Deployment  # noqa: E402

RECORDINGS = REPO / "recordings"
SERVICES = ["gestures", "objects", "reasoner", "describer", "speech", "ingest"]
SAMPLE_S = 5.0


def rss_mb(pid: int) -> float:
    """Resident memory of process `pid` in MB (0 if it is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def blocks(lines: list[str]) -> dict[int, list[str]]:
    """Each gesture's lines, without their "gesture N:" prefix."""
    out: dict[int, list[str]] = {}
    for line in lines:
        head, _, text = line.partition(": ")
        out.setdefault(int(head.split()[1]), []).append(text)
    return out


def expected_blocks(recording: Path, passes: int = 3) -> list[list[str]]:
    """The gesture blocks of one pass of `recording`, after checking offline that a looped
    recording repeats them pass after pass (what the soak compares every gesture with)."""
    run = default_run(looped_inputs(recording, passes))
    by_gesture = blocks(run.lines)
    per_pass = len(by_gesture) // passes
    assert per_pass > 0 and len(by_gesture) == per_pass * passes, sorted(by_gesture)
    first = [by_gesture[g] for g in range(1, per_pass + 1)]
    for k in range(1, passes):
        again = [by_gesture[k * per_pass + g] for g in range(1, per_pass + 1)]
        assert again == first, "a looped recording tells its gestures alike on every pass"
    return first


def ended_ids(monitor: PipelineMonitor, lines: list[str]) -> set[int]:
    """Gestures that ended: printed ones (the report forgets old ones on a long run) and those
    still waiting for their description."""
    printed = {n for n, block in blocks(lines).items() if any("ended at" in t for t in block)}
    waiting = {n for n, g in monitor.report.gestures.items() if g.end_frame is not None}
    return printed | waiting


def slope_per_min(samples: list[tuple[float, float]]) -> float:
    """Least-squares slope of (seconds, MB) samples, in MB per minute."""
    if len(samples) < 2:
        return 0.0
    ts = [t for t, _ in samples]
    ms = [m for _, m in samples]
    mt, mm = statistics.fmean(ts), statistics.fmean(ms)
    var = sum((t - mt) ** 2 for t in ts)
    return 60 * sum((t - mt) * (m - mm) for t, m in samples) / var if var else 0.0


async def soak(
    *,
    duration_s: float,
    kill_every_s: float | None,
    rate: float,
    recording: Path,
    seed: int = 0,
    out: Path | None = None,
    port: int | None = None,
    say: Any = print,
    at_least: tuple[int, int] = (0, 0),
    give_up_s: float = 300.0,
) -> dict[str, Any]:
    """Run the soak; its figures (and what it checked) as a dict. `kill_every_s` None: a kill
    each time a gesture was described since the last one and every service is back (the
    suite's short run: as many kills however loaded the machine). `at_least`: (gestures
    described, services killed) the run goes on for, past `duration_s` if need be, for at most
    `give_up_s`."""
    expected = expected_blocks(recording)
    out = out or Path(tempfile.mkdtemp(prefix="soak-"))
    lines: list[str] = []
    described: dict[int, int] = {}
    told: list[str] = []
    config = BusConfig(robot=f"soak{os.getpid()}", port=port or 17900 + os.getpid() % 1000)
    pipeline = Deployment(
        config,
        SERVICES,
        options={
            "ingest": {"recording": str(recording), "rate": rate, "loop": True},
            "speech": {"out_dir": str(out)},
        },
        watcher="monitor",
        clock="recording",
        env={
            "BEYOND_LOG_FORMAT": "text",
            "BEYOND_LOG_LEVEL": os.environ.get("SOAK_LOG", "WARNING"),
        },
        on_restart=lambda name, what: told.append(f"{name}: {what}"),
        log=lambda name, line: print(f"[{name}] {line}", file=sys.stderr, flush=True),
    )
    bus = await pipeline.open()
    monitor = PipelineMonitor.of(pipeline, bus, lines.append)
    monitor.start()

    async def capture() -> None:
        async for received in bus.subscribe(bus.keys.description, s.Description, FRAMES):
            sid = received.message.segment_id
            described[sid] = described.get(sid, 0) + 1

    loop = asyncio.get_running_loop()
    capturing = loop.create_task(capture())
    order = list(SERVICES)
    random.Random(seed).shuffle(order)
    kills: list[str] = []
    memory: list[tuple[float, float]] = []
    began = loop.time()
    try:
        await pipeline.start()
        began = loop.time()
        next_kill, next_sample = began + (kill_every_s or 0.0), began
        described_at_kill = 0
        want_described, want_kills = at_least

        def going() -> bool:
            elapsed = loop.time() - began
            short = len(described) < want_described or len(kills) < want_kills
            return elapsed < duration_s or (short and elapsed < give_up_s)

        while going():
            now = loop.time()
            if now >= next_sample:
                pids = [p.process.pid for p in pipeline.processes if p.running]
                memory.append((now - began, sum(map(rss_mb, [os.getpid(), *pids]))))
                next_sample += SAMPLE_S
                ended = len(ended_ids(monitor, lines))
                say(f"  {now - began:6.1f} s: {ended} gestures ended, {len(described)} "
                    f"described, {len(kills)} kills, {memory[-1][1]:.0f} MB")  # fmt: skip
            if kill_every_s is not None:
                due = now >= next_kill
            else:  # one kill per gesture described, everything alive again since the last
                alive = all(p.running for p in pipeline.processes)
                due = alive and len(described) > described_at_kill
            if due:
                name = order[len(kills) % len(order)]
                victim = next(p for p in pipeline.processes if p.name == name)
                if victim.running:
                    victim.process.kill()
                    kills.append(name)
                    described_at_kill = len(described)
                next_kill += kill_every_s or 0.0
            assert not pipeline.exited(), (pipeline.exited(), told)
            await asyncio.sleep(0.2)
        # drain: every gesture that ended is described, and said
        deadline = loop.time() + 120
        while loop.time() < deadline:
            ended = sorted(ended_ids(monitor, lines))
            log = out / "speech.log"
            said = log.read_text().count("\n") if log.exists() else 0
            # no restart still under way: a process just killed still looks alive until its
            # exit is reaped, so each kill must also have been answered by a restart (CI: the
            # last kill went uncounted, 3 restarts for 4 kills)
            restarted = sum(r.count for r in pipeline.restarts.values()) >= len(kills)
            alive = restarted and all(p.running for p in pipeline.processes)
            if alive and all(described.get(n) for n in ended) and said >= len(described):
                break
            await asyncio.sleep(0.2)
    finally:
        monitor.stop()
        capturing.cancel()
        codes = await pipeline.stop()
    elapsed = loop.time() - began
    ended = sorted(ended_ids(monitor, lines))
    log = out / "speech.log"
    spoken: dict[int, int] = {}
    for line in log.read_text().splitlines() if log.exists() else []:
        sid = int(line.split("\t")[1])
        spoken[sid] = spoken.get(sid, 0) + 1
    printed = blocks(lines)
    wrong = [
        n for n, block in printed.items() if block != expected[(n - 1) % len(expected)]
    ]  # a gesture told otherwise than `beyond analyse` tells it
    fifth = max(1, len(memory) // 5)
    figures: dict[str, Any] = {
        "duration_s": round(elapsed, 1),
        "rate": rate or "max",
        "recording": recording.name,
        "gestures_ended": len(ended),
        "described": len(described),
        "lost": [n for n in ended if n not in described],
        "described_twice": sorted(n for n, c in described.items() if c > 1),
        "said_twice": sorted(n for n, c in spoken.items() if c > 1),
        "not_said": [n for n in described if n not in spoken],
        "blocks_unlike_analyse": wrong,
        "kills": len(kills),
        "restarts": {n: r.count for n, r in pipeline.restarts.items()},
        # the deployment's own rule: killed by its SIGTERM while still starting is clean
        "clean_stop": not pipeline.unclean(),
        "unclean": {
            p.name: [codes[p.name], *list(p.lines)[-3:]]
            for p in pipeline.processes
            if p.name in pipeline.unclean()
        },
        "rss_first_fifth_mb": round(statistics.median(m for _, m in memory[:fifth]), 1)
        if memory
        else 0.0,
        "rss_last_fifth_mb": round(statistics.median(m for _, m in memory[-fifth:]), 1)
        if memory
        else 0.0,
        "rss_max_mb": round(max((m for _, m in memory), default=0.0), 1),
        "rss_slope_mb_per_min": round(slope_per_min(memory), 2),
        # past the first half, once the publishers' caches and the bounded records have filled
        "rss_slope_second_half_mb_per_min": round(slope_per_min(memory[len(memory) // 2 :]), 2),
        "samples": len(memory),
    }
    say(f"soak: {figures['duration_s']} s at rate {figures['rate']} over {recording.name}")
    say(f"  {len(ended)} gestures ended, {len(described)} described, {len(kills)} services "
        f"killed, restarts {figures['restarts']}")  # fmt: skip
    say(f"  lost {figures['lost']}, described twice {figures['described_twice']}, said twice "
        f"{figures['said_twice']}, not said {figures['not_said']}, blocks unlike analyse "
        f"{figures['blocks_unlike_analyse']}")  # fmt: skip
    say(f"  resident memory (all processes): first fifth {figures['rss_first_fifth_mb']} MB, "
        f"last fifth {figures['rss_last_fifth_mb']} MB (reference: the first fifth), max "
        f"{figures['rss_max_mb']} MB, slope {figures['rss_slope_mb_per_min']} MB/min over "
        f"{figures['samples']} samples ({figures['rss_slope_second_half_mb_per_min']} MB/min over "
        "the second half)")  # fmt: skip
    return figures


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=600.0, help="seconds (default 600)")
    parser.add_argument("--kill-every", type=float, default=30.0, help="seconds between kills")
    parser.add_argument("--rate", type=float, default=1.0, help="replay rate (0: max)")
    parser.add_argument("--recording", default="tap-ball-grasp-box.mcap")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    figures = asyncio.run(
        soak(
            duration_s=args.duration,
            kill_every_s=args.kill_every,
            rate=args.rate,
            recording=RECORDINGS / args.recording,
            seed=args.seed,
        )
    )
    print(json.dumps(figures))
    ok = not (figures["lost"] or figures["described_twice"] or figures["said_twice"])
    with contextlib.suppress(Exception):
        sys.stdout.flush()
    return 0 if ok and figures["clean_stop"] and not figures["blocks_unlike_analyse"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
