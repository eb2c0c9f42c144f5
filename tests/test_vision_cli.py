"""`beyond segment`: images, MCAP recordings, overlays, evaluation, and bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from beyond_self.cli import main
from beyond_self.cognition.vision.images import read_image, write_image
from beyond_self.cognition.vision.tabletop import Camera, make_table, simulate_experiment

REAL = "saponaro2019/lemon_and_cuboid"


def test_real_image_json_and_overlay(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    image = shared_data / REAL / "imgInput/00000000.ppm"
    mask = shared_data / REAL / "imgSeg/00000000.ppm"
    overlay = tmp_path / "overlay.png"
    code = main(
        ["segment", str(image), "--json", "--overlay", str(overlay), "--reference-mask", str(mask)]
    )
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    objects = report["objects"]
    assert len(objects) == 2
    assert {"id", "centroid", "area", "shape", "color", "size"} <= set(objects[0])
    assert [o["shape"] for o in objects] == ["circle", "box"]  # lemon left, cuboid right
    assert report["iou"] >= 0.8
    assert read_image(overlay).shape == (480, 640, 3)


def test_table_output_of_a_synthetic_frame(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    exp = simulate_experiment("touch", "green2", "box", "small", np.random.default_rng(3))
    path = write_image(tmp_path / "frame.png", exp.frames[0])
    assert main(["segment", str(path), "--size", "320x240"]) == 0
    out = capsys.readouterr().out
    assert "1 object(s)" in out and "green2" in out and "box" in out and "small" in out


def _stderr_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    return err


def test_bad_input_is_one_line_and_status_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.ppm"
    bad.write_bytes(b"P6\n320 240\n255\n\0\0")
    assert main(["segment", str(bad)]) == 2
    assert "truncated" in _stderr_line(capsys)

    blank = write_image(tmp_path / "blank.ppm", np.zeros((240, 320, 3), np.uint8))
    assert main(["segment", str(blank)]) == 2
    assert "blank" in _stderr_line(capsys)

    rng = np.random.default_rng(0)
    table = np.clip(make_table(Camera(), rng), 0, 255).astype(np.uint8)
    empty = write_image(tmp_path / "empty.png", table)
    assert main(["segment", str(empty)]) == 2
    assert "no objects found" in _stderr_line(capsys)

    assert main(["segment", str(empty), "--size", "640x480"]) == 2
    assert "expected 640x480" in _stderr_line(capsys)

    assert main(["segment", str(tmp_path / "missing.png")]) == 2
    assert "does not exist" in _stderr_line(capsys)

    assert main(["segment"]) == 2
    assert "exactly one of" in _stderr_line(capsys)


def test_mcap_recording_of_camera_frames(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import beyond_self.schemas as s
    from beyond_self.runtime.recording.writer import RecordingWriter

    exp = simulate_experiment("tap", "yellow", "circle", "big", np.random.default_rng(9))
    path = tmp_path / "rec.mcap"
    keys = s.Keys("r1")
    with RecordingWriter(path) as w:
        for i, frame in enumerate(exp.frames):
            h = s.Header(version=1, source="cam", seq=i, stamp=1_000_000_000 + i * 33_333_333)
            w.write(keys.camera, s.CameraFrame.build(h, 320, 240, frame.tobytes()))
    assert main(["segment", str(path), "--json", "--effects"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert len(report["frames"]) == len(exp.frames)
    first = report["frames"][0]["objects"]
    assert len(first) == 1 and first[0]["color"] == "yellow" and first[0]["shape"] == "circle"
    assert report["effects"]["labels"]["ObjVel"] == exp.labels["ObjVel"]
    assert report["effects"]["fps"] == pytest.approx(30.0, rel=0.01)
    assert main(["segment", str(path), "--json", "--frame", "2"]) == 0
    assert [f["index"] for f in json.loads(capsys.readouterr().out)["frames"]] == [2]
    assert main(["segment", str(path), "--frame", "999"]) == 2
    assert "no camera frame 999" in _stderr_line(capsys)


def test_evaluate_writes_confusion_matrices(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "eval"
    assert main(["segment", "--evaluate", str(out), "--experiments", "3", "--stills", "2"]) == 0
    text = capsys.readouterr().out
    assert "ObjVel: accuracy" in text and "Color: accuracy" in text
    assert (out / "confusion_experiments.png").stat().st_size > 1000
    assert (out / "confusion_objects.png").stat().st_size > 1000
    summary = json.loads((out / "summary.json").read_text())
    assert summary["experiments"]["ObjVel"]["n"] == 3
