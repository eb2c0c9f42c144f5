"""The object segmenter's per-frame description, in a process of its own.

Describing a frame (the table estimated from it, every object measured and labelled) is the
object segmenter's costliest work, and no gesture result waits for it. On a thread it shared the
GIL with the gestures' work; in a process of its own, at a lower priority when the source is
live, the system runs the gestures' work first. A frame goes to the worker through memory both
map (a memfd slot; the pipe carries its number and size) and its objects come back pickled:
a process pool pickled each 230 kB frame through a feeder and a manager thread, 0.7 ms of CPU
a frame between the two processes. The worker dies with the segmenter (runtime.process.lifeline).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import mmap
import multiprocessing
import os
import pickle
import struct
import threading
from dataclasses import dataclass
from multiprocessing.connection import Connection
from multiprocessing.reduction import recv_handle, send_handle
from typing import Any

import numpy as np

from beyond_self.cognition.vision.clusters import ClusterModel
from beyond_self.cognition.vision.pipeline import DetectedObject, describe_frame
from beyond_self.runtime.process import lifeline, native_heap

_REQUEST = struct.Struct("<cQIQQ")  # kind, request id, slot, height (or bytes), width
_NEW_SLOT, _DESCRIBE, _INLINE, _STOP = b"S", b"D", b"I", b"X"
HEAP_KEPT_BYTES = 8 * 2**20  # a frame's temporaries stay in the worker's heap (native_heap)
STOP_WAIT_S = 10.0


class DescriberGone(RuntimeError):
    """The worker process ended: nothing more is described (the segmenter is restarted)."""


@dataclass
class _Slot:
    index: int
    size: int
    memory: mmap.mmap  # holds its own descriptor of the memfd


class FrameDescriber:
    """`await describe(image)`: the frame's labelled objects, computed in the worker process.
    Callers on any event loop, several at a time (a fleet's robots); the worker takes their
    frames in turn."""

    def __init__(self, clusters: str | None, niceness: int = 0) -> None:
        context = multiprocessing.get_context("spawn")  # nothing of ours (a Zenoh session) forked
        parent = lifeline.child_env()[lifeline.ENV]  # the worker is started from this thread
        self._conn, child = context.Pipe(duplex=True)
        self._process = context.Process(
            target=_serve,
            args=(child, clusters, niceness, parent),
            name="frame describer",
            daemon=True,
        )
        self._process.start()
        child.close()  # the worker's end is the worker's alone: its exit is our end of file
        self._lock = threading.Lock()  # pending and free slots, between callers and reader
        self._send_lock = threading.Lock()  # a request's parts go out together
        self._pending: dict[int, tuple[asyncio.Future[list[DetectedObject]], _Slot | None]] = {}
        self._slots: list[_Slot] = []
        self._free: list[_Slot] = []
        self._ids = itertools.count()
        self._gone = False
        self._shared = hasattr(os, "memfd_create")  # elsewhere the frame goes on the pipe
        self._reader = threading.Thread(target=self._read, name="frame results", daemon=True)
        self._reader.start()

    async def describe(self, image: np.ndarray) -> list[DetectedObject]:
        frame = np.ascontiguousarray(image, dtype=np.uint8)
        if frame.ndim != 3 or frame.shape[2] != 3:
            raise ValueError(f"frame of shape {frame.shape}; valid: (height, width, 3) RGB")
        future: asyncio.Future[list[DetectedObject]] = asyncio.get_running_loop().create_future()
        request = next(self._ids)
        height, width = frame.shape[:2]
        with self._send_lock:
            slot = self._slot(frame.nbytes) if self._shared else None
            with self._lock:
                if self._gone:
                    raise DescriberGone("the frame describer's worker has ended")
                self._pending[request] = (future, slot)
            try:
                if slot is None:
                    self._conn.send_bytes(_REQUEST.pack(_INLINE, request, 0, height, width))
                    self._conn.send_bytes(frame.tobytes())
                else:
                    view = np.ndarray(frame.shape, np.uint8, slot.memory)
                    np.copyto(view, frame)
                    del view  # no view outlives the copy: the slot may be closed
                    self._conn.send_bytes(
                        _REQUEST.pack(_DESCRIBE, request, slot.index, height, width)
                    )
            except OSError:
                raise DescriberGone("the frame describer's worker has ended") from None
        return await future

    def _slot(self, size: int) -> _Slot:
        """A free slot of at least `size` bytes, or a new one the worker is sent (send lock
        held)."""
        with self._lock:
            for i, slot in enumerate(self._free):
                if slot.size >= size:
                    return self._free.pop(i)
        fd = os.memfd_create("beyond-frame", os.MFD_CLOEXEC)
        try:
            os.ftruncate(fd, size)
            slot = _Slot(len(self._slots), size, mmap.mmap(fd, size))
            self._slots.append(slot)
            self._conn.send_bytes(_REQUEST.pack(_NEW_SLOT, 0, slot.index, size, 0))
            send_handle(self._conn, fd, self._process.pid)
        finally:
            os.close(fd)
        return slot

    def _read(self) -> None:
        """The reader thread: each result to its caller's loop, until the worker ends."""
        while True:
            try:
                request, ok, value = pickle.loads(self._conn.recv_bytes())
            except (EOFError, OSError):
                break
            with self._lock:
                future, slot = self._pending.pop(request)
            with contextlib.suppress(RuntimeError):  # that caller's loop has closed
                future.get_loop().call_soon_threadsafe(self._settle, future, slot, ok, value)
        with self._lock:
            self._gone = True
            pending = list(self._pending.values())
            self._pending.clear()
        for future, _ in pending:
            with contextlib.suppress(RuntimeError):
                future.get_loop().call_soon_threadsafe(_fail, future)

    def _settle(
        self,
        future: asyncio.Future[list[DetectedObject]],
        slot: _Slot | None,
        ok: bool,
        value: Any,
    ) -> None:
        if slot is not None:
            with self._lock:
                self._free.append(slot)  # the worker is done with it
        if future.done():
            return  # its caller was cancelled
        if ok:
            future.set_result(value)
        else:
            future.set_exception(value)

    def close(self) -> None:
        """Stop the worker after the frames it was sent and wait for it (then kill it), and
        free the slots: the last robot run out of a process closes it."""
        with self._send_lock, contextlib.suppress(OSError):
            self._conn.send_bytes(_REQUEST.pack(_STOP, 0, 0, 0, 0))
        self._process.join(STOP_WAIT_S)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()
        self._reader.join(STOP_WAIT_S)
        self._conn.close()
        for slot in self._slots:
            slot.memory.close()
        self._slots.clear()
        self._free.clear()


def _fail(future: asyncio.Future[list[DetectedObject]]) -> None:
    if not future.done():
        future.set_exception(DescriberGone("the frame describer's worker has ended"))


def _serve(conn: Connection, clusters: str | None, niceness: int, parent: str) -> None:
    """The worker: frames in, their objects out, in the order sent, until told to stop."""
    lifeline.bind({lifeline.ENV: parent})
    from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

    threadpool_limits(limits=1, user_api="blas")
    native_heap.keep_freed(HEAP_KEPT_BYTES)
    if niceness:
        os.nice(niceness)
    model = ClusterModel.load(clusters)
    slots: dict[int, mmap.mmap] = {}
    while True:
        try:
            kind, request, index, height, width = _REQUEST.unpack(conn.recv_bytes())
        except (EOFError, OSError):
            return
        if kind == _STOP:
            return
        if kind == _NEW_SLOT:
            fd = recv_handle(conn)
            slots[index] = mmap.mmap(fd, height)
            os.close(fd)
            continue
        if kind == _INLINE:
            data = conn.recv_bytes()
            image = np.frombuffer(data, np.uint8).reshape(height, width, 3)
        else:
            image = np.ndarray((height, width, 3), np.uint8, slots[index])
        conn.send_bytes(_outcome(request, image, model))
        del image


def _outcome(request: int, image: np.ndarray, model: ClusterModel) -> bytes:
    """(request, True, objects) or (request, False, the exception), pickled."""
    try:
        result: tuple[int, bool, Any] = (
            request,
            True,
            describe_frame(image, model, require_objects=False).objects,
        )
    except Exception as exc:  # the caller's to raise: bad input is the service's to count
        result = (request, False, exc)
    try:
        return pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception as exc:  # an exception that does not pickle: its text does
        return pickle.dumps((request, False, RuntimeError(repr(exc))))
