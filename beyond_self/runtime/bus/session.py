"""One Zenoh session and the calls every service and tool makes on it: publish, subscribe,
query and reply, liveliness. Each call lives in the module named for it (runtime.bus.publisher,
runtime.bus.subscription, runtime.bus.queries, runtime.bus.liveliness); the bus opens the session,
hands it
to them, and closes everything it opened, in reverse order, before the session itself.

How a stream travels is one `Delivery` (runtime.bus.delivery), the same for both of its ends.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
from collections.abc import Callable, Mapping
from typing import Any, TypeVar, overload

import zenoh

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus import liveliness, queries
from beyond_self.runtime.bus.config import (
    CLIENT_WAIT_MS,
    BusConfig,
    describe,
    load_config,
    zenoh_config,
)
from beyond_self.runtime.bus.delivery import RELIABLE, Delivery
from beyond_self.runtime.bus.demux import SharedStreams
from beyond_self.runtime.bus.inbox import undeclare
from beyond_self.runtime.bus.publisher import Publisher, ZenohPublisher, declare_zenoh_publisher
from beyond_self.runtime.bus.queries import ErrorHandler, PlainQueryHandler, QueryHandler
from beyond_self.runtime.bus.subscription import (
    MalformedHandler,
    RawSubscription,
    Received,
    Subscription,
)
from beyond_self.schemas.base import Message
from beyond_self.schemas.keys import Keys

M = TypeVar("M", bound=Message)
Q = TypeVar("Q", bound=Message)
log = logging.getLogger("beyond.bus")


def open_failure(config: BusConfig, exc: Exception) -> str:
    """One line on why a session did not open: Zenoh's reason without its source location
    (" at /root/.cargo/.../orchestrator.rs:388."), and what to do when no router answered."""
    reason = re.sub(r"\s+at \S+\.rs:\d+\.?$", "", " ".join(str(exc).split()))
    if "Unable to connect" in reason and config.mode == "client":
        connect = config.endpoints()[1]
        waited = (config.connect_timeout_ms or CLIENT_WAIT_MS) / 1000
        start = "beyond router" + (f" --secure {config.secure}" if config.secure else "")
        return (
            f"no router answered at {', '.join(connect)} within {waited:g} s; start one "
            f"(`{start}`) or give its endpoint with --connect"
        )
    return f"cannot open the Zenoh session ({describe(config)}): {reason}"


sessions_opened = 0  # by this process; the `beyond` entry point reads it (cli.entry)


class Bus:
    def __init__(
        self, session: zenoh.Session, config: BusConfig, *, owns_session: bool = True
    ) -> None:
        self.session = session
        self.config = config
        self.keys = Keys(config.robot)
        self._owns_session = owns_session
        self._closers: list[Callable[[], None]] = []
        self._tasks: set[asyncio.Task[None]] = set()
        self._shared: SharedStreams | None = None

    def for_robot(self, robot: str, shared: SharedStreams | None = None) -> Bus:
        """The same session seen as robot `robot`'s bus (its keys), for one robot a fleet's
        service serves (runtime.fleet): closing it undeclares what was opened through it, and
        leaves the session open (the caller closes it when the robot leaves). With `shared`,
        its subscriptions to the robot's own keys are fed by the fleet process's shared streams
        (runtime.bus.demux)."""
        view = Bus(
            self.session,
            self.config.with_(robot=robot, robots=None, standby=None),
            owns_session=False,
        )
        view._shared = shared
        return view

    @classmethod
    def open(
        cls, config: BusConfig | None = None, *, access_rules: Mapping[str, Any] | None = None
    ) -> Bus:
        """A session as `config` says; a secure router enforces `access_rules`."""
        config = config or load_config()
        log.debug("opening Zenoh session: %s", describe(config))
        try:
            session = zenoh.open(zenoh_config(config, access_rules))
        except zenoh.ZError as exc:
            raise InputError(open_failure(config, exc)) from None
        global sessions_opened
        sessions_opened += 1
        return cls(session, config)

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def zid(self) -> str:
        return str(self.session.zid())

    def on_close(self, closer: Callable[[], None]) -> None:
        """Run `closer` when the bus closes (before the session does)."""
        self._closers.append(closer)

    # --- publish / subscribe -------------------------------------------------------------

    def publisher(self, key: str, cls: type[M], delivery: Delivery = RELIABLE) -> Publisher[M]:
        """Messages of type `cls` on `key`, sent as `delivery` says."""
        pub = Publisher(self.session, key, cls, delivery)
        self.on_close(pub.close)
        return pub

    def raw_publisher(
        self, key: str, encoding: str, delivery: Delivery = RELIABLE
    ) -> ZenohPublisher:
        """Already encoded payloads with an encoding string (replay of arbitrary channels)."""
        pub = declare_zenoh_publisher(self.session, key, encoding, delivery)
        self.on_close(lambda: undeclare(pub))
        return pub

    def subscribe(
        self,
        key: str,
        cls: type[M],
        delivery: Delivery = RELIABLE,
        *,
        on_malformed: MalformedHandler | None = None,
    ) -> Subscription[M]:
        """Messages of type `cls` on `key`, received as `delivery` says; call from the event
        loop that will consume them."""
        robot = self.keys.robot
        shared = None if self._shared is None else self._shared.stream_of(key, robot, delivery)
        sub = Subscription(
            self.session, key, cls, asyncio.get_running_loop(), delivery, on_malformed,
            shared=shared, robot=robot,
        )  # fmt: skip
        self.on_close(sub.close)
        return sub

    def subscribe_raw(self, keys: str | list[str], *, maxsize: int = 4096) -> RawSubscription:
        """Raw samples of one or more key expressions (give non-overlapping ones: a sample
        matching two of them arrives twice)."""
        keys = [keys] if isinstance(keys, str) else list(keys)
        sub = RawSubscription(self.session, keys, asyncio.get_running_loop(), maxsize)
        self.on_close(sub.close)
        return sub

    # --- query / reply -------------------------------------------------------------------

    @overload
    def queryable(
        self,
        key: str,
        request: type[Q],
        handler: QueryHandler[Q],
        *,
        on_error: ErrorHandler | None = None,
    ) -> Callable[[], None]: ...

    @overload
    def queryable(
        self,
        key: str,
        request: None,
        handler: PlainQueryHandler,
        *,
        on_error: ErrorHandler | None = None,
    ) -> Callable[[], None]: ...

    def queryable(
        self, key: str, request: Any, handler: Any, *, on_error: ErrorHandler | None = None
    ) -> Callable[[], None]:
        """Answer queries on `key` with `await handler(query_key, request)`, `request` decoded
        as the `request` type (None: queries without a payload); runtime.bus.queries.serve."""
        close, task = queries.serve(self.session, key, request, handler, on_error)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        self.on_close(close)
        return close

    async def query(
        self,
        selector: str,
        cls: type[M],
        *,
        payload: Message | None = None,
        timeout: float = 2.0,
        every: bool = False,
    ) -> list[Received[M]]:
        """Ask every matching queryable; their well-formed replies (malformed ones raise).
        `every`: all replies, also several on one key, and those of the queryables that did
        answer when another did not (an error or a timeout is skipped, not raised)."""
        return await queries.query(
            self.session, selector, cls, payload=payload, timeout=timeout, every=every
        )

    # --- liveliness ----------------------------------------------------------------------

    def declare_token(self, key: str) -> Callable[[], None]:
        """A liveliness token: others see it until it is undeclared or this process dies."""
        closer = liveliness.declare_token(self.session, key)
        self.on_close(closer)
        return closer

    def watch_tokens(
        self, key_expr: str, on_change: Callable[[str, bool], None]
    ) -> Callable[[], None]:
        """`on_change(key, present)` on the event loop for every token matching `key_expr` that
        appears (including those already there) or goes. Returns the undeclare."""
        closer = liveliness.watch_tokens(self.session, key_expr, on_change)
        self.on_close(closer)
        return closer

    async def wait_alive(self, key_expr: str, count: int = 1, timeout: float = 10.0) -> set[str]:
        """Wait until at least `count` distinct tokens match `key_expr`."""
        return await liveliness.wait_tokens(
            self.session, key_expr, lambda n: n >= count, f"{count}", timeout
        )

    async def wait_gone(self, key_expr: str, timeout: float = 10.0) -> None:
        """Wait until no token matches `key_expr` (services have stopped)."""
        await liveliness.wait_tokens(self.session, key_expr, lambda n: n == 0, "0", timeout)

    async def live_tokens(self, key_expr: str, timeout: float = 1.0) -> list[str]:
        """Keys of the tokens matching `key_expr` now."""
        return await liveliness.live_tokens(self.session, key_expr, timeout)

    def close(self) -> None:
        for closer in reversed(self._closers):
            with contextlib.suppress(Exception):
                closer()
        self._closers.clear()
        for task in list(self._tasks):
            task.cancel()
        if not self._owns_session:
            return
        with contextlib.suppress(Exception):
            self.session.close()  # type: ignore[no-untyped-call]  # zenoh's stub lacks "-> None"
