"""The checks exactly-once makes per message (runtime.resilience.ledger): what a service has
handled, kept as ranges of frames whichever order they come in; and what a restarted producer
withholds (`Keeper.suppressed`): only a message every consumer alive has handled, of a gesture
that is said, following each ledger heard, though the said gestures are worked out once per
ledger, not once per put."""

from __future__ import annotations

import random

import beyond_self.schemas as s
from beyond_self.runtime.resilience.ledger import Handled, Keeper
from beyond_self.schemas.identity import Identity
from beyond_self.schemas.keys import Keys

KEYS = Keys("r1")


def header(_cls: type[s.Ledger], _stamp: int | None) -> s.Header:
    return s.Header(version=1, source="test", seq=0, stamp=1)


def belief(segment: int, frame: int) -> s.ActionPosterior:
    return s.ActionPosterior(
        header=s.Header(version=1, source="gestures", seq=frame, stamp=frame),
        segment_id=segment,
        frame=frame,
        actions=["grasp", "tap"],
        posterior=[0.25, 0.75],
        log_likelihood=[-3.0, -2.0],
        normalised_log_likelihood=[-0.3, -0.2],
    )


def consumer(name: str, key: str, *handled: Identity, instance: int = 0) -> s.Ledger:
    keeper = Keeper(name, header)
    keeper.instance = instance
    keeper.handled.declare(key)
    for ident in handled:
        keeper.handled.add(key, ident)
    return keeper.ledger()


def runs(frames: set[int]) -> list[list[int]]:
    """The maximal runs of consecutive frames, as [first, last] ranges."""
    out: list[list[int]] = []
    for f in sorted(frames):
        if out and f == out[-1][1] + 1:
            out[-1][1] = f
        else:
            out.append([f, f])
    return out


def test_handled_frames_are_the_runs_of_what_came_in_any_order() -> None:
    rng = random.Random(7)
    for trial in range(200):
        # mostly in order, as a stream comes; some repeated (a restart), some out of order
        frames = list(range(rng.randrange(1, 40)))
        for _ in range(rng.randrange(0, 6)):
            i, j = rng.randrange(len(frames)), rng.randrange(len(frames))
            frames[i], frames[j] = frames[j], frames[i]
        frames = [f for f in frames if rng.random() > 0.2]
        frames += rng.sample(frames, min(len(frames), rng.randrange(0, 4)))
        handled, seen = Handled(), set()
        for f in frames:
            ident = Identity("r1", 1, "belief", f)
            assert handled.add("k", ident) == (f not in seen), (trial, frames)
            seen.add(f)
        kept = handled.keys.get("k", {}).get("belief", {}).get(1, [])
        assert kept == runs(seen), (trial, frames)
        for f in range(-1, 41):
            assert handled.has("k", Identity("r1", 1, "belief", f)) == (f in seen)


def test_a_belief_is_withheld_only_once_handled_by_every_consumer_and_said() -> None:
    producer = Keeper("gestures", header)
    producer.said_key = KEYS.description
    post = KEYS.gesture_posterior
    assert not producer.suppressed(post, belief(1, 5))  # nobody heard of: everything is sent

    producer.book.heard(consumer("reasoner", post, Identity("r1", 1, "belief", 5)))
    assert not producer.suppressed(post, belief(1, 5))  # handled, but gesture 1 is not said

    said = Identity("r1", 1, "description")
    producer.book.heard(consumer("speech", KEYS.description, said))
    assert producer.said() == {1}
    assert producer.suppressed(post, belief(1, 5))
    assert not producer.suppressed(post, belief(1, 6))  # a frame the reasoner lacks
    assert not producer.suppressed(post, belief(2, 5))  # a gesture not said

    # another consumer of descriptions, which has not said gesture 1: it is not said by all
    producer.book.heard(consumer("ros2_bridge", KEYS.description))
    assert producer.said() == set()
    assert not producer.suppressed(post, belief(1, 5))
    producer.book.heard(consumer("ros2_bridge", KEYS.description, said))
    assert producer.suppressed(post, belief(1, 5))

    # the reasoner replaced by an instance that has handled nothing: it needs it all again
    producer.book.heard(consumer("reasoner", post, instance=1))
    assert not producer.suppressed(post, belief(1, 5))
