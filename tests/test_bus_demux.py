"""A fleet process's shared streams (runtime/bus/demux.py): one Zenoh subscriber per stream for
every robot, each robot's samples handed to its own run's subscription, in order, the history
and what came before the run subscribed included, another shard's robots not kept."""

from __future__ import annotations

import asyncio
import threading

from busutil_net import private_config

from beyond_self.runtime.bus.delivery import EVENTS, STATUS
from beyond_self.runtime.bus.demux import SharedStreams
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.bus.subscription import Subscription
from beyond_self.schemas import Header, StreamClock, WordProbabilities
from beyond_self.schemas.keys import robot_pattern


def words(seg: int) -> WordProbabilities:
    header = Header(version=1, source="test", seq=seg, stamp=1_000 + seg)
    return WordProbabilities(
        header=header, segment_id=seg, words={}, evidence={}, action_belief={}, final=True
    )


async def segments(sub: Subscription[WordProbabilities], count: int) -> list[int]:
    return [(await sub.recv(timeout=10.0)).message.segment_id for _ in range(count)]


def drain_threads(expr: str) -> int:
    return sum(t.name == f"zenoh-drain {expr}" for t in threading.enumerate())


async def test_each_robot_gets_its_own_samples_from_one_subscriber() -> None:
    with Bus.open(private_config()) as bus:
        shared = SharedStreams(bus.session, robot_pattern("lab-*"), lambda r: r != "lab-x")
        lab1, lab2, labx = (bus.for_robot(r, shared) for r in ("lab-1", "lab-2", "lab-x"))
        pubs = {v: v.publisher(v.keys.words, WordProbabilities, EVENTS) for v in (lab1, lab2, labx)}
        for seg in (1, 2):  # before any subscriber: the publishers' caches give them back
            pubs[lab1].put(words(seg))
        pubs[lab2].put(words(7))
        pubs[labx].put(words(9))
        try:
            sub1 = lab1.subscribe(lab1.keys.words, WordProbabilities, EVENTS)
            assert await segments(sub1, 2) == [1, 2]
            stream = shared.stream("language/words", EVENTS)
            for _ in range(200):  # lab-2's history came with lab-1's, and waits for its run
                if "lab-2" in stream.waiting:
                    break
                await asyncio.sleep(0.02)
            assert list(stream.waiting) == ["lab-2"]  # lab-x: another shard's, not kept
            sub2 = lab2.subscribe(lab2.keys.words, WordProbabilities, EVENTS)
            for seg in (3, 4):
                pubs[lab1].put(words(seg))
                pubs[lab2].put(words(10 + seg))
                pubs[labx].put(words(20 + seg))
            assert await segments(sub2, 3) == [7, 13, 14]
            assert await segments(sub1, 2) == [3, 4]
            assert sub1.ready() is None and sub1.missed == 0 and sub2.missed == 0
            # one subscriber and one drain thread for every robot's stream
            assert drain_threads(stream.expr) == 1
            sub1.close()  # lab-1's run ends: lab-2's goes on, lab-1's samples wait again
            pubs[lab1].put(words(5))
            pubs[lab2].put(words(15))
            assert await segments(sub2, 1) == [15]
            for _ in range(200):
                if "lab-1" in stream.waiting:
                    break
                await asyncio.sleep(0.02)
            assert [m[0] for m in stream.waiting["lab-1"].items] == [lab1.keys.words]
            shared.forget("lab-1")  # the fleet no longer expects to serve it
            assert "lab-1" not in stream.waiting
        finally:
            shared.close()


async def test_a_plain_stream_is_shared_too_and_a_robot_beyond_the_pattern_is_not() -> None:
    with Bus.open(private_config()) as bus:
        shared = SharedStreams(bus.session, robot_pattern("lab-*"), lambda r: True)
        lab1, lab2, other = (bus.for_robot(r, shared) for r in ("lab-1", "lab-2", "other"))
        try:
            subs = [v.subscribe(v.keys.clock, StreamClock, STATUS) for v in (lab1, lab2)]
            assert drain_threads(shared.stream("clock", STATUS).expr) == 1
            # a robot the pattern does not name has a subscriber of its own, as before sharing
            own = other.subscribe(other.keys.clock, StreamClock, STATUS)
            assert drain_threads(other.keys.clock) == 1
            await asyncio.sleep(0.5)  # subscribers matched
            for stamp, view in enumerate((lab2, lab1, other), start=1):
                pub = view.publisher(view.keys.clock, StreamClock, STATUS)
                await asyncio.sleep(0.2)
                pub.put(StreamClock(header=Header(version=1, source="t", seq=0, stamp=stamp)))
            got = [(await s.recv(timeout=10.0)).message.header.stamp for s in (*subs, own)]
            assert got == [2, 1, 3]
        finally:
            shared.close()
