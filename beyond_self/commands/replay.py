"""`beyond replay FILE.mcap`: publish a recording on the bus with its original timing.

From a terminal, space pauses and resumes, and `s` (or any other key but `q`) publishes the next
message while paused; `--start-paused` waits for the first key. Keys are read from a pipe or a
file too when started paused (so a script can drive it); the end of stdin plays on."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import sys
import termios
import tty
from collections.abc import Iterator

from beyond_self.commands import argtypes
from beyond_self.commands.terminal import stop_on_signals
from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.log import setup_logging
from beyond_self.runtime.recording.reader import RecordedMessage, inspect_recording, require_mcap
from beyond_self.runtime.recording.replay import replay
from beyond_self.runtime.recording.replay_control import ReplayControl, rate_option, remapper
from beyond_self.runtime.recording.robots import recorded_robots
from beyond_self.schemas.keys import check_name

HELP = "publish an MCAP recording on the bus in stamp order"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="MCAP recording")
    speed = parser.add_mutually_exclusive_group()
    speed.add_argument(
        "--rate",
        type=argtypes.rate,
        default=1.0,
        help="speed factor (default 1; 0: as fast as possible, as --as-fast-as-possible)",
    )
    speed.add_argument(
        "--as-fast-as-possible", "--afap", action="store_true", help="no timing, just go"
    )
    parser.add_argument("--loop", action="store_true", help="repeat until interrupted")
    parser.add_argument(
        "--topics", nargs="+", type=argtypes.keyexpr, metavar="KEYEXPR", help="only these keys"
    )
    parser.add_argument(
        "--start", type=argtypes.seconds(zero=True), help="seconds from the recording start"
    )
    parser.add_argument(
        "--end", type=argtypes.seconds(zero=True), help="seconds from the recording start"
    )
    parser.add_argument(
        "--wait-for",
        type=argtypes.keyexpr,
        metavar="KEYEXPR",
        help="before playing, wait until a liveliness token matches (e.g. beyond/r/alive/*)",
    )
    parser.add_argument(
        "--wait-timeout",
        type=argtypes.seconds(),
        default=30.0,
        metavar="S",
        help="give up on --wait-for after S seconds (default 30)",
    )
    parser.add_argument(
        "--pace-for",
        type=_names,
        metavar="NAME[,NAME...]",
        help="services never to outrun (default: every service alive when the replay starts; "
        "'none' for no pacing)",
    )
    parser.add_argument(
        "--remap",
        action="append",
        default=[],
        metavar="FROM:TO",
        help="publish key FROM (and keys under it) as TO; repeat for several",
    )
    parser.add_argument(
        "--start-paused",
        action="store_true",
        help="wait for a key before the first message (space: play/pause, s: step)",
    )
    add_bus_arguments(parser)


def _names(text: str) -> list[str]:
    """--pace-for: service names separated by commas, or 'none'."""
    if text.strip().lower() == "none":
        return []
    names = [n.strip() for n in text.split(",") if n.strip()]
    for name in names:
        check_name("service", name)
    return names


@contextlib.contextmanager
def keyboard(control: ReplayControl, *, paused: bool) -> Iterator[None]:
    """Feed key presses from stdin to `control`: a terminal in cbreak mode, or, when started
    paused, a pipe or a file (otherwise stdin is left alone: it may belong to someone else).
    The end of stdin plays on, since nothing could resume a pause after it."""
    fd = sys.stdin.fileno() if sys.stdin is not None and not sys.stdin.closed else -1
    is_tty = fd >= 0 and os.isatty(fd)
    if fd < 0 and paused:
        raise InputError("--start-paused reads its keys from stdin, which is closed; give it one")
    if fd < 0 or not (is_tty or paused):
        yield
        return
    loop = asyncio.get_running_loop()
    saved = termios.tcgetattr(fd) if is_tty else None

    def take(data: bytes) -> None:
        if not data:
            loop.remove_reader(fd)
            control.close()
            print("stdin ended: playing on", file=sys.stderr, flush=True)
            return
        for char in data.decode(errors="replace"):
            if char == " ":
                control.toggle()
                state = "paused (space: play, s: step)" if control.paused else "playing"
                print(state, file=sys.stderr, flush=True)
            elif char == "q":
                control.close()
            elif char not in "\r\n":
                control.step()

    def on_key() -> None:
        try:
            data = os.read(fd, 64)
        except OSError:
            data = b""
        take(data)

    if saved is not None:
        tty.setcbreak(fd)
    try:
        loop.add_reader(fd, on_key)
    except PermissionError:  # a file or /dev/null, which epoll refuses: read now, never blocks
        while data := os.read(fd, 4096):
            take(data)
        take(b"")
    try:
        yield
    finally:
        loop.remove_reader(fd)
        if saved is not None:
            termios.tcsetattr(fd, termios.TCSADRAIN, saved)


def run(args: argparse.Namespace) -> int:
    setup_logging(fmt="text")
    config = config_from_args(args)
    require_mcap(args.file)
    remap = remapper(args.remap)
    rate = None if args.as_fast_as_possible else rate_option(args.rate, "--rate")

    async def go() -> int:
        stop = stop_on_signals()
        control = ReplayControl(paused=args.start_paused)
        stop_task = asyncio.get_running_loop().create_task(stop.wait())
        stop_task.add_done_callback(lambda _: control.close())
        t0: list[int] = []

        def shown(item: RecordedMessage) -> None:
            if not t0:
                t0.append(item.publish_time)
            if control.paused:
                at = (item.publish_time - t0[0]) / 1e9
                print(f"step: {at:.3f} s {item.key}", file=sys.stderr, flush=True)

        if args.start_paused:
            print("paused: space plays, s steps one message", file=sys.stderr, flush=True)
        with Bus.open(config) as bus, keyboard(control, paused=args.start_paused):
            if args.wait_for:
                try:
                    await bus.wait_alive(args.wait_for, timeout=args.wait_timeout)
                except TimeoutError:
                    raise InputError(
                        f"nothing alive matched --wait-for {args.wait_for} within "
                        f"{args.wait_timeout:g} s (see `beyond topics`); nothing replayed"
                    ) from None
            if args.pace_for is None:
                alive = await bus.live_tokens(bus.keys.alive("*"))
                pace_for = [key.rsplit("/", 1)[-1] for key in alive]
            else:
                pace_for = args.pace_for
            stats = await replay(
                bus,
                args.file,
                rate=rate,
                loop=args.loop,
                topics=args.topics,
                start=args.start,
                end=args.end,
                # $BEYOND_ROBOT too, as recordings/README.md says; a fleet's recording plays
                # every robot's keys as recorded (runtime.recording.robots)
                robot=config.robot
                if len(recorded_robots(inspect_recording(args.file))) <= 1
                else None,
                stop=stop,
                pace_for=pace_for,
                remap=remap,
                control=control,
                on_message=shown,
            )
        stop_task.cancel()
        print(
            f"replayed {stats.messages} messages in {stats.passes} pass(es), "
            f"{stats.span_s:.3f} s of recording in {stats.wall_s:.3f} s "
            f"({stats.speed:.1f}x real time; held back {stats.held_back_s:.3f} s by "
            f"{', '.join(pace_for) or 'nobody'})",
            file=sys.stderr,
        )
        if stats.damaged:  # one line, the same as inspect, analyse and up say (exit 2)
            raise InputError(stats.damaged)
        return 0

    return asyncio.run(go())
