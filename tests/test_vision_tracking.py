"""Nearest-centroid tracking with gating, velocities, contact runs, effect measures."""

from __future__ import annotations

import numpy as np
import pytest

from beyond_self.cognition.vision.effects import contact_run, measure_effects
from beyond_self.cognition.vision.tracking import Tracker, peak_speed, velocities


def test_two_objects_keep_their_identity_while_moving() -> None:
    tracker = Tracker(gate_px=10)
    ids_a, ids_b = set(), set()
    for k in range(20):
        a = (10.0 + 3 * k, 50.0)  # moving right 3 px/frame
        b = (100.0, 20.0 + 0.5 * k)
        ids = tracker.update(k, [b, a] if k % 2 else [a, b])
        ids_a.add(ids[1] if k % 2 else ids[0])
        ids_b.add(ids[0] if k % 2 else ids[1])
    assert len(ids_a) == 1 and len(ids_b) == 1 and ids_a != ids_b


def test_a_jump_beyond_the_gate_starts_a_new_track_and_lost_tracks_end() -> None:
    tracker = Tracker(gate_px=5, max_missed=2)
    first = tracker.update(0, [(0.0, 0.0)])[0]
    assert tracker.update(1, [(2.0, 0.0)])[0] == first
    assert tracker.update(2, [(40.0, 0.0)])[0] != first
    for k in range(3, 7):
        tracker.update(k, [(40.0, 0.0)])
    assert first not in {t.id for t in tracker.active}


def test_velocities_of_uniform_motion_and_gappy_tracks() -> None:
    frames = np.array([0, 1, 2, 4, 5, 6])  # frame 3 missing
    pos = np.column_stack([2.0 * frames, np.zeros(6)])
    v = velocities(frames, pos, fps=30.0)
    assert np.allclose(v[:, 0], 60.0) and np.allclose(v[:, 1], 0.0)
    assert peak_speed(frames, pos, 30.0) == pytest.approx(60.0)


def test_contact_run_bridges_single_frame_gaps() -> None:
    flags = np.zeros(30, bool)
    flags[[3, 4]] = True
    flags[10:15] = True
    flags[16:20] = True  # gap of one frame at 15
    assert contact_run(flags) == (10, 20)
    assert contact_run(np.zeros(5, bool)) is None


def test_effects_of_a_pushed_object() -> None:
    """Hand approaches at up to 0.9 m/s, pushes for 4 frames, object leaves at 0.5 m/s while the
    hand goes on at 0.1 m/s: relative speed 0.4 m/s (tracks made in pixels at 320 px/m)."""
    fps, scale = 30.0, 320.0
    n = 40
    contact0, contact1 = 15, 19
    hand = np.zeros((n, 2))
    obj = np.zeros((n, 2))
    approach = 0.9 * scale / fps * np.sin(np.linspace(0, np.pi, contact0)) ** 2
    hand[1:contact0, 0] = np.cumsum(approach[:-1])
    hand[contact0:, 0] = hand[contact0 - 1, 0]
    obj[:, 0] = hand[contact0 - 1, 0] + 10
    for k in range(contact0, n):
        dt = 1.0 / fps
        v_obj = 0.5 * scale
        v_hand = v_obj if k < contact1 else 0.1 * scale
        obj[k, 0] = obj[k - 1, 0] + v_obj * dt
        hand[k, 0] = hand[k - 1, 0] + v_hand * dt
    flags = np.zeros(n, bool)
    flags[contact0:contact1] = True
    frames = np.arange(n)
    m = measure_effects(frames, obj / scale, fps, frames, hand / scale, flags)
    assert m.object_speed == pytest.approx(0.5, rel=0.02)
    assert m.hand_speed == pytest.approx(0.9, rel=0.06)
    assert m.relative_speed == pytest.approx(0.4, rel=0.05)
    assert m.contact_s == pytest.approx(4 / 30)
    without_hand = measure_effects(frames, obj / scale, fps)
    assert without_hand.hand_speed is None and without_hand.object_speed == m.object_speed
