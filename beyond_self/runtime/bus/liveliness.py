"""Who is there: liveliness tokens, declared, watched, awaited and listed.

A service declares a token at `keys.alive(name)` while it runs; Zenoh withdraws it when the
service stops or its session is lost (a crash, a cut link), so a token's presence is the one
answer to "is that service there", across processes and machines, with no heartbeat of ours.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable

import zenoh

from beyond_self.runtime.bus.inbox import Inbox, direct_callback, undeclare


def declare_token(session: zenoh.Session, key: str) -> Callable[[], None]:
    """Declare a token on `key`; returns the undeclare."""
    token = session.liveliness().declare_token(key)
    return lambda: undeclare(token)


def watch_tokens(
    session: zenoh.Session, key_expr: str, on_change: Callable[[str, bool], None]
) -> Callable[[], None]:
    """Call `on_change(key, present)` on the running event loop for every token matching
    `key_expr` that appears (including those already there) or goes. Returns the undeclare."""
    loop = asyncio.get_running_loop()

    def on_sample(sample: zenoh.Sample) -> None:  # Zenoh thread
        present = sample.kind == zenoh.SampleKind.PUT
        with contextlib.suppress(RuntimeError):  # loop closed: nobody is listening
            loop.call_soon_threadsafe(on_change, str(sample.key_expr), present)

    sub = session.liveliness().declare_subscriber(
        key_expr, direct_callback(on_sample), history=True
    )
    return lambda: undeclare(sub)


async def live_tokens(session: zenoh.Session, key_expr: str, timeout: float = 1.0) -> list[str]:
    """Keys of the tokens currently matching `key_expr`."""

    def get() -> list[str]:
        replies = session.liveliness().get(key_expr, timeout=timeout)
        return sorted({str(r.ok.key_expr) for r in replies if r.ok is not None})

    return await asyncio.to_thread(get)


async def wait_tokens(
    session: zenoh.Session,
    key_expr: str,
    done: Callable[[int], bool],
    wanted: str,
    timeout: float,
) -> set[str]:
    """Wait until the number of tokens matching `key_expr` satisfies `done`; their keys."""
    loop = asyncio.get_running_loop()
    inbox: Inbox[tuple[str, bool]] = Inbox(loop, 1024)

    def on_sample(sample: zenoh.Sample) -> None:
        inbox.push((str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT))

    sub = session.liveliness().declare_subscriber(
        key_expr, direct_callback(on_sample), history=True
    )
    # The history arrives as samples too; a query answers "none" for the empty case.
    alive: set[str] = set(await live_tokens(session, key_expr, timeout=min(timeout, 1.0)))
    deadline = loop.time() + timeout
    try:
        while True:
            while len(inbox):
                key, present = await inbox.get(0)
                (alive.add if present else alive.discard)(key)
            if done(len(alive)):
                return alive
            remaining = deadline - loop.time()
            try:
                key, present = await inbox.get(max(remaining, 0.0))
            except TimeoutError:
                raise TimeoutError(
                    f"{len(alive)} live tokens on {key_expr} after {timeout} s, wanted "
                    f"{wanted}: {sorted(alive)}"
                ) from None
            (alive.add if present else alive.discard)(key)
    finally:
        undeclare(sub)
