"""`beyond up`: the whole pipeline, every service in its own process, on one machine.

    beyond up [--recording FILE | --log DIR | --live-source module:function] [--config FILE]
              [--profile all|robot|workstation] [--rate R] [--no-live] [--timeout S]
              [--wait-for NAME,...] [--until-stream-end] [bus options]

Starts the services of the profile on the configured bus (default: Zenoh peers on loopback),
waits for their liveliness, then starts the source. Service logs go to stderr with the service
name; pipeline events (recognised action, anticipated effect, description) to stdout, and a live
view when stdout is a terminal. With a recording or log it exits once every gesture has its
final description (status 0) or after --timeout (status 1); Ctrl-C stops everything cleanly.

Two machines (see README, Deployment): `--profile robot` (ingest, gestures, objects) and
`--profile workstation` (reasoner, describer, speech) start one side each, against a router
given with `--connect tcp/HOST:7447`. In peer mode the processes `up` starts stay one local peer
group (their traffic stays on the machine) and that group is linked to the router. The
workstation side joins as clients of its router unless a mode or config file says otherwise:
zenoh 1.10 routers assume the peers connected to them reach each other directly, which peers on
two machines' loopbacks cannot, so peers on both sides of one router would never meet. Either side
may start first: the source waits only for this machine's services (plus `--wait-for`), and the
cross-link streams are recovered from publisher caches when the other side joins late or a link
fails. The workstation side runs until stopped, or with `--until-stream-end` until the robot's
source has ended and every gesture it showed is described.

`--secure DIR` (README, "Securing a deployment"): every certificate the side needs is checked
first, then the side starts its own router (TLS, the generated access rules; linked with the
side's certificate to the endpoints given with `--connect`, if any) and its processes join it
as clients, each with its own certificate.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import signal
import sys
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.live import Live

from beyond.commands import argtypes
from beyond.live_view import render
from beyond.monitor import PipelineMonitor
from cognition.paths import REPO_ROOT
from core.errors import InputError
from runtime.bus import Bus
from runtime.cliargs import add_bus_arguments, config_from_args
from runtime.config import BusConfig
from runtime.service import exit_process
from schemas.keys import check_name
from services.launcher import (
    HealthWatch,
    ServiceProcess,
    service_env,
    start_service,
    stop_services,
)
from services.options import check_options, load_options
from services.registry import PROFILES, service_class

HELP = "start the pipeline's services as separate processes and watch them"
SECURE_LOCAL_ROUTER = "tls/127.0.0.1:7447"  # a side's own router, when it links to another
DEMO_RECORDING = REPO_ROOT / "recordings" / "tap-ball-grasp-box.mcap"
DEFAULT_TIMEOUT = 120.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--recording", type=Path, help="MCAP recording to replay into the pipeline")
    source.add_argument("--log", type=Path, help="YARP hand log (the article's data.log)")
    source.add_argument("--live-source", metavar="MODULE:FUNCTION", help="live source plug-in")
    parser.add_argument("--config", help="YAML/JSON file with per-service options")
    parser.add_argument("--profile", choices=list(PROFILES), default="all")
    parser.add_argument(
        "--skip",
        action="append",
        default=[],
        metavar="SERVICE",
        help="do not start this service (e.g. speech, when your own synthesizer replaces it)",
    )
    parser.add_argument(
        "--rate",
        type=argtypes.number(float, lo=0, hi=1e6),
        default=1.0,
        help="replay speed (0: as fast as possible)",
    )
    parser.add_argument("--no-live", action="store_true", help="no live view, event lines only")
    parser.add_argument(
        "--foxglove",
        nargs="?",
        type=argtypes.port,
        const=8765,
        metavar="PORT",
        help="also serve the bus to Foxglove on ws://localhost:PORT (default 8765)",
    )
    parser.add_argument(
        "--timeout",
        type=argtypes.seconds(),
        default=None,
        help=f"give up after S seconds (default {DEFAULT_TIMEOUT:.0f} with a source or "
        "--until-stream-end, else run until stopped)",
    )
    parser.add_argument(
        "--wait-for",
        action="append",
        default=[],
        metavar="NAME[,NAME...]",
        help="services elsewhere (e.g. the workstation's reasoner) the source waits for too",
    )
    parser.add_argument(
        "--until-stream-end",
        action="store_true",
        help="exit once the (remote) source has ended and every gesture is described",
    )
    add_bus_arguments(parser)


def run(args: argparse.Namespace) -> int:
    config = config_from_args(args)
    if args.profile == "workstation" and _mode_unset(args, config):
        config = config.with_(mode="client")
    if config.secure is not None and config.identity is None:  # the monitor is the side's
        config = config.with_(identity="robot" if args.profile == "robot" else "workstation")
    status = asyncio.run(up(args, local_group(config)))
    # every service is stopped and the session closed: leave before the interpreter's teardown,
    # which aborted `up` now and then (SIGABRT) after a run that had succeeded
    exit_process(status)


def secure_router(config: BusConfig, names: list[str], profile: str) -> list[str]:
    """On a secure bus every side runs its own router: check every certificate this side needs
    (one line naming the file, before anything starts) and return the router's command. Given
    endpoints elsewhere (the workstation's router), this side's router links to them with the
    side's certificate, and this side's processes stay on their own router, so a robot's
    pipeline keeps running when the network between the machines fails."""
    from runtime import keystore

    assert config.secure is not None
    remote = list(config.connect or ()) + list(config.routers)
    identity = ("robot" if profile == "robot" else "workstation") if remote else "router"
    for name in [*names, str(config.identity), identity]:
        keystore.check(config.secure, name)
    command = ["router", "--secure", str(config.secure), "--identity", identity]
    if remote:
        command += ["--listen", SECURE_LOCAL_ROUTER] + [a for e in remote for a in ("--connect", e)]
    return command


def _mode_unset(args: argparse.Namespace, config: BusConfig) -> bool:
    return (
        getattr(args, "mode", None) is None
        and not os.environ.get("BEYOND_ZENOH_MODE")
        and config.config_file is None
    )


def local_group(config: BusConfig) -> BusConfig:
    """In peer mode, endpoints given to connect to are routers linked to this machine's group,
    not a replacement of it: the services `up` starts keep meeting on loopback."""
    if config.mode == "peer" and config.connect is not None:
        return config.with_(connect=None, routers=config.routers + config.connect)
    return config


def monitor_name(profile: str) -> str:
    """Liveliness name of `up`'s own monitor: one per side, so two sides never mistake each
    other's monitor for their own."""
    return "monitor" if profile == "all" else f"monitor-{profile}"


def wait_list(values: list[str]) -> list[str]:
    names = [n.strip() for v in values for n in v.split(",") if n.strip()]
    for name in names:
        check_name("service", name)
    return names


async def up(args: argparse.Namespace, config: BusConfig) -> int:
    names = [n for n in PROFILES[args.profile] if n not in args.skip]
    monitor = monitor_name(args.profile)
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
        local = [n for n in names if n != "ingest"] + [monitor]
        options["ingest"]["wait_for"] = local + wait_list(args.wait_for)
    replayed = finite  # services follow the recording's clock
    finite = finite or args.until_stream_end
    timeout = args.timeout
    if timeout is None and ("ingest" in names or finite):
        timeout = DEFAULT_TIMEOUT
    if "reasoner" in names and "objects" not in names and args.profile == "all":
        # no object segmenter in this deployment: the reasoner must not wait for one
        options["reasoner"].setdefault("objects", False)
    for name in names:
        check_options(name, service_class(name), options[name])
    out = Console()
    router_command = None
    if config.secure is not None:
        router_command = secure_router(config, names, args.profile)
        config = config.with_(connect=None, routers=())  # this side's router links elsewhere
    extra = {"BEYOND_CLOCK": "recording"} if replayed else {}
    env = service_env(config, extra)
    processes: list[ServiceProcess] = []
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
    live: Live | None = None
    watch: HealthWatch | None = None

    def log_line(name: str, line: str) -> None:
        print(f"[{name}] {line}", file=sys.stderr, flush=True)

    def emit(line: str) -> None:
        if live is not None:
            live.console.print(line, markup=False, highlight=False)
        else:
            print(line, flush=True)

    status = 1
    router: ServiceProcess | None = None
    if router_command is not None:  # secure defaults and its own endpoints, not the clients'
        own = BusConfig(robot=config.robot, mode="router", secure=config.secure)
        env_router = service_env(own)
        router = await start_service("router", env_router, command=router_command, sink=log_line)
    try:
        bus = Bus.open(config)  # a secure client waits here for its router
    except BaseException:
        await stop_services([router] if router else [])
        raise
    with bus:
        foxglove = None
        if args.foxglove:  # imported only when asked for: the SDK is not free to load
            from runtime.foxglove_bridge import start_in_background

            foxglove = await start_in_background(bus, args.foxglove)
            emit(f"Foxglove: open a WebSocket connection to ws://localhost:{args.foxglove}")
        pipeline = PipelineMonitor(bus, emit)
        pipeline.start()
        token = bus.declare_token(bus.keys.alive(monitor))
        try:
            for name in names:  # the source last, once its consumers are up
                if name != "ingest":
                    processes.append(
                        await start_service(name, env, options=options[name], sink=log_line)
                    )
            # by name: on a shared bus the other machine's services are alive too
            for name in [n for n in names if n != "ingest"] + [monitor]:
                await bus.wait_alive(bus.keys.alive(name), timeout=60)
            if "ingest" in names:
                source_sp = await start_service(
                    "ingest", env, options=options["ingest"], sink=log_line
                )
                processes.append(source_sp)
                await alive_or_exited(bus, source_sp, timeout=60)
            if all(p.running for p in processes):
                emit(f"pipeline up: {', '.join(names)} on robot {config.robot!r}")
            watch = HealthWatch(
                bus, processes, lambda n, why: emit(f"service {n} is stuck ({why}); stopping it")
            )
            watch.start()
            use_live = out.is_terminal and not args.no_live
            if use_live:
                live = Live(render(pipeline, names), console=out, refresh_per_second=8)
                live.start()
            deadline = None if timeout is None else loop.time() + timeout
            while not stop.is_set():
                if finite and pipeline.done():
                    status = 0
                    break
                crashed = [
                    p.name for p in processes + ([router] if router else []) if not p.running
                ]
                if crashed:
                    emit(f"service(s) exited early: {', '.join(crashed)}")
                    break
                if deadline is not None and loop.time() > deadline:
                    emit(f"timed out after {timeout:.0f} s")
                    break
                pipeline.changed.clear()
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(pipeline.changed.wait(), 0.25)
                if live is not None:
                    live.update(render(pipeline, names))
            else:
                status = 0  # stopped by the user
        finally:
            if watch is not None:
                await watch.stop()
            if live is not None:
                live.update(render(pipeline, names))
                live.stop()
            token()
            pipeline.stop()
            codes = await stop_services(processes)
            if foxglove is not None:
                await foxglove()
            codes.update(await stop_services([router] if router else []))  # the router last
    emit(pipeline.summary())
    err_codes = ", ".join(f"{n} {c}" for n, c in codes.items())
    print(f"services stopped (exit codes: {err_codes})", file=sys.stderr)
    failed = {n: c for n, c in codes.items() if c not in (0, -signal.SIGTERM)}
    if failed:
        emit(f"services that did not stop cleanly: {failed}")
        status = status or 1
    return status


async def alive_or_exited(bus: Bus, sp: ServiceProcess, timeout: float) -> None:
    """Until `sp`'s liveliness token is seen (declared after its health queryable, so it now
    answers health), or until it exited (the watch loop then reports it). "pipeline up" used to
    be printed as soon as the source's process was spawned: whoever took the line at its word
    and asked the source for its health found nothing serving yet."""
    alive = asyncio.ensure_future(bus.wait_alive(bus.keys.alive(sp.name), timeout=timeout))
    exited = asyncio.ensure_future(sp.process.wait())
    try:
        await asyncio.wait({alive, exited}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        alive.cancel()
        exited.cancel()
    if alive.done() and not alive.cancelled():
        error = alive.exception()  # no token in time: a TimeoutError, as for the others
        if error is not None and not (exited.done() and not exited.cancelled()):
            raise error


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
