"""Record live bus traffic into MCAP (`beyond record`)."""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass
from pathlib import Path

from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.error_account import LogOnce
from beyond_self.runtime.log import event
from beyond_self.runtime.recording.writer import DEFAULT_CHUNK_SIZE, RecordingWriter
from beyond_self.schemas.codec import SchemaError

log = logging.getLogger("beyond.record")


@dataclass
class RecordStats:
    messages: int = 0
    malformed: int = 0
    dropped: int = 0


async def record(
    bus: Bus,
    keys: list[str],
    path: str | Path,
    *,
    stop: asyncio.Event | None = None,
    duration: float | None = None,
    count: int | None = None,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
    compression: str = "zstd",
    flush_interval: float = 1.0,
    metadata: dict[str, str] | None = None,
    ready: asyncio.Event | None = None,
    foxglove_views: bool = False,
) -> RecordStats:
    """Write every sample on `keys` to `path` until `stop` is set, `duration` s passed or `count`
    messages are written. Malformed samples on our keys are logged once per problem and key,
    counted and skipped. `ready` is set once the subscribers are declared. `foxglove_views`:
    also write the Foxglove views (RecordingWriter)."""
    loop = asyncio.get_running_loop()
    stop = stop or asyncio.Event()
    deadline = None if duration is None else loop.time() + duration
    stats = RecordStats()
    once = LogOnce()
    sub = bus.subscribe_raw(keys, maxsize=65536)
    writer = RecordingWriter(
        path,
        chunk_size=chunk_size,
        compression=compression,
        flush_interval=flush_interval,
        metadata=metadata,
        foxglove_views=foxglove_views,
    )
    if ready is not None:
        ready.set()

    async def close_on_stop() -> None:
        await stop.wait()
        sub.close()  # the loop below drains what already arrived, then sees EOFError

    watcher = loop.create_task(close_on_stop())
    try:
        while count is None or stats.messages < count:
            timeout = flush_interval
            if deadline is not None:
                timeout = min(timeout, deadline - loop.time())
                if timeout <= 0:
                    break
            try:
                sample = await sub.recv(timeout)
            except TimeoutError:
                writer.maybe_flush()
                continue
            except EOFError:
                break
            try:
                writer.write_wire(sample.key, sample.payload, sample.encoding, sample.received_ns)
                stats.messages += 1
            except SchemaError as exc:
                stats.malformed += 1
                if once.first(sample.key, str(exc)):
                    event(
                        log,
                        logging.WARNING,
                        "malformed sample skipped",
                        key=sample.key,
                        reason=str(exc),
                    )
            writer.maybe_flush()
    finally:
        watcher.cancel()
        stats.dropped = sub.dropped
        sub.close()
        writer.close()
    return stats
