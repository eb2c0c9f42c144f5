"""`beyond gesture` train / stream / evaluate, in-process."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from beyond_self.cli import main
from beyond_self.cognition.gestures.model_files import load_models


def test_stream_json_on_the_article_tap(
    shared_data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = shared_data / "saponaro2019/human_data"
    argv = [
        "gesture", "stream", str(folder / "HMM_M3_Q6_mixsplit.mat"),
        str(folder / "tap_notable_seated_1"), "--frames", "121:214", "--scale", "0.001", "--json",
    ]  # fmt: skip
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["actions"] == ["grasp", "tap", "touch"]
    frames = out["frames"]
    assert [f["t"] for f in frames] == list(range(1, 95))
    last = frames[-1]
    assert last["posterior"][1] > 0.99
    assert np.argmax(last["loglik"]) == 1
    assert abs(sum(last["posterior"]) - 1.0) < 1e-12


def test_stream_table_and_bad_input(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = shared_data / "saponaro2019/human_data"
    mat = str(folder / "HMM_M1_Q6_mixsplit.mat")
    log = str(folder / "tap_notable_seated_1")
    assert main(["gesture", "stream", mat, log, "--frames", "121:130", "--garbage"]) == 0
    out = capsys.readouterr().out
    assert "P(garbage)" in out and "most probable action after 10 frames" in out
    assert main(["gesture", "stream", mat, log, "--frames", "300:999"]) == 2
    err = capsys.readouterr().err
    assert "out of range" in err and err.count("\n") == 1
    assert main(["gesture", "stream", str(tmp_path / "none.json"), log]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_train_then_evaluate_synthetic(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model_file = tmp_path / "models.json"
    argv = ["gesture", "train", "-o", str(model_file), "--count", "4", "--iter", "3",
            "--states", "4", "--mix", "1"]  # fmt: skip
    assert main(argv) == 0
    models = load_models(model_file)
    assert models.actions == ("grasp", "tap", "touch")
    assert models.meta["sequences"] == {"grasp": 4, "tap": 4, "touch": 4}
    capsys.readouterr()
    plots = tmp_path / "plots"
    argv = ["gesture", "evaluate", str(model_file), "synthetic", "--count", "3", "--json",
            "-o", str(plots)]  # fmt: skip
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["n"] == 9
    assert len(report["early"]["fractions"]) == 10
    assert np.array(report["confusion"]).sum() == 9
    assert (plots / "confusion.png").is_file() and (plots / "early_recognition.png").is_file()
    assert main(["gesture", "train", "-o", str(tmp_path / "m.pkl")]) == 2


def _write_mcap(path: Path, actions: list[str], seed: int, metadata: dict[str, str]) -> None:
    from beyond_self.cognition.gestures.synthetic import synthesize_continuous
    from beyond_self.runtime.recording.writer import RecordingWriter
    from beyond_self.schemas.base import Header
    from beyond_self.schemas.keys import Keys
    from beyond_self.schemas.messages import Joint, SkeletonFrame

    stream = synthesize_continuous(actions, seed)
    key = Keys().skeleton
    with RecordingWriter(path, metadata=metadata) as writer:
        for i in range(stream.n_frames):
            joints = {
                name: Joint(position=tuple(float(v) for v in stream.joints[name][i]))
                for name in ("right_hand", "torso", "head")
            }
            stamp = 1_000_000_000 + i * 33_333_333
            header = Header(version=1, source="test", seq=i, stamp=stamp)
            writer.write(key, SkeletonFrame(header=header, frame=i + 1, joints=joints))


def test_train_and_evaluate_from_mcap_recordings(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "recordings"
    folder.mkdir()
    _write_mcap(
        folder / "session.mcap",
        ["grasp", "tap", "touch", "tap", "grasp", "touch"],
        seed=21,
        metadata={"gesture_actions": "grasp,tap,touch,tap,grasp,touch"},
    )
    _write_mcap(folder / "tap_extra.mcap", ["tap", "tap"], seed=22, metadata={})
    model_file = tmp_path / "m.json"
    argv = ["gesture", "train", "--data", str(folder), "-o", str(model_file),
            "--states", "4", "--mix", "1", "--iter", "3"]  # fmt: skip
    assert main(argv) == 0
    assert load_models(model_file).meta["sequences"] == {"grasp": 2, "tap": 4, "touch": 2}
    capsys.readouterr()
    argv = ["gesture", "evaluate", str(model_file), str(folder / "session.mcap"), "--json",
            "-o", str(tmp_path / "plots")]  # fmt: skip
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["n"] == 6
    assert [p["action"] for p in report["predictions"]] == [
        "grasp", "tap", "touch", "tap", "grasp", "touch"
    ]  # fmt: skip
    unlabelled = tmp_path / "session2.mcap"
    _write_mcap(unlabelled, ["tap"], seed=23, metadata={})
    assert main(["gesture", "evaluate", str(model_file), str(unlabelled)]) == 2
    assert "no gesture labels" in capsys.readouterr().err


def test_train_mixes_synthetic_with_recordings(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "mixed.json"
    human = str(shared_data / "saponaro2019/human_data")
    argv = ["gesture", "train", "--data", "synthetic", "--data", human, "--push-as",
            "touch", "--count", "2", "--states", "3", "--mix", "1", "--iter", "2",
            "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    models = load_models(out)
    # two synthetic gestures per action, and the recordings' 4 grasps, 5 taps, 7 touches
    assert models.meta["sequences"] == {"grasp": 6, "tap": 7, "touch": 9}
    assert models.meta["data"] == ["synthetic", human]
    assert models.features == "motion" and models.floor is not None
    assert "floor" in capsys.readouterr().err


def test_evaluate_compare_and_realism(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    human = str(shared_data / "saponaro2019/human_data")
    small = ["--count", "2", "--states", "3", "--mix", "1", "--iter", "2"]
    argv = ["gesture", "evaluate", "compare", human, "--json", "--out", str(tmp_path), *small]
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    assert list(report) == [
        "default",
        "loro",
        "loro+synthetic",
        "logo",
        "article",
        "default@ranges",
    ]
    assert report["default"]["n"] == 16 and report["article"]["n"] == 5
    assert report["default"]["accuracy"] >= 0.9  # the shipped models, trained on nothing real
    assert report["loro"]["meta"]["without_a_model"] == {"grasp1_hand": ["grasp"]}
    for name, entry in report.items():
        assert {r["recording"] for r in entry["recordings"]} <= set(LOG_NAMES)
        for plot in entry["plots"]:
            assert Path(plot).read_bytes()[:4] == b"\x89PNG", name
    assert main(["gesture", "realism", human, "--count", "3", "--out", str(tmp_path)]) == 0
    table = capsys.readouterr().out
    assert "median hand speed (u/s)" in table and "trajectory distance (u)" in table
    assert (tmp_path / "realism.png").read_bytes()[:4] == b"\x89PNG"
    assert main(["gesture", "evaluate", "compare", str(tmp_path / "nothing")]) == 2


LOG_NAMES = (
    "grasp1_hand", "touch1_hand", "push1_hand", "tap1_hand", "tap_notable_seated_1",
    "norobotview_tap_notable_seated_2",
)  # fmt: skip


@pytest.mark.slow
def test_the_readme_s_data_set_names_work_from_any_folder(
    shared_data: Path,
    tmp_path: Path,
    test_outputs: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """`human_data`, as the README types it, from a folder that holds no such thing: the
    article's data folder is looked in; `-o` is the current spelling (no deprecation note)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("BEYOND_DATA", str(shared_data))
    argv = ["gesture", "train", "--data", "synthetic", "--data", "human_data", "--push-as",
            "touch", "--count", "2", "--states", "3", "--mix", "1", "--iter", "2",
            "-o", "m.json"]  # fmt: skip
    assert main(argv) == 0
    assert "deprecated" not in capsys.readouterr().err
    human = str(shared_data / "saponaro2019" / "human_data")
    assert load_models(tmp_path / "m.json").meta["data"] == ["synthetic", human]
    assert main(["gesture", "realism", "human_data", "--push-as", "touch", "--count", "3"]) == 0
    plot = test_outputs / "gesture-evaluation" / "realism.png"  # not in the current folder
    assert plot.read_bytes()[:4] == b"\x89PNG" and not (tmp_path / "gesture-evaluation").exists()


def test_an_unknown_data_set_is_one_line_saying_where_to_get_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    for command in (["evaluate", "compare"], ["evaluate", "default"], ["realism"]):
        assert main(["gesture", *command, "no_such_data"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("beyond gesture: error: no_such_data is not")
        assert "$BEYOND_DATA" in err[0] and "gsaponaro/tcds-gestures" in err[0]
