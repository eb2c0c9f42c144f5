"""The Foxglove clients there are, accepted: a WebSocket handshake front before foxglove-sdk's
server.

foxglove-sdk 0.30 serves the Foxglove WebSocket protocol under its current subprotocol name,
`foxglove.sdk.v1`, and nothing else: a client that offers only the protocol's first name,
`foxglove.websocket.v1`, gets "HTTP 400 Missing expected sec-websocket-protocol header". The
protocol under both names is the same (Foxglove say so, and Lichtblick and Flora accept either
by adding the new name beside the old); but the npm client `@foxglove/ws-protocol` (0.8, its
`FoxgloveClient.SUPPORTED_SUBPROTOCOL`), Lichtblick releases before it added the new name and
older Foxglove apps offer only the first, while the current Foxglove app offers the new one.

So the bridge listens itself, and the SDK's server listens on an ephemeral loopback port behind
it. For each connection the front reads the HTTP upgrade request; a client that offers
`foxglove.websocket.v1` but not `foxglove.sdk.v1` is passed to the SDK asking for
`foxglove.sdk.v1`, and the SDK's answer is passed back naming the protocol the client offered.
Everything else, and every byte after the handshake, goes through unchanged in both directions
(no frame is parsed, so nothing is slower than one more loopback hop).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket

from beyond_self.core.errors import InputError

log = logging.getLogger("beyond.foxglove")
SDK_SUBPROTOCOL = "foxglove.sdk.v1"  # what foxglove-sdk's server accepts
FIRST_SUBPROTOCOL = "foxglove.websocket.v1"  # the protocol's first name, offered by older clients
SUBPROTOCOLS = (SDK_SUBPROTOCOL, FIRST_SUBPROTOCOL)
_HEADER = b"sec-websocket-protocol"
_HEAD_MAX = 16 * 1024  # bytes of an HTTP head (browsers send about 1 KiB)
_HANDSHAKE_S = 10.0
_CHUNK = 1 << 16


def listening_socket(host: str, port: int) -> socket.socket:
    """A TCP socket listening on host:port; InputError (one line, what to do) if it cannot."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
        family, kind, proto, _, address = infos[0]
        sock = socket.socket(family, kind, proto)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind(address)
            sock.listen(64)
        except OSError:
            sock.close()
            raise
    except OSError as exc:
        raise InputError(
            f"cannot serve Foxglove on {host}:{port} ({exc.strerror or exc}); "
            "choose a free port with --ws-port"
        ) from None
    sock.setblocking(False)
    return sock


def offered(head: bytes) -> list[str]:
    """The subprotocols an HTTP upgrade request offers, in its order."""
    names: list[str] = []
    for line in head.split(b"\r\n")[1:]:
        name, sep, value = line.partition(b":")
        if sep and name.strip().lower() == _HEADER:
            names += [p.strip() for p in value.decode("latin-1").split(",") if p.strip()]
    return names


def with_subprotocol(head: bytes, subprotocol: str) -> bytes:
    """`head` (an HTTP request or response head) with one Sec-WebSocket-Protocol header, naming
    `subprotocol`, in place of those it had."""
    lines = head.removesuffix(b"\r\n\r\n").split(b"\r\n")
    kept = [lines[0]] + [
        line for line in lines[1:] if line.partition(b":")[0].strip().lower() != _HEADER
    ]
    kept.append(b"Sec-WebSocket-Protocol: " + subprotocol.encode("latin-1"))
    return b"\r\n".join(kept) + b"\r\n\r\n"


class HandshakeFront:
    """Listens on `sock` and passes every connection to the SDK's server on loopback
    `upstream_port`, renaming the subprotocol for clients that offer only its first name."""

    def __init__(self, sock: socket.socket, upstream_port: int) -> None:
        self.sock = sock
        self.port = int(sock.getsockname()[1])
        self.upstream_port = upstream_port
        self.renamed = 0  # connections accepted under the first name
        self._server: asyncio.Server | None = None
        self._connections: set[asyncio.Task[None]] = set()

    async def start(self) -> None:
        self._server = await asyncio.start_server(self._accept, sock=self.sock, limit=_HEAD_MAX)

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
        for task in list(self._connections):
            task.cancel()
        await asyncio.gather(*self._connections, return_exceptions=True)
        if self._server is not None:
            await self._server.wait_closed()

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._connections.add(task)
        try:
            await self._serve(reader, writer)
        except (OSError, asyncio.IncompleteReadError, asyncio.LimitOverrunError, TimeoutError):
            pass  # a client that went away or sent no HTTP head: its connection, not ours
        except asyncio.CancelledError:
            pass  # the bridge is stopping (asyncio's server would log a cancelled handler)
        finally:
            self._connections.discard(task)
            writer.close()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), _HANDSHAKE_S)
        names = offered(head)
        first_only = FIRST_SUBPROTOCOL in names and SDK_SUBPROTOCOL not in names
        rename = FIRST_SUBPROTOCOL if first_only else None
        if rename is not None:
            head = with_subprotocol(head, SDK_SUBPROTOCOL)
        up_reader, up_writer = await asyncio.open_connection(
            "127.0.0.1", self.upstream_port, limit=_HEAD_MAX
        )
        try:
            up_writer.write(head)
            answer = await asyncio.wait_for(up_reader.readuntil(b"\r\n\r\n"), _HANDSHAKE_S)
            if rename is not None and answer.startswith(b"HTTP/1.1 101"):
                answer = with_subprotocol(answer, rename)
                self.renamed += 1
                log.info("client %s speaks %s", writer.get_extra_info("peername"), rename)
            writer.write(answer)
            pipes = [
                asyncio.ensure_future(_pipe(reader, up_writer)),
                asyncio.ensure_future(_pipe(up_reader, writer)),
            ]
            try:  # both ways until both ends close, or until one way fails
                await asyncio.wait(pipes, return_when=asyncio.FIRST_EXCEPTION)
            finally:
                for pipe in pipes:
                    pipe.cancel()
                await asyncio.gather(*pipes, return_exceptions=True)
        finally:
            up_writer.close()


async def _pipe(source: asyncio.StreamReader, sink: asyncio.StreamWriter) -> None:
    """Copy until `source` ends, then end `sink` (half-close, as the peer did)."""
    try:
        while data := await source.read(_CHUNK):
            sink.write(data)
            await sink.drain()
    finally:
        with contextlib.suppress(OSError, RuntimeError):
            if sink.can_write_eof():
                sink.write_eof()
