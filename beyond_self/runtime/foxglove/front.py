"""The Foxglove clients there are, accepted: a WebSocket handshake front before foxglove-sdk.

foxglove-sdk 0.30 serves the protocol only as `foxglove.sdk.v1`, while the npm client
`@foxglove/ws-protocol`, Lichtblick and older Foxglove apps offer only `foxglove.websocket.v1`
(the same protocol). So the bridge listens itself, with the SDK's server on a loopback port
behind it: the front reads each upgrade request, asks the SDK for `foxglove.sdk.v1` and answers
the client in the name it offered. Every byte after the handshake passes unparsed, copied by
threads of its own off the bridge's event loop: one loopback hop (docs/decisions.md).
"""

from __future__ import annotations

import contextlib
import logging
import socket
import threading

from beyond_self.core.errors import InputError

log = logging.getLogger("beyond.foxglove")
SDK_SUBPROTOCOL = "foxglove.sdk.v1"  # what foxglove-sdk's server accepts
FIRST_SUBPROTOCOL = "foxglove.websocket.v1"  # the protocol's first name, offered by older clients
SUBPROTOCOLS = (SDK_SUBPROTOCOL, FIRST_SUBPROTOCOL)
_HEADER = b"sec-websocket-protocol"
_END = b"\r\n\r\n"
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
    lines = head.removesuffix(_END).split(b"\r\n")
    kept = [lines[0]] + [
        line for line in lines[1:] if line.partition(b":")[0].strip().lower() != _HEADER
    ]
    kept.append(b"Sec-WebSocket-Protocol: " + subprotocol.encode("latin-1"))
    return b"\r\n".join(kept) + _END


def _read_head(sock: socket.socket) -> tuple[bytes, bytes]:
    """(HTTP head, the bytes read after it); OSError if the peer sends none in time."""
    data = b""
    while _END not in data:
        if len(data) > _HEAD_MAX:
            raise OSError("HTTP head too long")
        more = sock.recv(4096)
        if not more:
            raise OSError("closed before the end of the HTTP head")
        data += more
    head, _, rest = data.partition(_END)
    return head + _END, rest


def _pipe(source: socket.socket, sink: socket.socket) -> None:
    """Copy until `source` ends, then end `sink`'s sending side (as the peer did)."""
    buffer = bytearray(_CHUNK)
    view = memoryview(buffer)
    with contextlib.suppress(OSError):
        while n := source.recv_into(buffer):
            sink.sendall(view[:n])
    with contextlib.suppress(OSError):
        sink.shutdown(socket.SHUT_WR)


class HandshakeFront:
    """Listens on `sock` and passes every connection to the SDK's server on loopback
    `upstream_port`, renaming the subprotocol for clients that offer only its first name."""

    def __init__(self, sock: socket.socket, upstream_port: int) -> None:
        self.sock = sock
        self.port = int(sock.getsockname()[1])
        self.upstream_port = upstream_port
        self.renamed = 0  # connections accepted under the protocol's first name
        self._open: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._closed = False

    def start(self) -> None:
        threading.Thread(target=self._accept, name="foxglove front", daemon=True).start()

    def close(self) -> None:
        """Stop accepting and end every connection (their threads then finish)."""
        with self._lock:
            self._closed = True
            sockets = [self.sock, *self._open]
        for sock in sockets:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
            sock.close()

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self.sock.accept()
            except OSError:
                return  # closed
            threading.Thread(target=self._serve, args=(client,), daemon=True).start()

    def _track(self, *socks: socket.socket) -> bool:
        with self._lock:
            if self._closed:
                return False
            self._open.update(socks)
            return True

    def _serve(self, client: socket.socket) -> None:
        upstream: socket.socket | None = None
        try:
            if not self._track(client):
                return
            client.settimeout(_HANDSHAKE_S)
            head, early = _read_head(client)
            names = offered(head)
            first_only = FIRST_SUBPROTOCOL in names and SDK_SUBPROTOCOL not in names
            if first_only:
                head = with_subprotocol(head, SDK_SUBPROTOCOL)
            upstream = socket.create_connection(("127.0.0.1", self.upstream_port), _HANDSHAKE_S)
            if not self._track(upstream):
                return
            upstream.sendall(head + early)
            answer, after = _read_head(upstream)
            if first_only and answer.startswith(b"HTTP/1.1 101"):
                answer = with_subprotocol(answer, FIRST_SUBPROTOCOL)
                self.renamed += 1
                log.info("a client speaks %s", FIRST_SUBPROTOCOL)
            client.sendall(answer + after)
            client.settimeout(None)
            upstream.settimeout(None)
            back = threading.Thread(target=_pipe, args=(upstream, client), daemon=True)
            back.start()
            _pipe(client, upstream)
            back.join()
        except OSError:
            pass  # a client that went away or sent no HTTP head: its connection, not ours
        finally:
            for sock in (client, upstream):
                if sock is not None:
                    with self._lock:
                        self._open.discard(sock)
                    sock.close()
