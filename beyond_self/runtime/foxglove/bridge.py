"""The live Foxglove bridge (`beyond foxglove`, `beyond up --foxglove`), served by `foxglove-sdk`.

Every key under `beyond/<robot>/` is a channel named after the key, in the recordings' JSON form
with its JSON Schema (a live view and an MCAP file of the same run look the same), plus the views
of `runtime.foxglove.views`; known channels are advertised at start so a layout finds them before
any data. Work is done only for what a client watches: an idle bridge decodes nothing. Log times
are the stamps, so a replay's timeline is the stream's. Clients connect through a handshake front
(runtime.foxglove.front) that accepts both names of the protocol.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

import foxglove

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.bus.subscription import RawSample, decode_any
from beyond_self.runtime.foxglove.front import HandshakeFront, listening_socket
from beyond_self.runtime.foxglove.views import VIEWS, VIEWS_OF, View, encode_view, is_view_key
from beyond_self.runtime.recording.format import JSON, JSONSCHEMA
from beyond_self.schemas.base import Message
from beyond_self.schemas.codec import (
    SchemaError,
    recording_json_schema_bytes,
    to_recording_json,
    type_from_encoding,
)
from beyond_self.schemas.keys import STREAMS, type_for_key

log = logging.getLogger("beyond.foxglove")
DEFAULT_PORT = 8765
ALIVE_NAME = "foxglove"  # beyond/<robot>/alive/foxglove while the bridge listens


@dataclass
class BridgeStats:
    received: int = 0  # samples taken off the bus
    forwarded: int = 0  # messages handed to the server (channels and views)
    skipped: int = 0  # samples nobody watched
    malformed: int = 0


SDK_SERVER_LOG = "foxglove.websocket.server"


class FoxgloveBridge:
    """Serve the bus of `bus.keys.robot` on ws://host:port until `run` is stopped."""

    def __init__(self, bus: Bus, *, host: str = "127.0.0.1", port: int = DEFAULT_PORT) -> None:
        self.bus = bus
        self.stats = BridgeStats()
        self._context = foxglove.Context()
        sock = listening_socket(host, port)  # InputError at once if the port is taken
        # the SDK's server announces its own port, which only our front connects to: its
        # notices would name a port no user can open (the front's is logged by the caller)
        logging.getLogger(SDK_SERVER_LOG).setLevel(logging.WARNING)
        try:
            self._server = foxglove.start_server(
                name=f"beyond-self ({bus.keys.robot})",
                host="127.0.0.1",
                port=0,  # behind the front, on a port of its own
                context=self._context,
            )
        except RuntimeError as exc:
            sock.close()
            detail = str(exc).split(":", 1)[-1].strip()
            raise InputError(f"cannot start the Foxglove server ({detail})") from None
        self._front = HandshakeFront(sock, int(self._server.port))
        # at DEBUG only: a port of our own processes, for benchmarks that bypass the front
        log.debug("foxglove-sdk server behind the front on 127.0.0.1:%d", int(self._server.port))
        self.port = self._front.port
        self._channels: dict[str, Any] = {}
        self._views: dict[str, Any] = {}
        self._offset: int | None = None  # last stamp minus its arrival: the stamps' clock
        root = bus.keys.root
        for suffix, cls in STREAMS.values():
            self._channel(f"{root}/{suffix}", cls, "")
        for view in VIEWS:
            self._views[view.name] = foxglove.Channel(
                view.topic(root),
                schema=foxglove.Schema(
                    name=view.schema_name, encoding=JSONSCHEMA, data=view.schema()
                ),
                message_encoding=JSON,
                context=self._context,
            )

    def _channel(self, key: str, cls: type[Message] | None, encoding: str) -> Any:
        channel = self._channels.get(key)
        if channel is None:
            if cls is not None:
                schema = foxglove.Schema(
                    name=cls.schema_name(),
                    encoding=JSONSCHEMA,
                    data=recording_json_schema_bytes(cls),
                )
                channel = foxglove.Channel(
                    key, schema=schema, message_encoding=JSON, context=self._context
                )
            else:  # not ours: as it came, schemaless
                channel = foxglove.Channel(
                    key,
                    message_encoding=encoding or "application/octet-stream",
                    context=self._context,
                )
            self._channels[key] = channel
        return channel

    def forward(self, sample: RawSample) -> None:
        """One bus sample to its channel and its views, for whichever have subscribers."""
        self.stats.received += 1
        if is_view_key(sample.key):  # a replayed recording's own views: ours are derived here
            self.stats.skipped += 1
            return
        cls = type_from_encoding(sample.encoding) or type_for_key(sample.key)
        channel = self._channel(sample.key, cls, sample.encoding)
        views: tuple[View, ...] = VIEWS_OF.get(cls, ()) if cls is not None else ()
        watched = [self._views[v.name] for v in views if self._views[v.name].has_sinks()]
        if not channel.has_sinks() and not watched:
            self.stats.skipped += 1
            return
        if cls is None:  # not ours: at its arrival, on the stamps' clock once there is one
            channel.log(sample.payload, log_time=sample.received_ns + (self._offset or 0))
            self.stats.forwarded += 1
            return
        try:
            message = decode_any(sample)
        except SchemaError as exc:
            self.stats.malformed += 1
            log.debug("malformed sample on %s skipped: %s", sample.key, exc)
            return
        assert message is not None  # cls is known
        stamp = message.header.stamp
        if stamp:
            self._offset = stamp - sample.received_ns
        elif self._offset is None:  # on a replay's clock before the stream began: no time yet
            self.stats.skipped += 1
            return
        # an unstamped message at its arrival moved onto the stamps' clock, as a recorder logs it
        at = stamp or sample.received_ns + self._offset
        if channel.has_sinks():
            channel.log(to_recording_json(message), log_time=at)
            self.stats.forwarded += 1
        for view in views:
            target = self._views[view.name]
            if target.has_sinks():
                target.log(encode_view(view, message), log_time=at)
                self.stats.forwarded += 1

    async def run(self, stop: asyncio.Event, ready: asyncio.Event | None = None) -> BridgeStats:
        """Forward until `stop` is set; `ready` is set once subscribed to the bus."""
        sub = self.bus.subscribe_raw(self.bus.keys.everything, maxsize=1 << 14)
        self._front.start()
        # alive like a service, so tools and scripts can wait for the bridge to be listening
        self.bus.declare_token(self.bus.keys.alive(ALIVE_NAME))
        if ready is not None:
            ready.set()
        stopper = asyncio.get_running_loop().create_task(stop.wait())
        stopper.add_done_callback(lambda _: sub.close())
        try:
            while True:
                try:
                    sample = await sub.recv()
                except EOFError:
                    break
                self.forward(sample)
        finally:
            stopper.cancel()
            sub.close()
            self._front.close()
        return self.stats

    def close(self) -> None:
        for channel in [*self._channels.values(), *self._views.values()]:
            channel.close()
        self._server.stop()


async def start_in_background(
    bus: Bus, port: int, *, host: str = "127.0.0.1"
) -> Callable[[], Awaitable[BridgeStats]]:
    """A bridge running as a task of the current loop (`beyond up --foxglove`); returns the
    coroutine function that stops it. InputError at once if the port is taken."""
    bridge = FoxgloveBridge(bus, host=host, port=port)
    stop, ready = asyncio.Event(), asyncio.Event()
    task = asyncio.get_running_loop().create_task(bridge.run(stop, ready))
    await ready.wait()
    log.info("serving %s to Foxglove on ws://%s:%d", bus.keys.everything, host, bridge.port)

    async def finish() -> BridgeStats:
        stop.set()
        try:
            return await task
        finally:
            bridge.close()

    return finish
