"""`beyond simulate` and `cognition.scene`: the scene's two streams agree, the file is
deterministic and self-describing, and the pipeline recovers the scene's truth from it."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from beyond_self.cli import main
from beyond_self.cognition.gestures.segmentation import segment_gestures
from beyond_self.cognition.gestures.synthetic import synthesize_continuous
from beyond_self.cognition.scene import (
    EPOCH_NS,
    PRESETS,
    Scene,
    SceneItem,
    check_scene,
    parse_scene,
    simulate_scene,
)
from beyond_self.cognition.vision.tabletop import kinect_to_table
from beyond_self.commands.simulate import check_recording, checks_pass
from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.images import image_from_message, message_from_image
from beyond_self.runtime.recording.reader import inspect_recording, read_recording
from beyond_self.runtime.recording.writer import RecordingWriter
from beyond_self.schemas import CameraFrame, CompressedCameraFrame, Header, SkeletonFrame
from beyond_self.schemas.keys import Keys


@pytest.fixture(scope="module")
def demo_scene() -> Scene:
    return simulate_scene(parse_scene("tap-ball-grasp-box"), seed=3)


@pytest.fixture(scope="module")
def touch_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("sim") / "touch.mcap"
    assert main(["simulate", "touch:blue:circle:medium", "-o", str(path), "--seed", "4"]) == 0
    return path


# ---------------------------------------------------------------- scene specs


def test_presets_and_specs_parse() -> None:
    assert [it.action for it in parse_scene("tap-ball-grasp-box")] == ["tap", "grasp"]
    demo = parse_scene("tap-ball-grasp-box")
    assert demo[0].shape == "circle" and demo[1].shape == "box"
    assert {it.action for it in parse_scene("three-actions")} == {"grasp", "tap", "touch"}
    assert len({(it.color, it.shape, it.size) for it in parse_scene("three-actions")}) == 3
    assert parse_scene("touch-box")[0].shape == "box"
    items = parse_scene("tap:yellow:circle:small, grasp:blue:box:big")
    assert items == (
        SceneItem("tap", "yellow", "circle", "small"),
        SceneItem("grasp", "blue", "box", "big"),
    )
    assert set(PRESETS) >= {"tap-ball-grasp-box", "touch-box", "three-actions"}


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("juggle-balls", "valid: a preset"),
        ("push:blue:box:big", "unknown action 'push'"),
        ("tap:red:box:big", "unknown color 'red'; valid: green1, green2, yellow, blue"),
        ("tap:blue:cone:big", "unknown shape 'cone'"),
        ("tap:blue:box:huge", "unknown size 'huge'"),
        ("tap:blue:box", "is not action:color:shape:size"),
        ("tap:blue:box:big,", "is not action:color:shape:size"),
    ],
)
def test_bad_scenes_say_what_is_valid(spec: str, message: str) -> None:
    with pytest.raises(InputError, match=message):
        parse_scene(spec)


def test_bad_arguments_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = str(tmp_path / "x.mcap")
    assert main(["simulate", "tap:red:box:big", "-o", out]) == 2
    assert "unknown color 'red'" in capsys.readouterr().err
    assert main(["simulate", "touch-box", "-o", out, "--camera-fps", "60"]) == 2
    assert "camera fps 60 out of range" in capsys.readouterr().err
    assert main(["simulate", "touch-box", "-o", str(tmp_path / "no" / "x.mcap")]) == 2
    assert main(["simulate", "touch-box", "-o", out, "--robot", "a/b"]) == 2
    assert not (tmp_path / "x.mcap").exists()


# ---------------------------------------------------------------- the scene


def test_skeleton_is_the_gesture_generators(demo_scene: Scene) -> None:
    sk = demo_scene.skeleton
    assert sk.fps == 30.0
    assert [g.action for g in sk.gestures] == ["tap", "grasp"]
    assert {"right_hand", "torso", "head", "left_hand"} <= set(sk.joints)
    # rests between gestures and around them
    first, second = sk.gestures
    assert first.start >= 30 and second.start - first.stop >= 30 and sk.n_frames - second.stop > 0
    assert sk.seed is not None
    again = synthesize_continuous(["tap", "grasp"], seed=sk.seed)
    np.testing.assert_array_equal(again.joints["right_hand"], sk.joints["right_hand"])


def _windows(sc: Scene) -> list[tuple[int, np.ndarray]]:
    """Per gesture found by the default segmenter: (item, camera frames of the object
    segmenter's window: from 0.3 s before the found start to the found end)."""
    found = segment_gestures(sc.skeleton.features())
    t = np.arange(sc.n_camera_frames) / sc.camera_fps
    out = []
    for f in found:
        k = int(
            np.argmax(
                [min(f.stop, g.bounds.stop) - max(f.start, g.bounds.start) for g in sc.gestures]
            )
        )
        window = np.flatnonzero((t >= f.start / 30 - 0.3 - 1e-9) & (t <= (f.stop - 1) / 30 + 1e-9))
        out.append((k, window))
    return out


def _check_windows(sc: Scene) -> None:
    windows = _windows(sc)
    assert sorted(k for k, _ in windows) == list(range(len(sc.gestures)))
    for k, w in windows:
        g = sc.gestures[k]
        # the first frame: this object alone on the table (what the table is learned from)
        assert sc.object_index[w[0]] == k and np.isnan(sc.hand_xyz[w[0]]).all()
        # this object throughout the approach, the contact and what follows
        during = w[w < g.experiment[1]]
        assert np.all(sc.object_index[during] == k)
        assert g.experiment[0] > w[0] and g.contact[1] <= w[-1]
        # a window running into the next gesture's sees the table empty before the next object
        later = sc.object_index[w[w >= g.experiment[1]]]
        assert set(later.tolist()) <= {k, -1, k + 1}
        if k + 1 in later:
            assert -1 in later and np.argmax(later == -1) < np.argmax(later == k + 1)


def test_each_gesture_window_starts_on_its_object_alone(demo_scene: Scene) -> None:
    sc = demo_scene
    _check_windows(sc)
    t = np.arange(sc.n_camera_frames) / sc.camera_fps
    for k, g in enumerate(sc.gestures):
        start = g.bounds.start / 30
        # before the hand moves, for at least the window's lead: the object, no hand
        before = (t >= start - 0.4) & (t < start)
        assert before.sum() >= 5
        assert np.all(sc.object_index[before] == k) and np.all(np.isnan(sc.hand_xyz[before]))
        # the object sits still until the contact, and moves after it (tap pushes the ball
        # away, grasp carries the box off)
        b0, c0 = g.block[0], g.contact[0]
        assert np.abs(sc.object_xyz[b0:c0] - sc.object_xyz[b0]).max() < 1e-12
        moved = np.linalg.norm(sc.object_xyz[g.block[1] - 1, :2] - sc.object_xyz[b0, :2])
        assert moved > 0.05


def test_gestures_chained_after_a_short_rest_still_get_their_object() -> None:
    """Here the hand barely rests between gestures: each window still opens on its object."""
    sc = simulate_scene(
        parse_scene("touch:yellow:box:big,tap:yellow:box:small,tap:green2:box:big"), 1008
    )
    g = [x.bounds for x in sc.gestures]
    assert min(b.start - a.stop for a, b in itertools.pairwise(g)) < 45  # < 1.5 s
    _check_windows(sc)


def test_overlapping_windows_get_an_empty_table_between_objects() -> None:
    """If the segmenter ends one gesture after the next one's window opens, the old object goes
    first, the table stays empty longer than the tracker keeps a lost object, and the new one is
    on the table before that window opens."""
    from beyond_self.cognition.scene import _blocks

    sk = synthesize_continuous(["tap", "touch"], seed=3)
    (a, b) = sk.gestures
    cam_t = np.arange(int((sk.n_frames - 1) / 2) + 1) / 15
    # as the segmenter might report them: the second starts where the first ends
    detected = [(a.start, a.stop + 20), (a.stop + 20, b.stop)]
    (f0, l0), (f1, l1) = _blocks(sk, cam_t, 15.0, detected)
    assert f0 == 0 and l1 == len(cam_t)
    opens = (a.stop + 20) / 30 - 0.3  # the second window
    assert cam_t[f1] <= opens  # the new object is there when it opens
    assert f1 - l0 >= 15 // 3 + 1  # empty for longer than the tracker's 5 missed frames
    # without the overlap the swap is a plain switch, 0.5 s before the gesture (long rests)
    (_, l0), (f1, _) = _blocks(sk, cam_t, 15.0, [(a.start, a.stop), (b.start, b.stop)])
    assert l0 == f1 and abs(cam_t[f1] - (b.start / 30 - 0.5)) <= 1 / 15


def test_hand_approaches_along_the_skeletons_own_track(demo_scene: Scene) -> None:
    sc = demo_scene
    hand = sc.skeleton.joints["right_hand"]
    for g in sc.gestures:
        assert sc.camera_fps == 15  # camera frame n is skeleton frame 2n
        n_contact = (g.bounds.contact_start + 1) // 2
        # the contact in the image is at the skeleton's contact instant (within half a frame)
        assert g.contact[0] - 1 == n_contact
        # drawn from when the hand is on its way (not before the segmenter finds it leaving)
        n_start = g.experiment[0]
        assert (g.bounds.start + 1) // 2 <= n_start < n_contact
        frames = np.arange(n_start, n_contact + 1)
        # skeleton frames at the camera's instants (15 fps: every other skeleton frame)
        skel = kinect_to_table(hand[frames * 2])
        cam = sc.hand_xyz[frames]
        assert np.all(np.isfinite(cam))
        # the same path, translated so that its end touches the camera's object
        np.testing.assert_allclose(cam - cam[-1], skel - skel[-1], atol=1e-9)
        # and not before
        assert np.isnan(sc.hand_xyz[n_start - 1]).all()


def test_same_seed_same_scene_other_seed_other_scene() -> None:
    items = parse_scene("touch-box")
    a, b = simulate_scene(items, 7), simulate_scene(items, 7)
    fa, fb = list(a.frames()), list(b.frames())
    assert len(fa) == a.n_camera_frames
    assert all(np.array_equal(x, y) for x, y in zip(fa, fb, strict=True))
    np.testing.assert_array_equal(a.hand_xyz, b.hand_xyz)
    c = simulate_scene(items, 8)
    assert c.n_skeleton_frames != a.n_skeleton_frames or not np.array_equal(
        c.skeleton.joints["torso"], a.skeleton.joints["torso"]
    )
    with pytest.raises(InputError, match="camera fps"):
        simulate_scene(items, 7, camera_fps=2)
    with pytest.raises(InputError, match="no items"):
        simulate_scene((), 7)


# ---------------------------------------------------------------- the file


def test_same_arguments_same_bytes(touch_file: Path, tmp_path: Path) -> None:
    again = tmp_path / "again.mcap"
    assert main(["simulate", "touch:blue:circle:medium", "-o", str(again), "--seed", "4"]) == 0
    assert again.read_bytes() == touch_file.read_bytes()
    other = tmp_path / "other.mcap"
    assert main(["simulate", "touch:blue:circle:medium", "-o", str(other), "--seed", "5"]) == 0
    assert other.read_bytes() != touch_file.read_bytes()


def test_file_layout_stamps_and_metadata(touch_file: Path) -> None:
    keys = Keys("robot")
    info = inspect_recording(touch_file)
    assert info.complete and not info.error
    channels = {c.topic: c for c in info.channels}
    assert set(channels) == {keys.skeleton, keys.camera_compressed}
    meta = info.metadata["beyond"]
    assert meta["items"] == "touch:blue:circle:medium" and meta["seed"] == "4"
    truth = json.loads(meta["truth"])
    assert truth[0]["labels"]["Color"] == "blue" and truth[0]["labels"]["ObjVel"] == "slow"
    sk_stamps, cam_stamps, frames_seen = [], [], []
    for item in read_recording(touch_file):
        msg = item.message()
        if isinstance(msg, SkeletonFrame):
            sk_stamps.append(msg.header.stamp)
            frames_seen.append(msg.frame)
            assert len(msg.joints) == 9 and msg.header.source == "simulator"
        else:
            assert isinstance(msg, CompressedCameraFrame) and msg.format == "jpeg"
            cam_stamps.append(msg.header.stamp)
    sk, cam = np.asarray(sk_stamps), np.asarray(cam_stamps)
    # frame i at 2019-01-01T00:00:00Z + i/30 s; camera frame n at + n/15 s, same clock
    assert sk[0] == cam[0] == 1_546_300_800_000_000_000 == EPOCH_NS
    np.testing.assert_array_equal(sk - sk[0], np.rint(np.arange(len(sk)) * 1e9 / 30))
    np.testing.assert_array_equal(cam - cam[0], np.rint(np.arange(len(cam)) * 1e9 / 15))
    assert frames_seen == list(range(1, len(sk) + 1))
    assert abs((sk[-1] - cam[-1]) / 1e9) < 1 / 15


def test_robot_name_raw_frames_and_camera_rate(tmp_path: Path) -> None:
    out = tmp_path / "raw.mcap"
    spec = "touch:yellow:box:small"
    args = ["simulate", spec, "-o", str(out), "--seed", "2", "--robot", "r2"]
    assert main([*args, "--format", "raw", "--camera-fps", "10"]) == 0
    keys = Keys("r2")
    scene = simulate_scene(parse_scene(spec), 2, camera_fps=10)
    rendered = scene.frames()
    n = 0
    for item in read_recording(out):
        assert item.key in (keys.skeleton, keys.camera)
        if item.key == keys.camera:
            msg = item.message()
            assert isinstance(msg, CameraFrame) and msg.encoding == "rgb8"
            assert msg.header.stamp == EPOCH_NS + round(n * 1e9 / 10)
            # raw frames are the rendered ones, bit for bit
            assert np.array_equal(image_from_message(msg), next(rendered))
            n += 1
    assert n == scene.n_camera_frames == int((scene.n_skeleton_frames - 1) / 3) + 1


def test_check_needs_a_simulated_recording(tmp_path: Path) -> None:
    path = tmp_path / "plain.mcap"
    header = Header(version=SkeletonFrame.VERSION, source="t", seq=0, stamp=1)
    with RecordingWriter(path) as writer:
        writer.write(Keys().skeleton, SkeletonFrame(header=header, frame=1, joints={}))
    with pytest.raises(InputError, match="no scene truth"):
        check_recording(path)


def test_a_standard_mcap_reader_decodes_it(touch_file: Path) -> None:
    with touch_file.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        schemas = {s.name for s in summary.schemas.values()}
        assert {"beyond.SkeletonFrame", "foxglove.CompressedImage"} <= schemas
        for schema, _channel, message in reader.iter_messages():
            if schema is not None and schema.name == "foxglove.CompressedImage":
                doc = json.loads(message.data)
                assert doc["format"] == "jpeg" and doc["frame_id"] == "camera"
                assert (
                    message.publish_time
                    == doc["timestamp"]["sec"] * 10**9 + doc["timestamp"]["nsec"]
                )
                break
        else:
            pytest.fail("no camera frame")


def test_jpeg_frames_decode_close_to_the_rendered_ones() -> None:
    sc = simulate_scene(parse_scene("touch-box"), 1)
    frames = sc.frames()
    for _ in range(30):
        img = next(frames)
    header = Header(version=CompressedCameraFrame.VERSION, source="t", seq=0, stamp=5)
    msg = message_from_image(header, img, fmt="jpeg", quality=80)
    back = image_from_message(msg)
    assert back.shape == img.shape == (240, 320, 3)
    err = np.abs(back.astype(int) - img.astype(int))
    assert err.mean() < 3.5 and np.percentile(err, 99) < 12
    assert len(msg.data) < 12_000  # what keeps the shipped recordings small


# ---------------------------------------------------------------- end to end, without the bus


def test_the_pipeline_recovers_the_scene_from_the_file(touch_file: Path) -> None:
    checks = check_recording(touch_file)
    assert len(checks) == 1 and checks[0].index == 0
    c = checks[0]
    assert c.action == "touch"
    assert c.labels["Color"] == "blue" and c.labels["Shape"] == "circle"
    assert c.labels["Size"] == "medium" and c.labels["ObjVel"] == "slow"
    assert checks_pass(checks, 1)


@pytest.mark.parametrize("seed", [11, 12])
def test_every_gesture_is_found_recognised_and_its_object_read(seed: int) -> None:
    """Random scenes of three items: one segment per item, the action recognised, the object's
    colour, shape and size and the true ObjVel measured on the gesture's camera window (JPEG
    frames, as shipped)."""
    from beyond_self.cognition.variables import ACTIONS, AFFORDANCE_VARIABLES

    rng = np.random.default_rng(seed)
    items = [
        SceneItem(
            ACTIONS[k],
            str(rng.choice(AFFORDANCE_VARIABLES["Color"])),
            str(rng.choice(AFFORDANCE_VARIABLES["Shape"])),
            str(rng.choice(AFFORDANCE_VARIABLES["Size"])),
        )
        for k in rng.permutation(3)
    ]
    sc = simulate_scene(items, seed)
    images = [image_from_message(_jpeg(img)) for img in sc.frames()]
    checks = check_scene(
        sc.skeleton.joints, sc.skeleton_stamps(), sc.camera_stamps(), images, sc.gesture_truth()
    )
    assert sorted(c.index for c in checks) == [0, 1, 2]
    for c in checks:
        item = items[c.index]
        assert c.action == item.action
        assert c.labels["Color"] == item.color
        assert c.labels["Shape"] == item.shape
        assert c.labels["Size"] == item.size
        assert c.labels["ObjVel"] == sc.gestures[c.index].labels["ObjVel"]


def _jpeg(img: np.ndarray) -> CompressedCameraFrame:
    header = Header(version=CompressedCameraFrame.VERSION, source="t", seq=0, stamp=0)
    msg = message_from_image(header, img, fmt="jpeg", quality=80)
    assert isinstance(msg, CompressedCameraFrame)
    return msg


def test_check_ends_with_a_verdict_naming_every_variable(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The recordings how-to's scene with --seed 3: its touch of a small ball reads ObjVel and
    Contact wrong from the camera (docs/how-to/recordings.md says why); `--check` exits 1 with a
    verdict line naming each of the scene's eight variables and what differed."""
    scene = "grasp:blue:box:big,touch:yellow:circle:small"
    out = tmp_path / "two.mcap"
    assert main(["simulate", scene, "-o", str(out), "--seed", "3", "--check"]) == 1
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("check FAIL: 2 of 2 item(s) found")
    for variable in ("Action", "Color", "Shape", "Size", "ObjVel", "HandVel", "ObjHandVel"):
        assert f" {variable} " in last
    assert "ObjVel 1 of 2" in last and "Contact 1 of 2" in last
