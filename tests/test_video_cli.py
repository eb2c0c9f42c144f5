"""`beyond video FILE -o REC.mcap` on a real video of a person: a recording of skeleton frames
(the pose model's, in the gesture models' frame) and the person's images, stamped with the
video's frame times, the same bytes every time, which `beyond analyse` and `beyond up` play
alike; bad videos are one line and exit 2, a video with nobody in it exit 0, said."""

from __future__ import annotations

import contextlib
import filecmp
import io
import json
import re
import subprocess
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from busutil_net import env_for, private_config
from mcap.reader import make_reader
from pose_media import CARPHONE_FACE, carphone, write_empty_room
from rich.console import Console
from third_party_readers import official_schemas

from beyond_self.cli import main
from beyond_self.cognition.gestures.synthetic import JOINTS
from beyond_self.cognition.scene import EPOCH_NS
from beyond_self.live_view import render
from beyond_self.monitor import PipelineMonitor
from beyond_self.runtime.recording.reader import inspect_recording, read_recording
from beyond_self.schemas import (
    CompressedCameraFrame,
    Header,
    PersonPose,
    ServiceHealth,
    SkeletonFrame,
)
from beyond_self.schemas.keys import Keys
from beyond_self.services.launcher import BEYOND

FRAMES = 120  # carphone_pristine.mp4, a person in every one
FPS = 30000 / 1001


def beyond(*argv: str) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(list(argv))
    return code, out.getvalue()


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    path = tmp_path_factory.mktemp("video") / "carphone.mcap"
    code, out = beyond("video", str(carphone()), "-o", str(path))
    assert code == 0, out
    return path, out


@pytest.mark.slow  # the recording: about 9 s, shared by the tests below
def test_a_video_becomes_a_recording_stamped_with_its_frame_times(
    recorded: tuple[Path, str],
) -> None:
    path, out = recorded
    keys = Keys()
    skeletons: list[SkeletonFrame] = []
    images: list[CompressedCameraFrame] = []
    poses: list[PersonPose] = []
    for item in read_recording(path):
        msg = item.message()
        if isinstance(msg, SkeletonFrame):
            assert item.key == keys.skeleton
            skeletons.append(msg)
        elif isinstance(msg, PersonPose):
            assert item.key == keys.person_pose
            poses.append(msg)
        else:
            assert isinstance(msg, CompressedCameraFrame) and item.key == keys.person_camera
            images.append(msg)
    assert len(images) == FRAMES
    assert len(skeletons) >= 0.9 * FRAMES, f"a skeleton for {len(skeletons)} of {FRAMES} frames"
    assert f"a person in {len(skeletons)} " in out
    # each frame at its own time in the video, from the recordings' epoch
    stamps = np.array([m.header.stamp for m in images]) - EPOCH_NS
    assert np.abs(stamps - np.arange(FRAMES) * 1e9 / FPS).max() < 1e6  # within 1 ms
    by_frame = {m.frame: m for m in skeletons}
    for image in images:
        skeleton = by_frame.get(image.header.seq + 1)
        assert skeleton is None or skeleton.header.stamp == image.header.stamp
        assert (image.width, image.height, image.format) == (176, 144, "jpeg")
    for frame in skeletons:
        joints = frame.joints
        assert set(JOINTS) <= set(joints)
        assert joints["torso"].position == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
        assert joints["right_shoulder"].position[0] > 0 > joints["left_shoulder"].position[0]
        assert joints["head"].position[1] > joints["neck"].position[1] > 0
        assert joints["head"].confidence > 0.9 and joints["right_hand"].confidence < 0.5
        assert all(np.linalg.norm(j.position) < 1.2 for j in joints.values())
    # where the joints are in the image, for each skeleton, at its stamp, joint for joint
    assert [(p.frame, p.header.stamp) for p in poses] == [
        (k.frame, k.header.stamp) for k in skeletons
    ]
    x0, y0, x1, y1 = CARPHONE_FACE
    for pose, frame in zip(poses, skeletons, strict=True):
        assert set(pose.keypoints) == set(frame.joints) and (pose.width, pose.height) == (176, 144)
        u, v = pose.keypoints["head"].position
        assert x0 <= u <= x1 and y0 <= v <= y1
        assert pose.keypoints["right_hand"].confidence == frame.joints["right_hand"].confidence
    assert inspect_recording(path).metadata["beyond"]["generator"] == "beyond video"


@pytest.mark.slow
def test_the_same_video_gives_the_same_bytes(recorded: tuple[Path, str], tmp_path: Path) -> None:
    again = tmp_path / "again.mcap"
    assert beyond("video", str(carphone()), "-o", str(again))[0] == 0
    assert filecmp.cmp(recorded[0], again, shallow=False)


@pytest.mark.slow
def test_up_plays_it_as_analyse_reads_it(recorded: tuple[Path, str], tmp_path: Path) -> None:
    path, _ = recorded
    code, offline = beyond("analyse", str(path))
    assert code == 0
    config = private_config()
    env = {**env_for(config), "BEYOND_LOG_FORMAT": "text"}
    cmd = [*BEYOND, "up", "--recording", str(path), "--rate", "0", "--no-live", "--timeout", "60"]
    up = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert up.returncode == 0, up.stderr[-3000:]
    gesture_lines = [line for line in up.stdout.splitlines() if line.startswith("gesture ")]
    assert gesture_lines == offline.splitlines()
    # every frame was played and taken by the gesture streamer as a person's (none refused)
    # an image per frame, a skeleton and its pose in the image per frame with a person
    assert f"source finished after {3 * FRAMES} messages (0 dropped)" in up.stdout
    stopped = re.search(r"beyond\.gestures: stopped .*", up.stderr)
    assert stopped, up.stderr[-3000:]
    counts = dict(re.findall(r"(\w+)=(\d+)", stopped.group()))
    assert int(counts["messages_in"]) >= FRAMES
    assert counts["malformed"] == counts["errors"] == "0", stopped.group()


def test_bad_videos_are_one_line_and_exit_2(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out.mcap"
    not_video = tmp_path / "notes.mp4"
    not_video.write_text("not a video\n")
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(carphone().read_bytes()[:5000])  # the header of an mp4, no index, no frames
    for video, said in (
        (tmp_path / "missing.mp4", "does not exist"),
        (not_video, "cannot be read"),
        (cut, "cannot be read"),
    ):
        assert main(["video", str(video), "-o", str(out)]) == 2
        err = capfd.readouterr().err
        assert err.count("\n") == 1 and said in err and "Traceback" not in err, err
        assert not out.exists() and not out.with_name("out.mcap.partial").exists()


def test_a_video_with_nobody_in_it_says_so(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    room = write_empty_room(tmp_path / "room.mp4")
    out = tmp_path / "room.mcap"
    assert main(["video", str(room), "-o", str(out)]) == 0
    captured = capfd.readouterr()
    assert "no person seen" in captured.out and "20 frames" in captured.out, captured.out
    assert captured.err == "", captured.err
    counts = {c.topic: c.count for c in inspect_recording(out).channels}
    assert counts == {Keys().person_camera: 20}, counts


@pytest.mark.slow
def test_foxglove_draws_the_pose_over_the_persons_image(
    recorded: tuple[Path, str], tmp_path: Path, node_modules: Path
) -> None:
    """`beyond foxglove --export` (the bridge's views): each pose is a foxglove.ImageAnnotations
    at its image's stamp, valid under Foxglove's own schema, the joints where the person is."""
    out = tmp_path / "views.mcap"
    assert beyond("foxglove", "--export", str(recorded[0]), "-o", str(out))[0] == 0
    keys = Keys()
    view = f"{keys.root}/foxglove/pose"
    official = jsonschema.Draft202012Validator(official_schemas(node_modules)["ImageAnnotations"])
    stamps: dict[str, list[int]] = {view: [], keys.person_camera: []}
    x0, y0, x1, y1 = CARPHONE_FACE
    with out.open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages(topics=list(stamps)):
            stamps[channel.topic].append(message.log_time)
            if channel.topic != view:
                continue
            annotations = json.loads(message.data)
            official.validate(annotations)
            bones, joints = annotations["points"]
            assert bones["type"] == 4 and len(bones["points"]) == 2 * 14  # 14 bones
            assert joints["type"] == 1 and len(joints["points"]) == 15
            head = joints["points"][0]  # the joints in cognition.pose's order: head first
            assert x0 <= head["x"] <= x1 and y0 <= head["y"] <= y1
            stamp = joints["timestamp"]
            assert stamp["sec"] * 10**9 + stamp["nsec"] == message.log_time
    assert len(stamps[view]) >= 0.9 * FRAMES
    assert set(stamps[view]) <= set(stamps[keys.person_camera]), "drawn over its own image"


@pytest.mark.slow
def test_up_watches_a_video_live_to_its_end_and_stops_cleanly(tmp_path: Path) -> None:
    """`beyond up --video`: the pose runs in the ingest (the robot's side) at the video's own
    pace; the whole pipeline runs until the file ends, then every service stops, exit 0."""
    config = private_config()
    env = {**env_for(config), "BEYOND_LOG_FORMAT": "text"}
    cmd = [*BEYOND, "up", "--video", str(carphone()), "--no-live", "--timeout", "60"]
    up = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert up.returncode == 0, up.stderr[-3000:]
    pose = re.search(r"beyond\.ingest: pose (.*)", up.stderr)
    assert pose, up.stderr[-3000:]
    counts = {k: int(v) for k, v in re.findall(r"(\w+)=(\d+)", pose.group(1))}
    # every frame read; each estimated (a person seen, or counted as not) or shed, counted
    assert counts["frames"] == FRAMES
    assert counts["skeletons"] + counts["no_person"] + counts["shed"] == FRAMES
    assert counts["skeletons"] >= 1
    # the person's images, the skeletons and their poses in the images all published
    published = FRAMES + 2 * counts["skeletons"]
    assert f"source finished after {published} messages (0 dropped)" in up.stdout
    stopped = re.search(r"services stopped \(exit codes: (.*)\)", up.stderr)
    assert stopped and set(re.findall(r"\w+ (\d+)", stopped.group(1))) == {"0"}, up.stderr[-2000:]


def test_up_refuses_a_camera_that_does_not_open_or_a_missing_video_in_one_line(
    tmp_path: Path,
) -> None:
    """Before anything starts (no service, no bus): one line, exit 2; OpenCV's own complaints
    (a dozen lines from its back ends) stay quiet."""
    env = env_for(private_config())
    for source, said in (
        (["--camera", "63"], "camera 63 does not open"),
        (["--video", str(tmp_path / "missing.mp4")], "does not exist"),
    ):
        done = subprocess.run(
            [*BEYOND, "up", *source, "--no-live"],
            env=env,
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 2, done.stderr
        assert done.stderr.count("\n") == 1 and said in done.stderr, done.stderr
        assert done.stdout == ""


def test_the_live_view_shows_the_pose_rate_and_what_was_shed() -> None:
    monitor = PipelineMonitor(None, print)  # type: ignore[arg-type]  # fed by hand, no bus
    assert monitor.pose_rate == 0.0
    interval = round(1e9 / 30)

    def pose(i: int, late: int = 0) -> None:
        header = Header(PersonPose.VERSION, "ingest", i, EPOCH_NS + i * interval + late)
        monitor.on_pose(PersonPose(header=header, frame=i + 1, width=4, height=4, keypoints={}))

    for i in range(89):  # about 3 s of poses at 30 Hz
        pose(i)
    assert monitor.pose_rate == pytest.approx(30.0, rel=1e-6)
    pose(89, late=500_000_000)  # then one 0.5 s late: frames 44..89 in the last 2 s
    assert monitor.pose_rate == pytest.approx(45 / 2.0, rel=1e-6)
    header = Header(version=ServiceHealth.VERSION, source="ingest", seq=0, stamp=EPOCH_NS)
    monitor.health_reports["ingest"] = ServiceHealth(
        header=header, service="ingest", uptime_s=3.0, messages_in=0, messages_out=270,
        dropped=0, malformed=0, errors=0, skipped=7,
    )  # fmt: skip
    console = Console(width=120, record=True)
    console.print(render(monitor, ["ingest"]))
    text = console.export_text()
    assert f"pose: {monitor.pose_rate:.1f} Hz over the last 2 s, 90 frame(s) with a person" in text
    assert "7 frame(s) shed to keep up" in text
