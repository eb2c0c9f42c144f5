"""The base every service stands on: lifecycle, liveliness, health, counting, logging.

A service subclasses `Service`, names the streams it touches in class attributes (`subscribes`,
`publishes`, `serves`: stream and queryable names of schemas/keys.py, from which runtime/acl.py
generates a secure router's access rules), opens them in `setup()` with
`self.subscribe(key, Type, handler)`, `self.publisher(key, Type)` and `self.bus.queryable(...)`
(a key the class did not declare is refused there, so the rules cannot drift from the code;
a class that declares nothing is not checked, and has no place on a secure bus), and is run with
`asyncio.run(service.run())` (or `Service.main()`). It stops cleanly on SIGINT/SIGTERM:
consumers are cancelled, subscribers, publishers, queryables and the liveliness token are
undeclared, then the session closes.

Bad input never stops a service: a payload that does not decode is counted as malformed and
logged once per (key, reason); an `InputError` raised by a handler is counted as an error and
logged; the service goes on with the next message.
"""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import logging
import os
import signal
import sys
import time
from collections.abc import Awaitable, Callable
from typing import Any, Literal, NoReturn, TypeVar, overload

from core.errors import InputError
from runtime.bus import Bus, Publisher, Subscription
from runtime.clock import Clock
from runtime.config import BusConfig, load_config
from runtime.log import event, setup_logging
from runtime.reliable import (
    RecoveryPolicy,
    ReliablePublisher,
    ReliableSubscription,
    reliable_publisher,
    reliable_subscription,
)
from schemas.base import Header, Message
from schemas.codec import SchemaError
from schemas.keys import PROGRESS, check_name
from schemas.messages import Progress, ServiceHealth

M = TypeVar("M", bound=Message)
Handler = Callable[[M], Awaitable[None] | None]
_MAX_REMEMBERED_REASONS = 1000


REASON_MAX = 500  # characters of a logged reason (and of ServiceHealth.last_error)


def _bounded(text: str, limit: int = REASON_MAX) -> str:
    """`text` on one line of at most `limit` characters: a hostile payload's error (a 5,000-joint
    frame's list of joint names) must not become a 95 KB log line that a reader chokes on."""
    text = " ".join(text.split())
    if len(text) <= limit:
        return text
    return f"{text[: limit - 30]}... ({len(text)} characters)"


class Service:
    """Subclass, set `name` (or pass it), override `setup()`."""

    name: str = "service"
    health_period: float = 1.0
    subscribes: tuple[str, ...] | None = None  # stream names (schemas.keys.STREAMS)
    publishes: tuple[str, ...] | None = None
    serves: tuple[str, ...] | None = None  # queryable names (runtime.acl.QUERYABLES)

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
        self._stop = asyncio.Event()
        self._subscriptions: list[
            tuple[Subscription[Any] | ReliableSubscription[Any], Handler[Any]]
        ] = []
        self._publishers: list[Publisher[Any] | ReliablePublisher[Any]] = []
        self._paced: set[str] = set()  # keys whose handled stamps are reported as Progress
        self._handled: dict[str, int] = {}
        self._last_handled: dict[str, int] = {}
        self._progress: Publisher[Progress] | None = None
        self._recovery_reported: tuple[int, int] = (0, 0)
        self._tasks: list[asyncio.Task[None]] = []
        self._seen_reasons: set[tuple[str, str]] = set()
        self._seq = 0
        self._health_seq = 0
        self._started_at = time.monotonic()
        self.errors = 0
        self.malformed_other = 0
        self.last_error = ""

    # --- for subclasses --------------------------------------------------------------------

    async def setup(self) -> None:
        """Declare subscriptions and publishers here."""

    async def teardown(self) -> None:
        """Release anything `setup` acquired beyond subscriptions and publishers."""

    @property
    def bus(self) -> Bus:
        if self._bus is None:
            raise RuntimeError("the bus is open only while the service runs")
        return self._bus

    @overload
    def subscribe(
        self,
        key: str,
        cls: type[M],
        handler: Handler[M],
        *,
        maxsize: int = ...,
        recover: Literal[False] = ...,
        paced: bool = ...,
    ) -> Subscription[M]: ...

    @overload
    def subscribe(
        self,
        key: str,
        cls: type[M],
        handler: Handler[M],
        *,
        maxsize: int = ...,
        recover: Literal[True] | RecoveryPolicy,
        paced: bool = ...,
    ) -> ReliableSubscription[M]: ...

    def subscribe(
        self,
        key: str,
        cls: type[M],
        handler: Handler[M],
        *,
        maxsize: int = 1024,
        recover: bool | RecoveryPolicy = False,
        paced: bool = False,
    ) -> Subscription[M] | ReliableSubscription[M]:
        """Call `handler(message)` for every well-formed `cls` message on `key`. With `recover`,
        messages lost while a link was down come back from the publishers' caches (in order,
        once each; see runtime.reliable). With `paced` (sensor inputs), the stamp of every
        message handled is published as `Progress`, so a player never outruns this service."""
        self._check_declared("subscribe", key)
        sub: Subscription[M] | ReliableSubscription[M]
        if recover:
            policy = recover if isinstance(recover, RecoveryPolicy) else None
            sub = reliable_subscription(
                self.bus, key, cls, maxsize=maxsize, on_malformed=self._malformed, policy=policy
            )
        else:
            sub = self.bus.subscribe(key, cls, maxsize=maxsize, on_malformed=self._malformed)
        self._subscriptions.append((sub, handler))
        if paced:
            self._paced.add(key)
            self._handled.setdefault(key, -1)
        if self.started.is_set():
            self._tasks.append(asyncio.get_running_loop().create_task(self._consume(sub, handler)))
        return sub

    @overload
    def publisher(
        self, key: str, cls: type[M], *, reliable: bool = ..., cache: None = ...
    ) -> Publisher[M]: ...

    @overload
    def publisher(
        self, key: str, cls: type[M], *, reliable: bool = ..., cache: int
    ) -> ReliablePublisher[M]: ...

    def publisher(
        self, key: str, cls: type[M], *, reliable: bool = True, cache: int | None = None
    ) -> Publisher[M] | ReliablePublisher[M]:
        """A publisher; with `cache`, one that keeps its last `cache` messages for subscribers
        that recover (`subscribe(..., recover=True)`) after a link failure or a late start.
        A cached publisher never blocks (`reliable` is ignored): what a congested or dead link
        drops comes back from the cache (runtime.reliable.ReliablePublisher)."""
        self._check_declared("publish", key)
        pub: Publisher[M] | ReliablePublisher[M]
        if cache is not None:
            pub = reliable_publisher(self.bus, key, cls, cache=cache)
        else:
            pub = self.bus.publisher(key, cls, reliable=reliable)
        self._publishers.append(pub)
        return pub

    def _check_declared(self, kind: str, key: str) -> None:
        """Refuse a key the class did not declare (when it declares anything)."""
        if all(getattr(self, a) is None for a in ("subscribes", "publishes", "serves")):
            return
        if kind == "subscribe" and key.startswith(f"{self.bus.keys.root}/{PROGRESS}/"):
            return  # how far others have got: every service may read it (runtime.acl)
        from runtime.acl import declaration_of, declared_keys

        allowed = declared_keys(declaration_of(self.name, type(self)), self.bus.keys.root)[kind]
        if key not in allowed:
            raise InputError(
                f"service {self.name!r} may {kind} only on the keys its class declares "
                f"({', '.join(sorted(allowed)) or 'none'}), not {key}; add it to "
                f"{type(self).__qualname__}'s declarations"
            )

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
        return Header(
            version=cls.VERSION,
            source=self.name,
            seq=seq,
            stamp=self.clock.now_ns() if stamp is None else stamp,
            correlation=f"{self.name}/{seq}",
        )

    # --- health ---------------------------------------------------------------------------

    def health(self) -> ServiceHealth:
        seq = self._health_seq
        self._health_seq += 1
        subs = [s for s, _ in self._subscriptions]
        return ServiceHealth(
            header=Header(
                version=ServiceHealth.VERSION,
                source=self.name,
                seq=seq,
                stamp=self.clock.now_ns(),
                correlation=f"{self.name}/health/{seq}",
            ),
            service=self.name,
            uptime_s=round(time.monotonic() - self._started_at, 3),
            messages_in=sum(s.received for s in subs),
            messages_out=sum(p.sent for p in self._publishers),
            dropped=sum(s.dropped for s in subs),
            malformed=sum(s.malformed for s in subs) + self.malformed_other,
            errors=self.errors,
            last_error=self.last_error,
            inputs=sorted({s.key for s in subs}),
            outputs=sorted(
                {p.key for p in self._publishers}
                | ({self.bus.keys.progress(self.name)} if self._paced else set())
            ),
        )

    def _malformed(self, key: str, error: SchemaError) -> None:
        key, reason = _bounded(key, 200), _bounded(str(error))
        self.last_error = reason
        if (key, reason) not in self._seen_reasons:
            if len(self._seen_reasons) < _MAX_REMEMBERED_REASONS:
                self._seen_reasons.add((key, reason))
            event(self.log, logging.WARNING, "malformed payload skipped", key=key, reason=reason)

    def _failed(self, key: str, exc: BaseException) -> None:
        self.errors += 1
        key = _bounded(key, 200)
        self.last_error = _bounded(f"{type(exc).__name__}: {exc}")
        if isinstance(exc, InputError):
            reason = _bounded(str(exc))
            if (key, reason) not in self._seen_reasons:
                if len(self._seen_reasons) < _MAX_REMEMBERED_REASONS:
                    self._seen_reasons.add((key, reason))
                event(self.log, logging.WARNING, "bad input skipped", key=key, reason=reason)
        else:
            self.log.error(
                "handler failed", exc_info=exc, extra={"fields": {"key": key, "service": self.name}}
            )

    async def _consume(
        self, sub: Subscription[Any] | ReliableSubscription[Any], handler: Handler[Any]
    ) -> None:
        async for received in sub:
            self.clock.observe(received.message.header.stamp)
            try:
                result = handler(received.message)
                if inspect.isawaitable(result):
                    await result
            except asyncio.CancelledError:
                raise
            except Exception as exc:
                self._failed(received.key, exc)
            if sub.key in self._paced:
                self._last_handled[sub.key] = received.message.header.stamp
            if self._paced:
                self.publish_progress()

    def received_counts(self) -> dict[str, int]:
        """Messages received per input key, as reported in `Progress` (a service whose inputs
        carry their own sequence numbers may report those instead: they survive a restart)."""
        return {s.key: s.received for s, _ in self._subscriptions}

    async def resume(self) -> None:
        """A restarted instance does not publish again what its predecessor already did: the
        player keeps the last `Progress` of every service it paces (runtime.pacing), which says
        up to which stamp each output key was published."""
        try:
            replies = await self.bus.query(self.bus.keys.progress(self.name), Progress, timeout=2.0)
        except (InputError, TimeoutError):
            return
        done = {k: v for r in replies for k, v in r.message.published_stamps.items()}
        for pub in self._publishers:
            pub.skip_until = max(pub.skip_until, done.get(pub.key, -1))
        if any(v >= 0 for v in done.values()):
            event(self.log, logging.INFO, "resuming after a previous instance", **done)

    def publish_progress(self) -> None:
        """Publish how far each paced input is handled, how many messages each subscription
        received and each publisher sent: after the handler, so everything an input caused has
        been published before its progress says so."""
        for key, stamp in self._last_handled.items():
            self._handled[key] = max(self._handled.get(key, -1), stamp)
        if self._progress is not None:
            self._progress.put(
                Progress(
                    header=self.header(Progress, max(self._handled.values(), default=0)),
                    service=self.name,
                    handled=self._handled,
                    published={p.key: p.sent for p in self._publishers},
                    received=self.received_counts(),
                    published_stamps={p.key: p.last_stamp for p in self._publishers},
                )
            )

    async def _publish_health(self) -> None:
        pub = self.bus.publisher(self.bus.keys.health(self.name), ServiceHealth, reliable=False)
        while True:
            pub.put(self.health())
            if self._paced:
                self.publish_progress()
            self._report_recovery()
            await asyncio.sleep(self.health_period)

    def recovery(self) -> tuple[int, int]:
        """(recovered, missed): messages of recovering subscriptions that came from publisher
        caches after a link failure or a late start, and those no cache held any more."""
        subs = [s for s, _ in self._subscriptions if isinstance(s, ReliableSubscription)]
        return sum(s.recovered for s in subs), sum(s.missed for s in subs)

    def _report_recovery(self) -> None:
        now = self.recovery()
        if now != self._recovery_reported:
            self._recovery_reported = now
            event(
                self.log,
                logging.INFO,
                "recovered messages from publisher caches",
                service=self.name,
                recovered=now[0],
                missed=now[1],
            )

    # --- lifecycle ------------------------------------------------------------------------

    def stop(self) -> None:
        """Ask the service to stop (safe from signal handlers and other tasks)."""
        self._stop.set()

    async def run(self, *, install_signals: bool = True) -> None:
        """Open the bus (unless given one), set up, serve until stopped, clean up."""
        loop = asyncio.get_running_loop()
        if self._bus is None:
            config = self.config or load_config()
            if config.secure is not None and config.identity is None:
                config = config.with_(identity=self.name)
            self._bus = Bus.open(config)
            self._owns_bus = True
        if self._owns_bus:
            own_health = self.bus.keys.health(self.name)

            def guard(key: str) -> None:
                if key != own_health:
                    self._check_declared("serve", key)

            self.bus.guard = guard
        installed: list[signal.Signals] = []
        if install_signals:
            for sig in (signal.SIGINT, signal.SIGTERM):
                try:
                    loop.add_signal_handler(sig, self.stop)
                    installed.append(sig)
                except (NotImplementedError, RuntimeError, ValueError):
                    pass  # not the main thread, or not supported here
        undeclare_token = None
        try:
            await self.setup()
            if self._paced:
                await self.resume()
            for sub, handler in self._subscriptions:
                self._tasks.append(loop.create_task(self._consume(sub, handler)))
            health_key = self.bus.keys.health(self.name)

            async def answer_health(_key: str, _payload: bytes | None) -> list[tuple[str, Message]]:
                return [(health_key, self.health())]

            self.bus.queryable(health_key, answer_health)
            if self._paced:
                # never blocking: a subscriber across a dead link (a remote monitor) must not
                # stall the pipeline; a dropped report is repaired by the next, or by the
                # periodic one beside health
                self._progress = self.bus.publisher(
                    self.bus.keys.progress(self.name), Progress, reliable=False
                )
                self._progress.put(
                    Progress(
                        header=self.header(Progress, 0), service=self.name, handled=self._handled
                    )
                )
            self._tasks.append(loop.create_task(self._publish_health()))
            undeclare_token = self.bus.declare_token(self.bus.keys.alive(self.name))
            self.started.set()
            event(self.log, logging.INFO, "started", service=self.name, robot=self.bus.keys.robot)
            await self._stop.wait()
        finally:
            for task in self._tasks:
                task.cancel()
            for task in self._tasks:
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task
            self._tasks.clear()
            if undeclare_token is not None:
                undeclare_token()
            for sub, _ in self._subscriptions:
                sub.close()
            for pub in self._publishers:
                pub.close()
            with contextlib.suppress(Exception):
                await self.teardown()
            health = self.health()
            recovered, missed = self.recovery()
            event(
                self.log,
                logging.INFO,
                "stopped",
                service=self.name,
                messages_in=health.messages_in,
                messages_out=health.messages_out,
                malformed=health.malformed,
                dropped=health.dropped,
                errors=health.errors,
                recovered=recovered,
                missed=missed,
            )
            if self._owns_bus and self._bus is not None:
                self._bus.close()
                self._bus = None
            for sig in installed:
                loop.remove_signal_handler(sig)

    @classmethod
    def main(cls, *args: Any, **kwargs: Any) -> int:
        """Entry point for a service process: logging, run until SIGINT/SIGTERM, exit 0."""
        setup_logging()

        async def go() -> None:
            await cls(*args, **kwargs).run()

        try:
            asyncio.run(go())
        except InputError as exc:
            logging.getLogger("beyond").error(str(exc))
            return 2
        return 0

    @classmethod
    def main_and_exit(cls, *args: Any, **kwargs: Any) -> NoReturn:
        """`main`, then leave at once (`exit_process`)."""
        exit_process(cls.main(*args, **kwargs))


def exit_process(code: int) -> NoReturn:
    """Leave the process at once with `code`, logs and output flushed: for a process whose
    Zenoh session is closed and whose work is done (a service, `beyond up`). The interpreter's
    own teardown of native threads (Zenoh's, BLAS's) has been seen to abort such a process
    ("FATAL: exception not rethrown", SIGABRT) after it had stopped cleanly."""
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
