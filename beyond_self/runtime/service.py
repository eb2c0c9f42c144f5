"""The base every service stands on: its surface (subscribe, publish, serve, spawn, report), its
lifecycle (liveliness, health, clean shutdown on signals) and its accounting.

A service declares the streams it touches (`subscribes`, `publishes`, `serves`, names from
schemas/keys.py) and opens only those in `setup()`: runtime/security/acl.py generates a secure
router's rules from the declarations, and a key not declared is refused, so the rules cannot drift
from the code. Bad input never stops a service (runtime.resilience.accounting): what does not
decode, or what a handler, timer, task or queryable raises, is counted and logged once per kind of
problem. runtime/README.md shows a whole service.
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

from beyond_self.core.errors import InputError
from beyond_self.core.restorable import Restorable
from beyond_self.runtime.bus.config import BusConfig, load_config
from beyond_self.runtime.bus.delivery import RELIABLE, STATUS, Delivery
from beyond_self.runtime.bus.publisher import Publisher
from beyond_self.runtime.bus.queries import PlainQueryHandler, QueryHandler
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.bus.subscription import Handler, Received, Subscription, consume
from beyond_self.runtime.clock import Clock
from beyond_self.runtime.event_time import SourceTimes, Verdict
from beyond_self.runtime.log import event
from beyond_self.runtime.progress import ProgressReport
from beyond_self.runtime.resilience import heap, process
from beyond_self.runtime.resilience.accounting import ErrorAccount
from beyond_self.runtime.resilience.effect_log import EffectLog, take_over
from beyond_self.runtime.resilience.ledger import Keeper
from beyond_self.runtime.resilience.resume import InputGate, gated
from beyond_self.runtime.resilience.snapshots import Snapshots, SnapshotStore
from beyond_self.runtime.resilience.source_plan import ResumePlan, plan
from beyond_self.runtime.resilience.state import LedgerFile, state_dir
from beyond_self.runtime.security.acl import check_declared
from beyond_self.runtime.self_report import (
    health_of,
    log_recovery,
    recovery_of,
    restarts,
    stop_counts,
)
from beyond_self.runtime.service_cli import options_from_command_line
from beyond_self.runtime.service_upstream import CLOSES, Upstream, counted
from beyond_self.schemas.base import Header, Message
from beyond_self.schemas.codec import SchemaError
from beyond_self.schemas.identity import TYPES as IDENTIFIED
from beyond_self.schemas.keys import check_name
from beyond_self.schemas.messages import Progress, ServiceHealth, StreamClock

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
    """Subclass, set `name` (or pass it), override `setup()`."""

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
        self.config = config
        self._bus = bus
        self._owns_bus = bus is None
        self.clock = clock or Clock.from_env()
        if health_period is not None:
            self.health_period = health_period
        self.log = logging.getLogger(f"beyond.{self.name}")
        self.started = asyncio.Event()
        self.account = ErrorAccount(self.log, self.name)
        self._stop = asyncio.Event()
        self._subscriptions: list[tuple[Subscription[Any], Handler[Any]]] = []
        self._publishers: list[Publisher[Any]] = []
        self._progress = ProgressReport(self.name, self.header)
        self.ledgers = Keeper(self.name, self.header)  # exactly once (runtime.resilience.ledger)
        self.fleet_member = False  # run by runtime.fleet for one robot of many
        self._once: set[str] = set()  # keys whose handling is not repeated after a restart
        self._upstreams: list[Upstream] = []  # numbered event streams (`complete=`)
        self._gates: dict[str, InputGate[Any]] = {}  # sensor key -> its restored position
        # what `keep_state` keeps: the snapshots, and how to ask for the state now
        self._state: tuple[Snapshots[Any], Callable[[], Any]] | None = None
        self.times = SourceTimes()  # whose time each sensor key keeps (runtime.event_time)
        self._recovery_reported: tuple[int, int] = (0, 0)
        self._tasks: set[asyncio.Task[Any]] = set()
        self._timers: set[asyncio.TimerHandle] = set()
        self._seq = 0
        self._health_seq = 0
        self.started_at = time.monotonic()

    # --- for subclasses --------------------------------------------------------------------

    async def setup(self) -> None:
        """Open subscriptions, publishers and queryables here."""

    async def teardown(self) -> None:
        """Release anything `setup` acquired beyond subscriptions and publishers."""

    @property
    def subscriptions(self) -> list[Subscription[Any]]:
        return [s for s, _ in self._subscriptions]

    @property
    def publishers(self) -> list[Publisher[Any]]:
        return list(self._publishers)

    @property
    def paced_keys(self) -> set[str]:
        return set(self._progress.paced)

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
        `delivery` says (runtime.bus.delivery), each identity once (runtime.resilience.ledger). With
        `paced`
        (sensor inputs), the stamp of every message handled is published as `Progress`, so a
        player never outruns this service; `key` belongs to one source (runtime.event_time):
        another's messages, and the owner's not after the last one handled (a restarted
        source repeats what was handled), are skipped and counted. With
        `once` (a handler whose effect is not to be repeated: a sentence said), a restarted
        instance does not handle again what its predecessor handled; given the effect's own
        log (runtime.resilience.effect_log), nor what that log says was done. With `complete`
        (a numbered event stream from `producer`, runtime.service_upstream), the base counts
        what was received and calls `complete(stamp)` once every event `producer` derived from
        its input up to `stamp` has arrived."""
        self._check_declared("subscribe", key)
        upstream = None
        if complete is not None:
            upstream = Upstream(key, producer, complete)
            self._upstreams.append(upstream)
            handler = counted(upstream, handler)
        sub = self.bus.subscribe(key, cls, delivery, on_malformed=self.account.malformed)
        if (gate := self._gates.get(key)) is not None:
            handler = gated(gate, handler)
        self._subscriptions.append((sub, handler))
        if cls in IDENTIFIED:
            self.ledgers.handled.declare(key)
        if once:
            self._once.add(key)
        if isinstance(once, EffectLog):
            take_over(self.ledgers, key, cls, once, self.log)
        if paced:
            self._progress.pace(key)
            self.times.track(key)
        if self.started.is_set():
            self.spawn(self._consume(sub, handler), key)
        if upstream is not None:  # the producer's progress says when its events are complete
            self.subscribe(self.bus.keys.progress(producer), Progress, upstream.progress)
        return sub

    def publisher(self, key: str, cls: type[M], delivery: Delivery = RELIABLE) -> Publisher[M]:
        """A publisher of `cls` messages on `key`, sending as `delivery` says."""
        self._check_declared("publish", key)
        pub = self.bus.publisher(key, cls, delivery)
        if cls in IDENTIFIED:
            pub.suppress = self.ledgers.suppressed
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

    def done_downstream(self, key: str, kind: str) -> set[int]:
        """Gestures whose `kind` on this service's output `key` every consumer has, and which
        are said: a successor does not work on them again (runtime.resilience.ledger)."""
        return self.ledgers.done_downstream(key, kind)

    def seen_downstream(self, key: str, kinds: tuple[str, ...]) -> set[int]:
        """Gestures some consumer of this service's output `key` has had with one of `kinds`
        (a predecessor's numbering, what it closed)."""
        return self.ledgers.seen_downstream(key, kinds)

    def resume_plan(self, pacer: Pacer) -> ResumePlan:
        """A source's resume plan (runtime.resilience.source_plan), once `pacer` has heard its
        consumers: what they all have, moved back to what their successors need again."""
        keys = self.bus.keys
        return plan(self.ledgers, pacer.handled_by_all(), keys.gesture_segment, keys.description)

    def _closed(self, key: str) -> set[int]:
        """Gestures of the events on `key` closed for this service: its last per-gesture output
        every consumer has, or cancelled (runtime.service_upstream)."""
        done = [self.done_downstream(p.key, CLOSES[p.cls]) for p in self._publishers
                if p.cls in CLOSES]  # fmt: skip
        closed = set.intersection(*done) if done else set()
        return closed | self.seen_downstream(key, ("cancel",))

    def state_folder(self) -> Path | None:
        """This service's state folder on this machine (runtime.resilience.state); None without
        one, or when a fleet runs it for one of its robots (the robot's side keeps its own)."""
        return None if self.fleet_member else state_dir(self.bus.keys.robot, self.name)

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
        if self._state is not None:
            raise RuntimeError(f"{self.name}: keep_state called twice")
        folder = self.state_folder()
        store = SnapshotStore(folder) if folder is not None else None
        snapshots = Snapshots(cls, self.ledgers, store, self.bus.keys.description, inputs)
        restored = snapshots.chosen(restarted=restarts() > 0)
        restore(restored)
        gate = InputGate(restored, lambda: snapshots.newest, restore, on_gap)
        for key in inputs:
            if key in self._gates or any(sub.key == key for sub, _ in self._subscriptions):
                raise RuntimeError(f"{self.name}: keep_state after {key} was subscribed")
            self._gates[key] = gate
        self._state = (snapshots, snapshot)
        return snapshots

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
        self.account.error(key, exc)

    def _query_failed(self, key: str, exc: Exception) -> None:
        if isinstance(exc, SchemaError):
            self.account.malformed_other += 1
            self.account.malformed(key, exc)
        else:
            self.report_error(key, exc)

    def _check_declared(self, kind: str, key: str) -> None:
        check_declared(self.name, type(self), kind, key, self.bus.keys.root)

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

    # --- health and progress -------------------------------------------------------------

    def health_report(self) -> ServiceHealth:
        """This service's `ServiceHealth`: what it received, sent, dropped, could not read."""
        seq = self._health_seq
        self._health_seq += 1
        return health_of(self, seq)

    def received_counts(self) -> dict[str, int]:
        """Messages received per input key, as reported in `Progress` (a service whose inputs
        carry their own sequence numbers may report those instead: they survive a restart)."""
        counts = {s.key: s.received for s, _ in self._subscriptions}
        counts.update({up.key: up.received for up in self._upstreams})
        return counts

    def published_counts(self) -> dict[str, int]:
        """Messages published per output key, as reported in `Progress` (a service whose
        outputs carry their own running count may report that instead: it survives a
        restart)."""
        return {p.key: p.sent for p in self._publishers}

    def progress_report(self) -> Progress:
        """How far each paced input is handled, and what was received and published
        (runtime.progress)."""
        stamps = {p.key: p.last_stamp for p in self._publishers}
        now = self.clock.now_ns()  # as it stands now: it bounds a stream with no owner yet
        for key in self._progress.paced:
            self._progress.handled_up_to(key, self.times.progress(key, ceiling=now))
        return self._progress.report(self.published_counts(), self.received_counts(), stamps)

    def publish_progress(self) -> None:
        self._progress.publish(self.progress_report())

    def recovery(self) -> tuple[int, int]:
        """(recovered, missed): messages of recovering subscriptions that came from publisher
        caches after a link failure or a late start, and those no cache held any more."""
        return recovery_of(self.subscriptions)

    async def _consume(self, sub: Subscription[Any], handler: Handler[Any]) -> None:
        ledgers, progress, times = self.ledgers, self._progress, self.times
        paced, identified = times.tracked(sub.key), sub.cls in IDENTIFIED
        refusal: list[Exception] = []  # the current message's, if its handler refused it

        def fresh(received: Received[Any]) -> bool:
            refusal.clear()
            if identified and ledgers.duplicate(received.key, received.message) is not None:
                return False
            if paced:
                header = received.message.header
                verdict = times.verdict(sub.key, header.source, header.stamp)
                if verdict is Verdict.FOREIGN:
                    self.account.refused(sub.key, times.why_foreign(sub.key, header.source))
                return verdict is Verdict.FRESH
            return True

        def failed(key: str, exc: Exception) -> None:
            refusal.append(exc)
            self.report_error(key, exc)

        def done(received: Received[Any]) -> None:
            header = received.message.header
            refused = bool(refusal) and isinstance(refusal[0], InputError)
            # bad input is counted and forgotten: no time, no owner, no ledger entry
            if refused:
                times.refuse(sub.key, header.source, header.stamp)
            elif times.take(sub.key, header.source, header.stamp):  # the key's own stream
                self.clock.observe(header.stamp)
            if identified and not refused:
                ledgers.record(received.key, received.message)
            if self._state is not None:
                snapshots, snapshot = self._state
                try:
                    snapshots.offer(snapshot())
                except Exception as exc:  # counted; the next message offers one again
                    self.report_error("snapshot", exc)
            if progress.wanted:
                self.publish_progress()

        await consume(sub, handler, failed, after=done, accept=fresh)

    def _follow_clock(self) -> None:
        """On a replay, follow the player's stream clock (runtime.clock), so that health and
        progress are stamped on the stream's time even when no input has come for a while."""
        # not one of the subscriptions (nor in health's inputs): a malformed tick is counted
        # as malformed input outside them, as a malformed query is
        sub = self.bus.subscribe(
            self.bus.keys.clock, StreamClock, STATUS, on_malformed=self._query_failed
        )

        def tick(message: StreamClock) -> None:
            self.clock.observe(message.header.stamp)

        self.spawn(consume(sub, tick, self.report_error), "clock")

    async def _report_periodically(self) -> None:
        pub = self.bus.publisher(self.bus.keys.health(self.name), ServiceHealth, STATUS)
        loop = asyncio.get_running_loop()
        # the first report at once (it shows the service is up), the next ones at a phase of
        # the period of this robot's own: a fleet's runs start together when their robots
        # appear, and reports in step would build and send a health report and a ledger for
        # every robot in one go each second, a burst that every gesture under way queues behind
        due = loop.time() + self.health_period * report_phase(self.bus.keys.robot)
        while True:
            pub.put(self.health_report())
            if self._progress.paced:
                self.publish_progress()
            self.ledgers.tick()
            self._recovery_reported = log_recovery(self, self._recovery_reported)
            await asyncio.sleep(max(due - loop.time(), 0.0))
            due = max(due, loop.time()) + self.health_period

    # --- lifecycle ------------------------------------------------------------------------

    def stop(self) -> None:
        """Ask the service to stop (safe from signal handlers and other tasks)."""
        self._stop.set()

    async def run(self, *, install_signals: bool = True) -> None:
        """Open the bus (unless given one), set up, serve until stopped, clean up."""
        if self._bus is None:
            config = self.config or load_config()
            if config.secure is not None and config.identity is None:
                config = config.with_(identity=self.name)
            self._bus = Bus.open(config)
            self._owns_bus = True
        installed = process.install_signals(self.stop) if install_signals else []
        undeclare_token: Callable[[], None] | None = None
        try:
            # before setup: a restarted one resumes
            self.ledgers.said_key = self.bus.keys.description
            if (folder := self.state_folder()) is not None:
                self.ledgers.file = LedgerFile(folder)
            await self.ledgers.ask(self.bus, self.log, restarted=restarts() > 0)
            await self.setup()
            for upstream in self._upstreams:  # restarted: the gestures it had closed
                upstream.closed(self._closed(upstream.key))
            outputs = [p.key for p in self._publishers if p.cls in IDENTIFIED]
            self.ledgers.adopt(self._once, outputs)
            self.spawn(self.ledgers.open(self.bus, self.report_error), "ledger")
            for sub, handler in self._subscriptions:
                self.spawn(self._consume(sub, handler), sub.key)
            if self.clock.is_recording:
                self._follow_clock()
            health_key = self.bus.keys.health(self.name)

            async def answer_health(_key: str, _request: None) -> list[tuple[str, Message]]:
                return [(health_key, self.health_report())]

            self.queryable(health_key, None, answer_health)
            if self._progress.paced:
                progress_key = self.bus.keys.progress(self.name)

                async def answer_progress(_key: str, _request: None) -> Progress:
                    return self.progress_report()

                self.queryable(progress_key, None, answer_progress)
                self._progress.open(self.bus, self.progress_report())
            self.spawn(self._report_periodically(), "health")
            undeclare_token = self.bus.declare_token(self.bus.keys.alive(self.name))
            self.started.set()
            heap.settle_soon()
            event(self.log, logging.INFO, "started", service=self.name, robot=self.bus.keys.robot)
            await self._stop.wait()
        finally:
            await self._shut_down(undeclare_token)
            for sig in installed:
                asyncio.get_running_loop().remove_signal_handler(sig)

    async def _shut_down(self, undeclare_token: Callable[[], None] | None) -> None:
        for timer in self._timers:
            timer.cancel()
        self._timers.clear()
        tasks = list(self._tasks)
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        if undeclare_token is not None:
            undeclare_token()
        for sub, _ in self._subscriptions:
            sub.close()
        for pub in self._publishers:
            pub.close()
        try:
            await self.teardown()
        except Exception as exc:
            self.report_error("teardown", exc)
        heap.release()
        stopped = stop_counts(self, self.health_report())
        event(self.log, logging.INFO, "stopped", **stopped)
        if self._owns_bus and self._bus is not None:
            self._bus.close()
            self._bus = None

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
