"""The base every service stands on: what a service calls (docs/concepts/service.md), its
lifecycle; the machinery beneath is runtime.service_core.

A service declares the streams it touches (`subscribes`, `publishes`, `serves`, schemas/keys.py)
and opens only those in `setup()`: a secure router's rules are generated from the declarations
(runtime/security/acl.py), and a key not declared is refused. Bad input never stops a service:
it is counted and logged once per kind of problem (runtime.error_account).
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import time
import zlib
from collections.abc import Callable, Coroutine, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn, TypeVar, overload

from beyond_self.core.restorable import Restorable
from beyond_self.runtime import process
from beyond_self.runtime import service_core as core
from beyond_self.runtime.bus.config import BusConfig, load_config
from beyond_self.runtime.bus.delivery import RELIABLE, Delivery
from beyond_self.runtime.bus.publisher import Publisher
from beyond_self.runtime.bus.queries import PlainQueryHandler, QueryHandler
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.bus.subscription import Handler, Subscription
from beyond_self.runtime.clock import Clock
from beyond_self.runtime.error_account import ErrorAccount
from beyond_self.runtime.event_time import SourceTimes
from beyond_self.runtime.progress import ProgressReport
from beyond_self.runtime.resilience.effect_log import EffectLog, take_over
from beyond_self.runtime.resilience.ledger import Keeper
from beyond_self.runtime.resilience.resume import InputGate, gated
from beyond_self.runtime.resilience.snapshots import Snapshots
from beyond_self.runtime.resilience.source_plan import ResumePlan, plan
from beyond_self.runtime.resilience.state import state_dir
from beyond_self.runtime.security.acl import check_declared
from beyond_self.runtime.self_report import health_of
from beyond_self.runtime.service_cli import options_from_command_line
from beyond_self.runtime.service_core import Downstream
from beyond_self.runtime.service_upstream import CLOSES, Upstream, counted
from beyond_self.schemas.base import Header, Message
from beyond_self.schemas.codec import SchemaError
from beyond_self.schemas.identity import TYPES as IDENTIFIED
from beyond_self.schemas.keys import check_name
from beyond_self.schemas.messages import Progress, ServiceHealth

if TYPE_CHECKING:
    from beyond_self.runtime.recording.pacing import Pacer

M = TypeVar("M", bound=Message)
# the constructor's keyword arguments every service takes (the rest are its own options)
BASE_OPTIONS = frozenset({"config", "bus", "clock", "health_period", "name"})
Q = TypeVar("Q", bound=Message)
R = TypeVar("R", bound=Restorable)


def report_phase(robot: str) -> float:
    """Where in the health period a robot's runs report, in [0, 1): the same for a robot
    every time (a hash of its name), spread over the period across a fleet's robots."""
    return zlib.crc32(robot.encode()) / 2**32


class Service:
    """Subclass, set `name` (or pass it), override `setup()`. What a service calls is listed in
    docs/concepts/service.md (fifteen names); the machinery is runtime.service_core's."""

    name: str = "service"
    health_period: float = 1.0
    subscribes: tuple[str, ...] | None = None  # stream names (schemas.keys.STREAMS)
    publishes: tuple[str, ...] | None = None
    serves: tuple[str, ...] | None = None  # queryable names (runtime.security.acl.QUERYABLES)
    # one process may serve many robots, a run per robot (runtime.fleet): not a robot's source
    fleet: bool = False

    def __init__(
        self,
        name: str | None = None,
        *,
        config: BusConfig | None = None,
        bus: Bus | None = None,
        clock: Clock | None = None,
        health_period: float | None = None,
    ) -> None:
        self.name = check_name("service", name or self.name)
        if config is not None and config.secure is not None and config.identity is None:
            config = config.with_(identity=self.name)  # on a secure bus a service is its name
        self._config = config
        self._bus = bus
        self._owns_bus = bus is None
        self.clock = clock or Clock.from_env()
        if health_period is not None:
            self.health_period = health_period
        self.log = logging.getLogger(f"beyond.{self.name}")
        self.started = asyncio.Event()
        self._account = ErrorAccount(self.log, self.name)
        self._stop = asyncio.Event()
        self._subscriptions: list[tuple[Subscription[Any], Handler[Any]]] = []
        self._publishers: list[Publisher[Any]] = []
        self._progress = ProgressReport(self.name, self.header)
        self._ledgers = Keeper(self.name, self.header)  # exactly once (runtime.resilience.ledger)
        self._fleet_member = False  # run by runtime.fleet for one robot of many
        self._once: set[str] = set()  # keys whose handling is not repeated after a restart
        self._upstreams: list[Upstream] = []  # numbered event streams (`complete=`)
        self._gates: dict[str, InputGate[Any]] = {}  # sensor key -> its restored position
        # what `keep_state` keeps: the snapshots, and how to ask for the state now
        self._state: tuple[Snapshots[Any], Callable[[], Any]] | None = None
        self._times = SourceTimes()  # whose time each sensor key keeps (runtime.event_time)
        self._recovery_reported: tuple[int, int] = (0, 0)
        self._tasks: set[asyncio.Task[Any]] = set()
        self._timers: set[asyncio.TimerHandle] = set()
        self._seq = 0
        self._health_seq = 0
        self._started_at = time.monotonic()

    # --- overridden by subclasses ----------------------------------------------------------

    async def setup(self) -> None:
        """Open subscriptions, publishers and queryables here."""

    async def teardown(self) -> None:
        """Release anything `setup` acquired beyond subscriptions and publishers."""

    def health_report(self) -> ServiceHealth:
        """This service's `ServiceHealth`: what it received, sent, dropped, could not read."""
        seq = self._health_seq
        self._health_seq += 1
        return health_of(self, seq)

    def published_counts(self) -> dict[str, int]:
        """Messages published per output key, as reported in `Progress` (a service whose
        outputs carry their own running count may report that instead: it survives a
        restart)."""
        return {p.key: p.sent for p in self._publishers}

    # --- called by subclasses --------------------------------------------------------------

    @property
    def bus(self) -> Bus:
        if self._bus is None:
            raise RuntimeError("the bus is open only while the service runs")
        return self._bus

    def subscribe(
        self,
        key: str,
        cls: type[M],
        handler: Handler[M],
        delivery: Delivery = RELIABLE,
        *,
        paced: bool = False,
        once: bool | EffectLog = False,
        complete: Callable[[int], None] | None = None,
        producer: str = "",
    ) -> Subscription[M]:
        """Call `handler(message)` for every well-formed `cls` message on `key`, received as
        `delivery` says (runtime.bus.delivery), each identity once (runtime.resilience.ledger).
        With `paced` (sensor inputs), the stamp of every message handled is published as
        `Progress`, so a player never outruns this service; `key` belongs to one source
        (runtime.event_time): another's messages, and the owner's not after the last one handled
        (a restarted source repeats what was handled), are skipped and counted. With `once` (a
        handler whose effect is not to be repeated: a sentence said), a restarted instance does
        not handle again what its predecessor handled; given the effect's own log
        (runtime.resilience.effect_log), nor what that log says was done. With `complete` (a
        numbered event stream from `producer`, runtime.service_upstream), the base counts what
        was received and calls `complete(stamp)` once every event `producer` derived from its
        input up to `stamp` has arrived."""
        self._check_declared("subscribe", key)
        upstream = None
        if complete is not None:
            upstream = Upstream(key, producer, complete)
            self._upstreams.append(upstream)
            handler = counted(upstream, handler)
        sub = self.bus.subscribe(key, cls, delivery, on_malformed=self._account.malformed)
        if (gate := self._gates.get(key)) is not None:
            handler = gated(gate, handler)
        self._subscriptions.append((sub, handler))
        if cls in IDENTIFIED:
            self._ledgers.handled.declare(key)
        if once:
            self._once.add(key)
        if isinstance(once, EffectLog):
            take_over(self._ledgers, key, cls, once, self.log)
        if paced:
            self._progress.pace(key)
            self._times.track(key)
        if self.started.is_set():
            self.spawn(core.consume_loop(self, sub, handler), key)
        if upstream is not None:  # the producer's progress says when its events are complete
            self.subscribe(self.bus.keys.progress(producer), Progress, upstream.progress)
        return sub

    def publisher(
        self, key: str, cls: type[M], delivery: Delivery = RELIABLE, *, progress: bool = False
    ) -> Publisher[M]:
        """A publisher of `cls` messages on `key`, sending as `delivery` says. With `progress`,
        each put is told in this service's `Progress` at once (not after the message being
        handled): a successor started meanwhile learns from it not to send it again."""
        self._check_declared("publish", key)
        pub = self.bus.publisher(key, cls, delivery)
        if cls in IDENTIFIED:
            pub.suppress = self._ledgers.suppressed
        if progress:
            pub.after_put = lambda: core.publish_progress(self)
        self._publishers.append(pub)
        return pub

    @overload
    def queryable(self, key: str, request: type[Q], handler: QueryHandler[Q]) -> None: ...

    @overload
    def queryable(self, key: str, request: None, handler: PlainQueryHandler) -> None: ...

    def queryable(self, key: str, request: Any, handler: Any) -> None:
        """Answer queries on `key` with `await handler(query_key, request)` (the decoded
        `request`, None without a payload): a message, a list of (key, message), or None.
        A malformed request is counted as malformed, whatever the handler raises as an error;
        the asker gets an error reply either way."""
        self._check_declared("serve", key)
        self.bus.queryable(key, request, handler, on_error=self._query_failed)

    def watch_tokens(self, key_expr: str, on_change: Callable[[str, bool], None]) -> None:
        """`on_change(key, present)` for every liveliness token matching `key_expr` that
        appears or goes (runtime.bus.liveliness); what it raises is counted as an error."""

        def guarded(key: str, present: bool) -> None:
            try:
                on_change(key, present)
            except Exception as exc:
                self.report_error(key, exc)

        self.bus.watch_tokens(key_expr, guarded)

    def downstream(self, key: str) -> Downstream:
        """What the consumers of this service's output `key` have had (`done(kind)`: every
        consumer, and said; `seen(*kinds)`: some consumer): a successor does not work on what is
        done again, and numbers on from what was seen (runtime.resilience.ledger)."""
        return Downstream(self, key)

    def resume_plan(self, pacer: Pacer) -> ResumePlan:
        """A source's resume plan (runtime.resilience.source_plan), once `pacer` has heard its
        consumers: what they all have, moved back to what their successors need again."""
        keys = self.bus.keys
        return plan(self._ledgers, pacer.handled_by_all(), keys.gesture_segment, keys.description)

    def keep_state(
        self,
        cls: type[R],
        restore: Callable[[R | None], None],
        snapshot: Callable[[], R | None],
        inputs: Sequence[str],
        on_gap: Callable[[Any, int], None] | None = None,
    ) -> Snapshots[R]:
        """Keep this service's `cls` state across kills (runtime.resilience.snapshots): `restore`
        is called at once with the one to go on from (None: start afresh); after every message
        handled, `snapshot()` says the state now, taken when it moved (told with the ledger,
        stored in the state folder when there is one). The messages of the sensor keys `inputs`
        reach their handlers from the restored state's stamp on (runtime.resilience.resume), and
        `on_gap(message, since)` hears of inputs that are gone (without it, the service takes
        what comes). Called in `setup()`, before those keys are subscribed."""
        return core.keep_state(self, cls, restore, snapshot, inputs, on_gap)

    def spawn(self, work: Coroutine[Any, Any, Any], name: str = "task") -> asyncio.Task[Any]:
        """Run `work` beside the handlers until the service stops (then it is cancelled); what
        it raises is counted as an error under `name`."""
        task = asyncio.get_running_loop().create_task(work, name=f"{self.name}: {name}")
        self._tasks.add(task)

        def finished(done: asyncio.Task[Any]) -> None:
            self._tasks.discard(done)
            if not done.cancelled() and done.exception() is not None:
                self.report_error(name, done.exception())  # type: ignore[arg-type]

        task.add_done_callback(finished)
        return task

    def call_later(self, delay_s: float, fn: Callable[[], object], name: str = "timer") -> None:
        """Call `fn()` in `delay_s` seconds unless the service stops first; what it raises is
        counted as an error under `name`. For the machine's business (retries, reports), never
        to decide an output: outputs follow the inputs' stamps (runtime/README.md)."""
        loop = asyncio.get_running_loop()

        def fire() -> None:
            self._timers.discard(handle)
            try:
                fn()
            except Exception as exc:
                self.report_error(name, exc)

        handle = loop.call_later(delay_s, fire)
        self._timers.add(handle)

    def report_error(self, key: str, exc: BaseException) -> None:
        """Count and log `exc`, raised while handling `key`; the service goes on."""
        self._account.error(key, exc)

    def derive(self, source: Header, cls: type[Message]) -> Header:
        """Header of a `cls` output computed from `source`: same stamp, same sequence number and the
        correlation id of the chain, so outputs are a pure function of inputs (replays of one
        recording give identical bytes even into a long-running service)."""
        return Header(
            version=cls.VERSION,
            source=self.name,
            seq=source.seq,
            stamp=source.stamp,
            correlation=source.correlation or f"{source.source}/{source.seq}",
        )

    def header(self, cls: type[Message], stamp: int | None = None) -> Header:
        """Header of an original `cls` message (a sensor): own sequence, clock stamp."""
        seq = self._seq
        self._seq += 1
        return cls.original_header(self.name, seq, self.clock.now_ns() if stamp is None else stamp)

    # --- the base's own --------------------------------------------------------------------

    def _query_failed(self, key: str, exc: Exception) -> None:
        if isinstance(exc, SchemaError):
            self._account.malformed_other += 1
            self._account.malformed(key, exc)
        else:
            self.report_error(key, exc)

    def _check_declared(self, kind: str, key: str) -> None:
        check_declared(self.name, type(self), kind, key, self.bus.keys.root)

    def _state_folder(self) -> Path | None:
        """This service's state folder on this machine (runtime.resilience.state); None without
        one, or when a fleet runs it for one of its robots (the robot's side keeps its own)."""
        return None if self._fleet_member else state_dir(self.bus.keys.robot, self.name)

    def _closed(self, key: str) -> set[int]:
        """Gestures of the events on `key` closed for this service: its last per-gesture output
        every consumer has, or cancelled (runtime.service_upstream)."""
        done = [self._ledgers.done_downstream(p.key, CLOSES[p.cls]) for p in self._publishers
                if p.cls in CLOSES]  # fmt: skip
        closed = set.intersection(*done) if done else set()
        return closed | self._ledgers.seen_downstream(key, ("cancel",))

    # --- lifecycle ------------------------------------------------------------------------

    def stop(self) -> None:
        """Ask the service to stop (safe from signal handlers and other tasks)."""
        self._stop.set()

    async def run(self, *, install_signals: bool = True) -> None:
        """Open the bus (unless given one), set up, serve until stopped, clean up."""
        if self._bus is None:
            config = self._config or load_config()
            if config.secure is not None and config.identity is None:
                config = config.with_(identity=self.name)
            self._bus = Bus.open(config)
            self._owns_bus = True
        installed = process.install_signals(self.stop) if install_signals else []
        undeclare_token: Callable[[], None] | None = None
        try:
            undeclare_token = await core.start(self, report_phase(self.bus.keys.robot))
            await self._stop.wait()
        finally:
            await core.shut_down(self, undeclare_token)
            if self._owns_bus and self._bus is not None:
                self._bus.close()
                self._bus = None
            for sig in installed:
                asyncio.get_running_loop().remove_signal_handler(sig)

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        """The service's own options on its command line (`python my_service.py --help`), beside
        the bus options; each parsed value that is not None is passed to the constructor as the
        keyword argument its `dest` names."""

    @classmethod
    def warm(cls, options: Mapping[str, Any]) -> None:
        """Load now what `setup` will ask for with these options (a model shared by the
        process's runs): a process started held (services.launcher) does it before it joins
        the bus. What fails here is left to `setup`, which says it as it always has."""

    @classmethod
    def check_requirements(cls) -> None:
        """Raise InputError (one line: what is missing, how to get it) when something the
        service needs outside Python is absent; `main` says it and exits 2 before starting."""

    @classmethod
    def main(cls, *args: Any, argv: Sequence[str] | None = None, **kwargs: Any) -> NoReturn:
        """Entry point for a service process: its command line (`argv`, default the process's:
        `--help`, the bus options of every `beyond` command, `add_arguments`'), logging, run
        until SIGINT/SIGTERM, then leave with status 0 (2 for bad input such as a bad option).
        A caller that parsed its own command line (`beyond service`) passes `argv=()`.

        It leaves through `process.exit_process`, not by returning to the interpreter: once the
        session is closed, the interpreter's own teardown of Zenoh's native threads can abort a
        process that stopped cleanly (SIGABRT, "FATAL: exception not rethrown")."""
        service = options_from_command_line(cls, argv, kwargs)
        process.exit_process(process.run_to_completion(lambda: cls(*args, **service).run()))
