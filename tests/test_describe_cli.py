"""`beyond describe` and the `--gesture-log` evidence option, run in-process like a user would."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from beyond_self.cli import main
from beyond_self.cognition.bn import learn_network, load_bag, load_definition, save_model
from beyond_self.cognition.descriptions import score_sentence


@pytest.fixture(scope="module")
def real_model(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    base = shared_data / "salvi2012"
    model = learn_network(
        load_bag(base / "sent-1-5_lab_aff_bag.txt", load_definition(base / "networkDefinition.txt"))
    )
    path = tmp_path_factory.mktemp("describe") / "real.json"
    save_model(model, path)
    return path


def _json(capsys: pytest.CaptureFixture[str], argv: list[str]) -> object:
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_exact_nbest_is_sorted_and_scores_are_the_formula(
    real_model: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["describe", str(real_model), "--evidence", "Action=grasp", "ObjVel=slow", "--json"]
    best = _json(capsys, argv)
    assert isinstance(best, list) and len(best) == 10
    scores = [item["score"] for item in best]
    assert scores == sorted(scores, reverse=True)
    words = _json(
        capsys,
        ["bn", "words", str(real_model), "--evidence", "Action=grasp", "ObjVel=slow", "--json"],
    )
    assert isinstance(words, dict)
    for item in best:  # independent re-scoring: mean log P of the words
        assert abs(score_sentence(item["sentence"], words) - item["score"]) < 1e-5
    # the article: a slowly moving grasped object is described with "but"
    assert " but " in best[0]["sentence"]


def test_require_keeps_only_matching_sentences(
    real_model: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["describe", str(real_model), "--evidence", "Action=touch", "Color=green2"]
    best = _json(
        capsys, [*argv, "Shape=circle", "--require", r"\bgreen\b", "--nbest", "3", "--json"]
    )
    assert isinstance(best, list) and len(best) == 3
    assert all(re.search(r"\bgreen\b", item["sentence"]) for item in best)


def test_gesture_evidence_is_fused(
    real_model: Path, shared_data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    human = shared_data / "saponaro2019" / "human_data"
    gesture = [
        "--gesture-log",
        str(human / "HMM_M3_Q6_mixsplit.mat"),
        str(human / "tap_notable_seated_1"),
    ]
    observed = ["--evidence", "Size=small", "Shape=circle", "ObjVel=slow"]
    alone = _json(
        capsys, ["bn", "query", str(real_model), "--query", "Action", *observed, "--json"]
    )
    fused = _json(
        capsys,
        ["bn", "query", str(real_model), "--query", "Action", *observed, *gesture,
         "--frames", "121:214", "--json"],
    )  # fmt: skip
    assert isinstance(alone, dict) and isinstance(fused, dict)
    assert max(alone["Action"], key=alone["Action"].get) == "touch"
    assert max(fused["Action"], key=fused["Action"].get) == "tap"


def test_gesture_conflicts_and_bad_options_exit_2(
    real_model: Path, shared_data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    human = shared_data / "saponaro2019" / "human_data"
    gesture = [
        "--gesture-log",
        str(human / "HMM_M3_Q6_mixsplit.mat"),
        str(human / "tap_notable_seated_1"),
    ]
    assert main(["describe", str(real_model), "--evidence", "Action=tap", *gesture]) == 2
    assert "drop Action" in capsys.readouterr().err
    assert main(["describe", str(real_model), "--frames", "1:5"]) == 2
    assert "give --gesture-log" in capsys.readouterr().err
    both = [*gesture, "--gesture", "grasp=0,tap=1,touch=0"]
    assert main(["describe", str(real_model), *both]) == 2
    assert "not both" in capsys.readouterr().err
    old = ["--gesture", *gesture[1:]]  # the two-argument --gesture of old
    assert main(["describe", str(real_model), *old]) == 2
    assert "--gesture-log MODELS LOG" in capsys.readouterr().err
    assert main(["describe", str(real_model), *gesture, "--frames", "300:999"]) == 2
    assert "out of range" in capsys.readouterr().err
    assert main(["describe", str(real_model), "--nbest", "0"]) == 2
