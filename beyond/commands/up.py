"""`beyond up`: the whole pipeline, every service in its own process, on one machine.

    beyond up [--recording FILE | --log DIR | --live-source module:function] [--config FILE]
              [--profile all|robot|workstation] [--rate R] [--no-live] [--timeout S]

Starts the services of the profile on the configured bus (default: Zenoh peers on loopback),
waits for their liveliness, then starts the source. Service logs go to stderr with the service
name; pipeline events (recognised action, anticipated effect, description) to stdout, and a live
view when stdout is a terminal. With a recording or log it exits once every gesture has its
final description (status 0) or after --timeout (status 1); Ctrl-C stops everything cleanly.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import sys
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.live import Live

from cognition.errors import InputError
from cognition.paths import REPO_ROOT
from runtime.bus import Bus
from runtime.cliargs import add_bus_arguments, config_from_args
from runtime.config import BusConfig
from services.launcher import ServiceProcess, service_env, start_service, stop_services
from services.live_view import render
from services.monitor import PipelineMonitor
from services.options import check_options, load_options
from services.registry import PROFILES, service_class

HELP = "start the pipeline's services as separate processes and watch them"
DEMO_RECORDING = REPO_ROOT / "recordings" / "tap-ball-grasp-box.mcap"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--recording", type=Path, help="MCAP recording to replay into the pipeline")
    source.add_argument("--log", type=Path, help="YARP hand log (the article's data.log)")
    source.add_argument("--live-source", metavar="MODULE:FUNCTION", help="live source plug-in")
    parser.add_argument("--config", help="YAML/JSON file with per-service options")
    parser.add_argument("--profile", choices=list(PROFILES), default="all")
    parser.add_argument(
        "--rate", type=float, default=1.0, help="replay speed (0: as fast as possible)"
    )
    parser.add_argument("--no-live", action="store_true", help="no live view, event lines only")
    parser.add_argument("--timeout", type=float, default=120.0, help="give up after S seconds")
    add_bus_arguments(parser)


def run(args: argparse.Namespace) -> int:
    return asyncio.run(up(args, config_from_args(args)))


async def up(args: argparse.Namespace, config: BusConfig) -> int:
    names = list(PROFILES[args.profile])
    file_options = load_options(args.config)
    options: dict[str, dict[str, Any]] = {n: dict(file_options.get(n, {})) for n in names}
    source = _source(args)
    finite = (bool(source) and "log" in source) or "recording" in source
    if "ingest" in names:
        if not source and not any(k in options["ingest"] for k in ("recording", "log", "plugin")):
            source = {"recording": str(DEMO_RECORDING)}
            finite = True
        options["ingest"].update(source)
        options["ingest"].setdefault("rate", args.rate)
        options["ingest"]["wait_for"] = [n for n in names if n != "ingest"] + ["monitor"]
    for name in names:
        check_options(name, service_class(name), options[name])
    out = Console()
    extra = {"BEYOND_CLOCK": "recording"} if finite else {}
    env = service_env(config, extra)
    processes: list[ServiceProcess] = []
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
    live: Live | None = None

    def log_line(name: str, line: str) -> None:
        print(f"[{name}] {line}", file=sys.stderr, flush=True)

    def emit(line: str) -> None:
        if live is not None:
            live.console.print(line, markup=False, highlight=False)
        else:
            print(line, flush=True)

    status = 1
    with Bus.open(config) as bus:
        monitor = PipelineMonitor(bus, emit)
        monitor.start()
        token = bus.declare_token(bus.keys.alive("monitor"))
        try:
            for name in names:  # the source last, once its consumers are up
                if name != "ingest":
                    processes.append(
                        await start_service(name, env, options=options[name], sink=log_line)
                    )
            others = [n for n in names if n != "ingest"]
            await bus.wait_alive(bus.keys.alive("*"), count=len(others) + 1, timeout=60)
            if "ingest" in names:
                processes.append(
                    await start_service("ingest", env, options=options["ingest"], sink=log_line)
                )
            emit(f"pipeline up: {', '.join(names)} on robot {config.robot!r}")
            use_live = out.is_terminal and not args.no_live
            if use_live:
                live = Live(render(monitor, names), console=out, refresh_per_second=8)
                live.start()
            deadline = loop.time() + args.timeout
            while not stop.is_set():
                if finite and monitor.done():
                    status = 0
                    break
                crashed = [p.name for p in processes if not p.running]
                if crashed:
                    emit(f"service(s) exited early: {', '.join(crashed)}")
                    break
                if loop.time() > deadline:
                    emit(f"timed out after {args.timeout:.0f} s")
                    break
                monitor.changed.clear()
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(monitor.changed.wait(), 0.25)
                if live is not None:
                    live.update(render(monitor, names))
            else:
                status = 0  # stopped by the user
        finally:
            if live is not None:
                live.update(render(monitor, names))
                live.stop()
            token()
            monitor.stop()
            codes = await stop_services(processes)
    emit(monitor.summary())
    err_codes = ", ".join(f"{n} {c}" for n, c in codes.items())
    print(f"services stopped (exit codes: {err_codes})", file=sys.stderr)
    failed = {n: c for n, c in codes.items() if c not in (0, -signal.SIGTERM)}
    if failed:
        emit(f"services that did not stop cleanly: {failed}")
        status = status or 1
    return status


def _source(args: argparse.Namespace) -> dict[str, str]:
    if args.recording is not None:
        if not args.recording.is_file():
            raise InputError(f"recording {args.recording} does not exist")
        return {"recording": str(args.recording)}
    if args.log is not None:
        return {"log": str(args.log)}
    if args.live_source is not None:
        return {"plugin": args.live_source}
    return {}
