"""Event time per source (runtime.event_time), apart from the bus: a sensor key belongs to the
first source whose message is taken, another source's messages are foreign and move nothing,
a refused message moves nothing, and a jump forward is a pause, not an attack."""

from __future__ import annotations

from beyond_self.runtime.event_time import RECENT_STAMPS, SourceTimes, Verdict

KEY = "beyond/robot/sensors/skeleton"
HOUR = 3600 * 10**9
NEVER = 2**63  # no clock bounds it


def test_the_first_source_taken_owns_the_key_and_a_stranger_never_moves_its_time() -> None:
    times = SourceTimes()
    times.track(KEY)
    assert times.verdict(KEY, "simulator", 10) is Verdict.FRESH
    assert times.take(KEY, "simulator", 10)
    assert times.owner(KEY) == "simulator"
    # a wall-clock stamp years later from `beyond pub`: foreign, counted, and nothing moves
    assert times.verdict(KEY, "beyond-pub", 10**18) is Verdict.FOREIGN
    assert not times.take(KEY, "beyond-pub", 10**18)
    assert (times.foreign, times.handled(KEY), times.progress(KEY, ceiling=NEVER)) == (1, 10, 10)
    # so the owner's next frame is fresh, not stale
    assert times.verdict(KEY, "simulator", 11) is Verdict.FRESH
    assert times.stale == 0


def test_a_repeat_is_no_loss_an_unread_old_stamp_is_stale_and_a_pause_is_neither() -> None:
    times = SourceTimes()
    times.track(KEY)
    times.take(KEY, "ingest", 100)
    times.refuse(KEY, "ingest", 101)  # read, though refused: its repeat is a repeat too
    # a restarted source plays again from where its consumers need: nothing is lost
    assert times.verdict(KEY, "ingest", 100) is Verdict.REPEAT
    assert times.verdict(KEY, "ingest", 101) is Verdict.FRESH  # after the last *handled*
    assert times.verdict(KEY, "ingest", 50) is Verdict.STALE  # never read: out of order, lost
    assert (times.repeated, times.stale) == (1, 1)
    assert times.verdict(KEY, "ingest", 100 + 24 * HOUR) is Verdict.FRESH  # a day idle


def test_repeats_are_told_within_a_bounded_count_of_stamps() -> None:
    times = SourceTimes()
    times.track(KEY)
    for stamp in range(1, 5 * RECENT_STAMPS):
        times.take(KEY, "ingest", stamp)
    assert times.verdict(KEY, "ingest", 5 * RECENT_STAMPS - 1) is Verdict.REPEAT
    assert times.verdict(KEY, "ingest", 1) is Verdict.STALE  # forgotten: counted as lost


def test_a_refused_message_claims_nothing_and_moves_no_time() -> None:
    times = SourceTimes()
    times.track(KEY)
    # the README's incomplete frame before anything else: refused, so it owns nothing and
    # moves no time; a player may count the stream read only as far as its own clock (3)
    assert times.verdict(KEY, "beyond-pub", 10**18) is Verdict.FRESH
    times.refuse(KEY, "beyond-pub", 10**18)
    assert (times.owner(KEY), times.handled(KEY)) == (None, -1)
    assert times.progress(KEY, ceiling=3) == 3
    assert times.take(KEY, "simulator", 5)
    assert times.owner(KEY) == "simulator"
    assert times.progress(KEY, ceiling=NEVER) == 5  # the stranger's refused stamp is gone
    # the owner's own bad frame: counted, its time stays, only how far it was read moves
    times.refuse(KEY, "simulator", 6)
    assert (times.refused, times.handled(KEY), times.progress(KEY, ceiling=NEVER)) == (2, 5, 6)
    assert times.verdict(KEY, "simulator", 6) is Verdict.FRESH
    # once the key has an owner, another source's refused frame moves nothing at all
    times.refuse(KEY, "beyond-pub", 10**18)
    assert (times.refused, times.handled(KEY), times.progress(KEY, ceiling=NEVER)) == (3, 5, 6)


def test_a_stream_that_begins_with_bad_frames_is_read_as_far_as_the_clock() -> None:
    """A recording whose first frames all lack the hand: no owner yet, but a player waiting on
    the service sees it has read them (up to its own clock), so the replay goes on."""
    times = SourceTimes()
    times.track(KEY)
    for stamp in range(100, 130):
        times.refuse(KEY, "simulator", stamp)
    assert (times.owner(KEY), times.handled(KEY)) == (None, -1)
    assert times.progress(KEY, ceiling=0) == 0  # the player's clock not heard yet
    assert times.progress(KEY, ceiling=NEVER) == 129
    assert times.take(KEY, "simulator", 130)
    assert (times.owner(KEY), times.progress(KEY, ceiling=0)) == ("simulator", 130)


def test_keys_are_apart_and_an_untracked_key_is_always_fresh() -> None:
    times = SourceTimes()
    times.track(KEY)
    times.track("beyond/robot/sensors/camera")
    times.take(KEY, "a", 1)
    assert times.take("beyond/robot/sensors/camera", "b", 1)  # its own owner
    assert times.owner("beyond/robot/sensors/camera") == "b"
    assert not times.tracked("beyond/robot/language/description")
    assert times.verdict("beyond/robot/language/description", "x", 0) is Verdict.FRESH
    assert times.take("beyond/robot/language/description", "x", 0)


def test_the_line_for_a_foreign_source_names_both_sources() -> None:
    times = SourceTimes()
    times.track(KEY)
    times.take(KEY, "simulator", 1)
    line = times.why_foreign(KEY, "beyond-pub")
    assert "'beyond-pub'" in line and "'simulator'" in line and KEY in line
    assert "\n" not in line
