"""`beyond up`: the whole pipeline, every service in its own process, on one machine or one side.

The command around a `services.deployment.Deployment`, which starts and supervises the
processes: its run, the state it goes on from, and the exit status. Beside it: the options
(`up_options`), what the side runs (`up_services`), where it meets the bus (`up_side`), and the
event lines on stdout and the live view while it runs (`up_watch`). A run with a source ends once
the source has ended and every gesture has its final description; `--timeout` bounds start-up
and the tail, never a running source's silence. Sides, fleets and the secure bus:
docs/concepts/deployment.md, fleets.md and security.md.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from pathlib import Path

from beyond_self.commands.up_options import DEFAULT_TIMEOUT
from beyond_self.commands.up_options import add_arguments as add_arguments
from beyond_self.commands.up_services import awaited_elsewhere, deployment
from beyond_self.commands.up_side import check_fleet_profile, local_group, mode_unset, side_identity
from beyond_self.commands.up_watch import EventLines, already_up, say_what_is_awaited, watch
from beyond_self.core.errors import InputError
from beyond_self.monitor import PipelineMonitor
from beyond_self.runtime import outputs
from beyond_self.runtime.bus.cliargs import config_from_args
from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.process import exit_process
from beyond_self.runtime.resilience.run_state import RunState, deployment_folder, run_state_root
from beyond_self.services.deployment import Deployment, Ending

HELP = "start the pipeline's services as separate processes and watch them"
LOST = 3  # exit status of a run that lost gestures or sensor frames (its summary says which)


def run(args: argparse.Namespace) -> int:
    config = config_from_args(args)
    if args.robots is not None or args.standby is not None:
        check_fleet_profile(args.profile)
    if args.profile.endswith("workstation") and mode_unset(args, config):
        config = config.with_(mode="client")
    if config.secure is not None and config.identity is None:  # the monitor is the side's
        config = config.with_(identity=side_identity(args.profile, config.robot))
    try:
        status = asyncio.run(up(args, local_group(config)))
    except InputError as exc:  # bad input (a damaged recording...): one line, as every command
        print(f"beyond up: error: {exc}", file=sys.stderr)
        status = 2
    # every service is stopped and the session closed: leave without the interpreter's teardown,
    # which can abort (SIGABRT) a process whose Zenoh native threads are up (exit_process)
    exit_process(status)


async def up(args: argparse.Namespace, config: BusConfig) -> int:
    lines = EventLines()
    side, _ = deployment(args, config, lines)
    finite = "ingest" in side.services or args.until_stream_end  # ends when its source does
    timeout = args.timeout
    if timeout is None and ("ingest" in side.services or finite):
        timeout = DEFAULT_TIMEOUT
    state = run_state(args, side, config)
    # the processes start now, held off the bus: their interpreters and imports overlap the
    # session's opening and the look for another `up`, which refuses before any joins
    await side.prepare()
    try:
        bus = await side.open()
        running = await already_up(side, bus)
    except BaseException:
        await side.stop()
        raise
    if running:
        await side.stop()
        raise InputError(
            f"robot {side.config.robot!r} already has {', '.join(running)} on the bus (another "
            "beyond up?); stop it first, or give this one another --robot"
        )
    if said := state.begin(run_command(args, side), fresh=args.fresh):
        print(f"[up] {said}", file=sys.stderr, flush=True)
    pipeline = PipelineMonitor.of(side, bus, lines.emit, state)
    loop = asyncio.get_running_loop()
    hints: list[asyncio.Task[None]] = []
    try:
        if args.foxglove:  # imported only when asked for: the SDK is not free to load
            from beyond_self.runtime.foxglove.bridge import start_in_background

            side.attach(await start_in_background(bus, args.foxglove))
            lines.emit(f"Foxglove: open a WebSocket connection to ws://localhost:{args.foxglove}")
        pipeline.start()
        await side.start()
        if not side.exited():
            shards = f", {args.shards} shards each" if args.shards > 1 else ""
            names = ", ".join(side.services)
            lines.emit(f"pipeline up: {names} on robot {side.config.robot!r}{shards}")
        hints.append(loop.create_task(say_what_is_awaited(bus, awaited_elsewhere(args))))
        ending = await watch(side, pipeline, lines, timeout, finite, live=not args.no_live)
        await pipeline.last_health()  # what was dropped since the last report counts too
    finally:
        for task in hints:
            task.cancel()
        pipeline.stop()
        codes = await side.stop()
    lines.emit(pipeline.summary())
    if side.restarts:
        counts = ", ".join(f"{n} {r.count}" for n, r in side.restarts.items() if r.count)
        print(f"restarts: {counts or 'none'}", file=sys.stderr)
    err_codes = ", ".join(f"{n} {c}" for n, c in codes.items())
    print(f"services stopped (exit codes: {err_codes})", file=sys.stderr)
    if failed := side.unclean():
        lines.emit(f"services that did not stop cleanly: {failed}")
        return 1
    if ending.reason == "done":  # complete: the same command again starts over
        state.clear()
    end = pipeline.stream_end
    return exit_status(ending, end.damage if end is not None else "", pipeline.losses())


def run_state(args: argparse.Namespace, side: Deployment, bus: BusConfig) -> RunState:
    """The side's state on this machine (runtime.resilience.run_state), given to its services:
    its own, keyed by its bus `bus` (as given, before a secure side's router is placed) and its
    outputs folder, so another deployment's `--fresh` (a demo on another port) never clears it."""
    out = getattr(args, "out_dir", None)
    outputs_folder = out.resolve() if out is not None else outputs.out_dir()
    root = run_state_root(outputs_folder) / deployment_folder(bus, outputs_folder)
    state = RunState(root, side.config.robot, side.watcher or "up", side.services)
    side.env.update(state.env())
    return state


# what does not change a run's results: the same command but for these goes on from its state
# (--shards only spreads the robots' runs, whose state is each robot's own, over processes)
PRESENTATION = frozenset(("fresh", "no_live", "timeout", "foxglove", "func", "command", "shards"))


def run_command(args: argparse.Namespace, side: Deployment) -> str:
    """The run's identity: the side's services and every option that shapes its results, the
    source's path resolved."""
    options = {
        k: str(Path(v).resolve()) if k in ("recording", "log", "video") and v else v
        for k, v in sorted(vars(args).items())
        if k not in PRESENTATION and not callable(v)
    }
    everything = {"robot": side.config.robot, "services": side.services, **options}
    return json.dumps(everything, sort_keys=True, default=str)


def exit_status(ending: Ending, damage: str, lost: list[str]) -> int:
    """0, or 1 (a failure, a timeout), InputError (2: a damaged source), or LOST (the run lost
    gestures or sensor frames, which the summary said)."""
    if not ending.ok:
        return 1
    if damage:  # the readable part was played and described; what was lost, as analyse says it
        raise InputError(damage)
    return LOST if lost else 0
