"""The segmenter announces a gesture's start while it unfolds (the streamer relies on it)."""

from beyond_self.cognition.gestures import GestureSegmenter, Segment, synthesize_continuous


def test_current_start_is_known_while_the_gesture_unfolds() -> None:
    stream = synthesize_continuous(["tap", "grasp"], seed=11)
    seg = GestureSegmenter()
    starts_seen: list[int] = []
    ends: list[tuple[int, int]] = []
    for x in stream.features():
        done = seg.push(x)
        if isinstance(done, Segment):
            ends.append((done.start, done.stop))
        if seg.current_start is not None and seg.current_start not in starts_seen:
            starts_seen.append(seg.current_start)
    assert len(ends) == 2
    # the start announced while the gesture was under way is the start of the final segment
    assert [s for s, _ in ends] == starts_seen[: len(ends)]
