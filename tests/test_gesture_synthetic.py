"""The seeded skeleton-stream generator: determinism, geometry, and what each action does."""

from __future__ import annotations

import numpy as np
import pytest

from beyond_self.cognition.gestures.synthetic import (
    JOINTS,
    synthesize_continuous,
    synthesize_dataset,
    synthesize_gesture,
)
from beyond_self.core.errors import InputError


def test_same_seed_same_bytes_other_seed_other_data() -> None:
    a = synthesize_gesture("tap", 5)
    b = synthesize_gesture("tap", 5)
    c = synthesize_gesture("tap", 6)
    for j in JOINTS:
        assert a.joints[j].tobytes() == b.joints[j].tobytes()
    assert a.object_xyz.tobytes() == b.object_xyz.tobytes()
    assert a.hand.shape != c.hand.shape or not np.array_equal(a.hand, c.hand)
    d1 = synthesize_dataset(3, 0)
    d2 = synthesize_dataset(4, 0)
    # adding gestures leaves the earlier ones unchanged; other seeds share nothing
    assert all(np.array_equal(x, y) for x, y in zip(d1["grasp"], d2["grasp"], strict=False))
    d3 = synthesize_dataset(3, 1)
    assert not any(np.array_equal(x, y) for x in d1["touch"] for y in d3["touch"])


@pytest.mark.parametrize("action", ["grasp", "tap", "touch"])
def test_geometry_of_each_action(action: str) -> None:
    s = synthesize_gesture(action, 11)
    g = s.gestures[0]
    assert s.action == action and s.fps == 30.0
    assert set(JOINTS) <= set(s.joints)
    assert all(v.shape == (s.n_frames, 3) for v in s.joints.values())
    assert 0 < g.start < g.contact_start <= g.contact_stop <= g.stop < s.n_frames
    hand, torso, obj = s.hand, s.joints["torso"], s.object_xyz
    # camera frame: the person faces the sensor, ~2 m away; the object is between them
    assert 1.5 < torso[:, 2].mean() < 2.6
    assert obj[0, 2] < torso[0, 2] - 0.3
    assert obj[0, 1] < torso[0, 1] - 0.15  # on a table below the torso joint
    # at contact the hand is at the object; at rest it is back near the body
    contact = hand[g.contact_start : g.contact_stop + 1]
    assert np.min(np.linalg.norm(contact - obj[g.contact_start], axis=1)) < 0.1
    assert hand[g.stop, 2] > obj[0, 2] + 0.25
    start, end = obj[0], obj[-1]
    if action == "touch":
        assert np.linalg.norm(end - start) < 1e-9  # the object stays put
    if action == "tap":
        assert end[0] < start[0] - 0.02  # pushed along -x
        assert abs(end[1] - start[1]) < 1e-9
        # lateral approach: just before contact the hand is beside the object, at its height
        before = hand[g.contact_start - 3]
        assert before[0] > start[0] + 0.03 and abs(before[1] - start[1]) < 0.08
    if action == "grasp":
        lifted = obj[g.contact_start : g.contact_stop, 1].max()
        assert lifted > start[1] + 0.1
        assert np.linalg.norm(end - hand[g.stop]) < 0.1  # taken along to where the hand rests
        # vertical approach: before contact the hand comes down from above the object
        above = hand[g.contact_start - 8]
        assert above[1] > start[1] + 0.03


def test_continuous_stream_has_rests_between_gestures() -> None:
    s = synthesize_continuous(["grasp", "tap", "touch", "tap"], 3)
    assert [g.action for g in s.gestures] == ["grasp", "tap", "touch", "tap"]
    assert s.action is None
    for a, b in zip(s.gestures, s.gestures[1:], strict=False):
        assert b.start - a.stop >= 25  # at least ~1 s of rest
    assert len(synthesize_continuous(5, 1).gestures) == 5
    with pytest.raises(InputError):
        synthesize_continuous(["wave"], 0)
    with pytest.raises(InputError):
        synthesize_gesture("push", 0)


def test_features_are_the_motion_of_the_cut_gesture() -> None:
    s = synthesize_gesture("grasp", 2)
    start, stop = s.gesture_span()
    g = s.gestures[0]
    assert g.start <= start < g.contact_start < stop <= g.stop  # cut by the segmenter
    f = s.gesture_features()
    assert f.shape == (stop - start, 7)
    # where the hand is relative to the start (it reaches forward and comes down on the
    # object, body units), how fast (units/s) and since when (s)
    assert np.array_equal(f[0, :3], np.zeros(3))
    assert f[:, 2].min() < -1.0 and np.abs(f[:, :3]).max() < 3.0
    assert 0.5 < np.percentile(np.linalg.norm(f[:, 3:6], axis=1), 90) < 8.0
    assert np.allclose(np.diff(f[:, 6]), 1 / 30)
    positions = s.gesture_features(space="position")
    assert np.array_equal(positions, s.features()[start:stop])
