"""Query and reply: typed queryables served on the event loop, and typed queries.

A queryable's handler gets the query's key and its decoded request (None when the query carried
no payload) and returns a message (replied on the query's key), a list of (key, message), or
None (no reply). Whatever goes wrong (a malformed request, an `InputError` of the handler, a
bug) is answered with an error reply, so the asker learns why at once instead of timing out,
and reported to `on_error`, so the service counts it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

import zenoh

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.inbox import Inbox, direct_callback, undeclare
from beyond_self.runtime.bus.subscription import Received
from beyond_self.schemas.base import Message
from beyond_self.schemas.codec import decode, encode, wire_encoding

M = TypeVar("M", bound=Message)
Q = TypeVar("Q", bound=Message)
Answer = list[tuple[str, Message]] | Message | None
QueryHandler = Callable[[str, Q | None], Awaitable[Answer]]
PlainQueryHandler = Callable[[str, None], Awaitable[Answer]]  # queries without a payload
ErrorHandler = Callable[[str, Exception], None]

log = logging.getLogger("beyond.bus")


def _log_error(key: str, exc: Exception) -> None:
    log.warning("query on %s failed: %s", key, exc)


def serve(
    session: zenoh.Session,
    key: str,
    request: type[Q] | None,
    handler: Callable[[str, Any], Awaitable[Answer]],  # QueryHandler[Q] or PlainQueryHandler
    on_error: ErrorHandler | None = None,
) -> tuple[Callable[[], None], asyncio.Task[None]]:
    """Answer queries on `key` on the running loop; returns (undeclare, serving task)."""
    loop = asyncio.get_running_loop()
    inbox: Inbox[zenoh.Query] = Inbox(loop, 256)
    queryable = session.declare_queryable(key, direct_callback(inbox.push))
    report = on_error or _log_error

    async def answer(query: zenoh.Query) -> None:
        query_key = str(query.key_expr)
        try:
            decoded: Q | None = None
            if query.payload is not None and request is not None:  # else: a payload is ignored
                decoded = decode(query.payload.to_bytes(), request, query_key)
            reply = await handler(query_key, decoded)
            replies = [(query_key, reply)] if isinstance(reply, Message) else reply or []
            for reply_key, message in replies:
                query.reply(
                    reply_key,
                    encode(message),
                    encoding=zenoh.Encoding(wire_encoding(type(message))),
                )
        except Exception as exc:
            report(query_key, exc)
            with contextlib.suppress(Exception):
                query.reply_err(str(exc))
        finally:
            query.drop()  # type: ignore[no-untyped-call]  # zenoh's stub lacks "-> None"

    async def serving() -> None:
        while True:
            try:
                query = await inbox.get()
            except EOFError:
                return
            await answer(query)

    def close() -> None:
        undeclare(queryable)
        inbox.close()

    return close, loop.create_task(serving())


async def query(
    session: zenoh.Session,
    selector: str,
    cls: type[M],
    *,
    payload: Message | None = None,
    timeout: float = 2.0,
    every: bool = False,
) -> list[Received[M]]:
    """Ask every matching queryable; their well-formed replies (malformed ones raise). With
    `every`, replies on one key are not consolidated into the latest, and an error reply (a
    queryable that failed, a timeout) is skipped rather than raised."""
    loop = asyncio.get_running_loop()
    inbox: Inbox[zenoh.Reply] = Inbox(loop, 4096)
    done = loop.create_future()

    def resolve() -> None:
        if not done.done():
            done.set_result(None)

    def finished() -> None:
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(resolve)

    kwargs: dict[str, Any] = {"timeout": timeout}
    if every:
        kwargs["consolidation"] = zenoh.ConsolidationMode.NONE
        kwargs["target"] = zenoh.QueryTarget.ALL
    if payload is not None:
        kwargs["payload"] = encode(payload)
        kwargs["encoding"] = zenoh.Encoding(wire_encoding(type(payload)))
    session.get(selector, zenoh.handlers.Callback(inbox.push, finished), **kwargs)
    async with asyncio.timeout(timeout + 1.0):  # not wait_for: see runtime.recording.pacing
        await done
    replies: list[Received[M]] = []
    while len(inbox):
        reply = await inbox.get(0)
        sample = reply.ok
        if sample is None:
            if every:
                continue
            err = reply.err
            detail = err.payload.to_string() if err is not None else "?"
            raise InputError(f"query {selector} answered with an error: {detail}")
        key = str(sample.key_expr)
        message = decode(sample.payload.to_bytes(), cls, key)
        replies.append(Received(key, message, time.time_ns()))
    return replies
