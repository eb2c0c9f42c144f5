"""The machinery under `Service` (runtime.service): the handler loop of a subscription, the start
and stop of a run, health and progress reports, snapshots. Kept apart so the base's own module
holds only what a service author calls; nothing here is for services to call.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Coroutine, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from beyond_self.core.errors import InputError
from beyond_self.core.restorable import Restorable
from beyond_self.runtime.bus.delivery import STATUS
from beyond_self.runtime.bus.subscription import Handler, Received, Subscription, consume
from beyond_self.runtime.event_time import Verdict
from beyond_self.runtime.log import event
from beyond_self.runtime.process import heap
from beyond_self.runtime.resilience.resume import InputGate
from beyond_self.runtime.resilience.snapshots import Snapshots, SnapshotStore
from beyond_self.runtime.resilience.state import LedgerFile
from beyond_self.runtime.self_report import log_recovery, restarts, stop_counts
from beyond_self.schemas.base import Message
from beyond_self.schemas.identity import TYPES as IDENTIFIED
from beyond_self.schemas.messages import Progress, ServiceHealth, StreamClock

if TYPE_CHECKING:
    from beyond_self.runtime.bus.publisher import Publisher
    from beyond_self.runtime.bus.queries import PlainQueryHandler
    from beyond_self.runtime.bus.session import Bus
    from beyond_self.runtime.clock import Clock
    from beyond_self.runtime.error_account import ErrorAccount
    from beyond_self.runtime.event_time import SourceTimes
    from beyond_self.runtime.progress import ProgressReport
    from beyond_self.runtime.resilience.ledger import Keeper
    from beyond_self.runtime.service_upstream import Upstream


class Service(Protocol):
    """What the machinery reads and calls of a running service: the `Service` base
    (runtime.service) is one, so this module and the base's own do not import each other."""

    name: str
    log: logging.Logger
    started: asyncio.Event
    health_period: float
    _account: ErrorAccount
    _subscriptions: list[tuple[Subscription[Any], Handler[Any]]]
    _publishers: list[Publisher[Any]]
    _progress: ProgressReport
    _ledgers: Keeper
    _once: set[str]
    _upstreams: list[Upstream]
    _gates: dict[str, InputGate[Any]]
    _state: tuple[Snapshots[Any], Callable[[], Any]] | None
    _times: SourceTimes
    _recovery_reported: tuple[int, int]
    _started_at: float
    _tasks: set[asyncio.Task[Any]]
    _timers: set[asyncio.TimerHandle]

    @property
    def bus(self) -> Bus: ...
    @property
    def clock(self) -> Clock: ...
    async def setup(self) -> None: ...
    async def teardown(self) -> None: ...
    def health_report(self) -> ServiceHealth: ...
    def published_counts(self) -> dict[str, int]: ...
    def queryable(self, key: str, request: None, handler: PlainQueryHandler) -> None: ...
    def spawn(self, work: Coroutine[Any, Any, Any], name: str = "task") -> asyncio.Task[Any]: ...
    def report_error(self, key: str, exc: BaseException) -> None: ...
    def _state_folder(self) -> Path | None: ...
    def _query_failed(self, key: str, exc: Exception) -> None: ...
    def _closed(self, key: str) -> set[int]: ...


class Downstream:
    """What the consumers of one of a service's keys have had (its ledger's word on them): a
    restarted service does not work again on what is `done`, and numbers on from what it `seen`."""

    def __init__(self, service: Service, key: str) -> None:
        self._ledgers = service._ledgers
        self.key = key

    def done(self, kind: str) -> set[int]:
        """Gestures whose `kind` every consumer of the key has, and which are said."""
        return self._ledgers.done_downstream(self.key, kind)

    def seen(self, *kinds: str) -> set[int]:
        """Gestures some consumer of the key has had with one of `kinds`."""
        return self._ledgers.seen_downstream(self.key, kinds)


def keep_state(
    service: Service,
    cls: type[Restorable],
    restore: Callable[[Any], None],
    snapshot: Callable[[], Any],
    inputs: Sequence[str],
    on_gap: Callable[[Any, int], None] | None,
) -> Snapshots[Any]:
    if service._state is not None:
        raise RuntimeError(f"{service.name}: keep_state called twice")
    folder = service._state_folder()
    store = SnapshotStore(folder) if folder is not None else None
    keys = service.bus.keys
    snapshots = Snapshots(cls, service._ledgers, store, keys.description, inputs)
    restored = snapshots.chosen(restarted=restarts() > 0)
    restore(restored)
    gate = InputGate(restored, lambda: snapshots.newest, restore, on_gap)
    for key in inputs:
        if key in service._gates or any(sub.key == key for sub, _ in service._subscriptions):
            raise RuntimeError(f"{service.name}: keep_state after {key} was subscribed")
        service._gates[key] = gate
    service._state = (snapshots, snapshot)
    return snapshots


def received_counts(service: Service) -> dict[str, int]:
    """Messages received per input key, as reported in `Progress`; a numbered event stream's
    count is its own (runtime.service_upstream): it survives a restart."""
    counts = {s.key: s.received for s, _ in service._subscriptions}
    counts.update({up.key: up.received for up in service._upstreams})
    return counts


def progress_report(service: Service) -> Progress:
    """How far each paced input is handled, and what was received and published."""
    stamps = {p.key: p.last_stamp for p in service._publishers}
    now = service.clock.now_ns()  # as it stands now: it bounds a stream with no owner yet
    for key in service._progress.paced:
        service._progress.handled_up_to(key, service._times.progress(key, ceiling=now))
    published = service.published_counts()
    return service._progress.report(published, received_counts(service), stamps)


def publish_progress(service: Service) -> None:
    service._progress.publish(progress_report(service))


async def consume_loop(service: Service, sub: Subscription[Any], handler: Handler[Any]) -> None:
    """The handler loop of one subscription: each identity once, a paced key's own source's
    messages in order, then the ledger, the snapshot and the progress told."""
    ledgers, progress, times = service._ledgers, service._progress, service._times
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
                service._account.refused(sub.key, times.why_foreign(sub.key, header.source))
            return verdict is Verdict.FRESH
        return True

    def failed(key: str, exc: Exception) -> None:
        refusal.append(exc)
        service.report_error(key, exc)

    def done(received: Received[Any]) -> None:
        header = received.message.header
        refused = bool(refusal) and isinstance(refusal[0], InputError)
        # bad input is counted and forgotten: no time, no owner, no ledger entry
        if refused:
            times.refuse(sub.key, header.source, header.stamp)
        elif times.take(sub.key, header.source, header.stamp):  # the key's own stream
            service.clock.observe(header.stamp)
        if identified and not refused:
            ledgers.record(received.key, received.message)
        if service._state is not None:
            snapshots, snapshot = service._state
            try:
                snapshots.offer(snapshot())
            except Exception as exc:  # counted; the next message offers one again
                service.report_error("snapshot", exc)
        if progress.wanted:
            publish_progress(service)

    await consume(sub, handler, failed, after=done, accept=fresh)


def follow_clock(service: Service) -> None:
    """On a replay, follow the player's stream clock (runtime.clock), so that health and
    progress are stamped on the stream's time even when no input has come for a while."""
    # not one of the subscriptions (nor in health's inputs): a malformed tick is counted
    # as malformed input outside them, as a malformed query is
    bus = service.bus
    sub = bus.subscribe(bus.keys.clock, StreamClock, STATUS, on_malformed=service._query_failed)

    def tick(message: StreamClock) -> None:
        service.clock.observe(message.header.stamp)

    service.spawn(consume(sub, tick, service.report_error), "clock")


async def report_periodically(service: Service, phase: float) -> None:
    bus = service.bus
    pub = bus.publisher(bus.keys.health(service.name), ServiceHealth, STATUS)
    loop = asyncio.get_running_loop()
    # the first report at once (it shows the service is up), the next ones at a phase of the
    # period of this robot's own: a fleet's runs start together when their robots appear, and
    # reports in step would build and send a health report and a ledger for every robot in one
    # go each second, a burst that every gesture under way queues behind
    due = loop.time() + service.health_period * phase
    while True:
        pub.put(service.health_report())
        if service._progress.paced:
            publish_progress(service)
        service._ledgers.tick()
        service._recovery_reported = log_recovery(service, service._recovery_reported)
        await asyncio.sleep(max(due - loop.time(), 0.0))
        due = max(due, loop.time()) + service.health_period


async def start(service: Service, phase: float) -> Callable[[], None]:
    """Everything a run does before it serves: the others' ledgers asked (a restarted one
    resumes), `setup`, the handler loops, health, progress, the liveliness token (returned:
    its undeclaring)."""
    bus, ledgers = service.bus, service._ledgers
    ledgers.said_key = bus.keys.description
    if (folder := service._state_folder()) is not None:
        ledgers.file = LedgerFile(folder)
    await ledgers.ask(bus, service.log, restarted=restarts() > 0)
    await service.setup()
    for upstream in service._upstreams:  # restarted: the gestures it had closed
        upstream.closed(service._closed(upstream.key))
    outputs = [p.key for p in service._publishers if p.cls in IDENTIFIED]
    ledgers.adopt(service._once, outputs)
    service.spawn(ledgers.open(bus, service.report_error), "ledger")
    for sub, handler in service._subscriptions:
        service.spawn(consume_loop(service, sub, handler), sub.key)
    if service.clock.is_recording:
        follow_clock(service)
    health_key = bus.keys.health(service.name)

    async def answer_health(_key: str, _request: None) -> list[tuple[str, Message]]:
        return [(health_key, service.health_report())]

    service.queryable(health_key, None, answer_health)
    if service._progress.paced:

        async def answer_progress(_key: str, _request: None) -> Progress:
            return progress_report(service)

        service.queryable(bus.keys.progress(service.name), None, answer_progress)
        service._progress.open(bus, progress_report(service))
    service.spawn(report_periodically(service, phase), "health")
    undeclare = bus.declare_token(bus.keys.alive(service.name))
    service.started.set()
    heap.settle_soon()
    event(service.log, logging.INFO, "started", service=service.name, robot=bus.keys.robot)
    return undeclare


async def shut_down(service: Service, undeclare_token: Callable[[], None] | None) -> None:
    for timer in service._timers:
        timer.cancel()
    service._timers.clear()
    tasks = list(service._tasks)
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    if undeclare_token is not None:
        undeclare_token()
    for sub, _ in service._subscriptions:
        sub.close()
    for pub in service._publishers:
        pub.close()
    try:
        await service.teardown()
    except Exception as exc:
        service.report_error("teardown", exc)
    heap.release()
    stopped = stop_counts(service, service.health_report())
    event(service.log, logging.INFO, "stopped", **stopped)
