"""The synthetic tabletop: camera geometry, determinism, and effects rendered as the world says."""

from __future__ import annotations

import numpy as np
import pytest

from beyond_self.cognition.vision.pipeline import analyse_experiment
from beyond_self.cognition.vision.tabletop import Camera, kinect_to_table, simulate_experiment
from beyond_self.cognition.world import simulate_effects
from beyond_self.core.errors import InputError


def test_camera_projection() -> None:
    cam = Camera()
    assert cam.px_per_m() == pytest.approx(320.0)
    assert cam.project(np.array([0.0, 0.0, 0.0])) == pytest.approx((159.5, 119.5))
    # 10 cm right and 5 cm towards the far side: 32 px right, 16 px up
    assert cam.project(np.array([0.1, 0.05, 0.0])) == pytest.approx((191.5, 103.5))
    # lifted 20 cm towards a camera 1 m up: 1 / 0.8 times further from the centre
    assert cam.project(np.array([0.1, 0.0, 0.2])) == pytest.approx((159.5 + 40.0, 119.5))
    pts = np.random.default_rng(0).uniform(-0.3, 0.3, (10, 2))
    back = cam.table_point(cam.project(np.column_stack([pts, np.zeros(10)])))
    assert np.allclose(back, pts)
    assert Camera(640, 480).px_per_m() == pytest.approx(640.0)
    with pytest.raises(InputError):
        Camera(10, 10)


def test_same_seed_same_bytes() -> None:
    a = simulate_experiment("touch", "green1", "box", "small", np.random.default_rng(5))
    b = simulate_experiment("touch", "green1", "box", "small", np.random.default_rng(5))
    c = simulate_experiment("touch", "green1", "box", "small", np.random.default_rng(6))
    assert a.frames.tobytes() == b.frames.tobytes()
    assert a.frames.shape != c.frames.shape or a.frames.tobytes() != c.frames.tobytes()


@pytest.mark.parametrize("action", ["tap", "grasp", "touch"])
def test_the_rendered_motion_is_the_worlds(action: str) -> None:
    rng = np.random.default_rng(11)
    exp = simulate_experiment(action, "yellow", "circle", "medium", rng)
    # the effects are the world's, drawn from the same generator state
    eff = simulate_effects(action, "circle", "medium", np.random.default_rng(11))
    assert exp.labels["Shape"] == "circle" and exp.labels["Color"] == "yellow"
    assert {k: exp.labels[k] for k in eff.labels()} == exp.effects.labels()
    c0, c1 = exp.contact
    assert c1 - c0 == max(round(exp.effects.contact_s * exp.fps), 1)
    # object speed in the image (pixels -> metres) peaks at the drawn object speed
    step = np.linalg.norm(np.diff(exp.object_xyz[:, :2], axis=0), axis=1) * exp.fps
    assert step.max() == pytest.approx(exp.effects.object_speed, rel=0.15)
    # hand peak speed before contact is the drawn hand speed
    hand = np.linalg.norm(np.diff(exp.hand_xyz[: c0 + 1, :2], axis=0), axis=1) * exp.fps
    assert hand.max() == pytest.approx(exp.effects.hand_speed, rel=0.1)
    moved = np.linalg.norm(exp.object_px[-1] - exp.object_px[0])
    if action == "touch":
        assert moved < 3.0
    else:
        assert moved > 15.0
    if action == "grasp":  # carried up the image
        assert exp.object_px[-1][1] < exp.object_px[0][1] - 15


def test_a_given_hand_track_drives_the_hand() -> None:
    """A sensor-frame reach: 0.3 m towards the sensor (-z) and 0.1 m down (-y) in 0.5 s."""
    n = 16
    s = np.linspace(0.0, 1.0, n)
    smooth = 10 * s**3 - 15 * s**4 + 6 * s**5
    track = np.column_stack([0.1 * np.ones(n), 0.2 - 0.1 * smooth, 1.5 - 0.3 * smooth])
    exp = simulate_experiment(
        "tap", "blue", "box", "big", np.random.default_rng(2), hand_track=track
    )
    c0 = exp.contact[0]  # the track fills the n frames before contact
    table = kinect_to_table(track)
    assert np.allclose(np.diff(exp.hand_xyz[c0 - n : c0], axis=0), np.diff(table, axis=0))
    # towards the sensor = towards the robot = down the image: 0.3 m is 96 px at the table, more
    # higher up (the reach starts 10 cm higher, nearer the camera)
    down = exp.hand_px[c0 - 1][1] - exp.hand_px[c0 - n][1]
    assert 96 < down < 96 / (1 - 0.15) + 40
    x, y, z = exp.hand_xyz[c0 - n]
    assert exp.hand_px[c0 - n] == pytest.approx(
        (159.5 + 320 * x / (1 - z), 119.5 - 320 * y / (1 - z))
    )
    peak = np.linalg.norm(np.diff(table, axis=0), axis=1).max() * exp.fps
    assert exp.effects.hand_speed == pytest.approx(peak)
    measured = analyse_experiment(exp).effects.hand_speed
    assert measured is not None
    planar = np.linalg.norm(np.diff(table[:, :2], axis=0), axis=1).max() * exp.fps
    assert measured == pytest.approx(planar, rel=0.1)
    with pytest.raises(InputError, match="hand_track"):
        simulate_experiment("tap", "blue", "box", "big", np.random.default_rng(2), hand_track=[1])


def test_bad_labels_are_refused() -> None:
    rng = np.random.default_rng(0)
    with pytest.raises(InputError, match="Color value 'red'"):
        simulate_experiment("tap", "red", "box", "big", rng)
    with pytest.raises(InputError, match="action"):
        simulate_experiment("kick", "blue", "box", "big", rng)
