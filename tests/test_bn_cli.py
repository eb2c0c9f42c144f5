"""`beyond bn ...` and `beyond demo`, run in-process through the dispatcher."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from beyond_self.cli import main


@pytest.fixture(scope="module")
def model_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("bn") / "model.json"
    assert main(["bn", "learn", "-o", str(path)]) == 0
    return path


def _json(capsys: pytest.CaptureFixture[str], argv: list[str]) -> object:
    capsys.readouterr()
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_show_json(model_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = _json(capsys, ["bn", "show", str(model_path), "--json"])
    assert isinstance(out, dict)
    assert set(out) == {"nodes", "arcs", "node_log_likelihood", "zero_columns", "removed_mass"}
    assert out["zero_columns"] == {} and out["removed_mass"] == 0.0
    assert out["nodes"][0] == {"name": "Action", "values": ["grasp", "tap", "touch"]}
    assert len(out["nodes"]) == 57
    assert ["Action", "HandVel"] in out["arcs"]
    assert all(ll <= 0 for ll in out["node_log_likelihood"].values())


def test_query_one_variable(model_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = _json(
        capsys,
        [
            "bn",
            "query",
            str(model_path),
            "--query",
            "Action",
            "--evidence",
            "Contact=long",
            "--json",
        ],
    )
    assert isinstance(out, dict) and list(out) == ["Action"]
    dist = out["Action"]
    assert list(dist) == ["grasp", "tap", "touch"]
    assert sum(dist.values()) == pytest.approx(1.0)
    assert dist["grasp"] > 0.95  # only a grasp holds the object long in the simulated world


def test_query_several_variables_with_soft_evidence(
    model_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["bn", "query", str(model_path), "--query", "ObjVel", "ball"]
    argv += ["--evidence", "Shape=circle", "--soft", "Action=grasp:0.2,tap:0.5,touch:0.3"]
    argv += ["--json"]
    out = _json(capsys, argv)
    assert isinstance(out, dict)
    assert out["variables"] == ["ObjVel", "ball"]
    assert len(out["rows"]) == 6
    assert out["rows"][0]["assignment"] == {"ObjVel": "slow", "ball": "-"}
    assert sum(r["p"] for r in out["rows"]) == pytest.approx(1.0)
    # Without --json a table is printed.
    assert main(argv[:-1]) == 0
    assert "ObjVel" in capsys.readouterr().out


def test_words(model_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["bn", "words", str(model_path), "--evidence", "Action=tap", "Shape=circle", "--json"]
    out = _json(capsys, argv)
    assert isinstance(out, dict) and len(out) == 49
    assert out["ball"] + out["sphere"] > out["box"] + out["cube"]
    assert out["taps"] > out["grasps"]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--query", "Speed"], "unknown query variable 'Speed'"),
        (["--query", "Action", "--evidence", "Shape=ball"], "unknown value of Shape 'ball'"),
        (["--query", "Action", "--evidence", "Shape"], "--evidence expects VAR=VALUE"),
        (["--query", "Action", "--evidence", "Action=tap"], "both observed and queried"),
        (["--query", "Shape", "--soft", "Action=grasp:0.5,push:0.5"], "unknown value of Action"),
        (["--query", "Shape", "--soft", "Speed=fast:1"], "unknown soft-evidence variable"),
        (["--query", "Shape", "--soft", "Action=grasp:0.5,tap:0.4,touch:0.4"], "sum to 1.3"),
        (["--query", "Shape", "--soft", "Action=grasp:1.5,tap:-0.5"], "lie in [0, 1]"),
        (["--query", "Shape", "--soft", "Action=grasp:a"], "value:p pairs"),
        (["--query", "Shape", "--soft", "Action=grasp:1", "Action=tap:1"], "Action twice"),
        (["--query", "Shape", "--gesture", "grasp=1,push=0"], "unknown action"),
        (["--query", "Shape", "--gesture", "grasp=1,tap=0"], "lacks action(s) touch"),
        (["--query", "Shape", "--gesture", "grasp=x"], "ACTION=p pairs"),
        (
            ["--query", "Shape", "--evidence", "Action=tap", "--gesture", "grasp=0,tap=1,touch=0"],
            "drop Action=tap from --evidence",
        ),
        (
            ["--query", "Shape", "--soft", "Action=tap:1", "--gesture", "grasp=0,tap=1,touch=0"],
            "drop Action from --soft",
        ),
        (
            # in this world only a grasp (long contact) makes the narrator say "rises"
            ["--query", "Shape", "--evidence", "Contact=short", "rises=rises"],
            "zero probability",
        ),
    ],
)
def test_bad_input_exits_2_with_one_line(
    model_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    capsys.readouterr()
    assert main(["bn", "query", str(model_path), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err
    assert err.count("\n") == 0


@pytest.mark.parametrize("command", ["query", "words"])
@pytest.mark.parametrize(
    ("old", "names"),
    [
        (["--soft", "Action=0.2,0.5,0.3"], "VAR=value:p,value:p"),
        (
            ["--gesture", "HMM_M3_Q6_mixsplit.mat", "tap_notable_seated_1"],
            "--gesture-log MODELS LOG",
        ),
        (["--gesture", "HMM_M3_Q6_mixsplit.mat"], "--gesture-log MODELS LOG"),
    ],
)
def test_the_old_evidence_forms_exit_2_naming_the_new_one(
    model_path: Path,
    capsys: pytest.CaptureFixture[str],
    command: str,
    old: list[str],
    names: str,
) -> None:
    """`--soft VAR=p1,p2,...` and `--gesture MODELS LOG` are refused, not half-understood."""
    capsys.readouterr()
    query = ["--query", "Shape"] if command == "query" else []
    assert main(["bn", command, str(model_path), *query, *old]) == 2
    err = capsys.readouterr().err.strip()
    assert names in err
    assert err.count("\n") == 0


def test_gesture_evidence_given_directly_is_fused(
    model_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A certain gesture is the action observed; an unnormalised one is normalised first."""
    base = ["bn", "query", str(model_path), "--query", "ObjVel", "--evidence", "Shape=circle"]
    observed = _json(capsys, [*base, "Action=tap", "--json"])
    certain = _json(capsys, [*base, "--gesture", "grasp=0,tap=1,touch=0", "--json"])
    assert isinstance(observed, dict) and isinstance(certain, dict)
    assert certain["ObjVel"] == pytest.approx(observed["ObjVel"], abs=1e-12)
    soft = _json(capsys, [*base, "--soft", "Action=grasp:0.2,tap:0.5,touch:0.3", "--json"])
    scaled = _json(capsys, [*base, "--gesture", "grasp=0.4,tap=1,touch=0.6", "--json"])
    assert isinstance(soft, dict) and isinstance(scaled, dict)
    assert scaled["ObjVel"] == pytest.approx(soft["ObjVel"], abs=1e-12)
    assert main([*base, "--gesture", "grasp=0,tap=1,touch=0"]) == 0
    shown = " ".join(capsys.readouterr().out.split())  # undo rich's line wrapping
    assert "gesture grasp 0.000, tap 1.000, touch 0.000" in shown


def test_missing_model_file_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bn", "show", str(tmp_path / "none.json")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_learn_the_real_network(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "lab.json"
    bag = shared_data / "salvi2012/sent-1-5_lab_aff_bag.txt"
    network = shared_data / "salvi2012/networkDefinition.txt"
    assert main(["bn", "learn", str(bag), "--network", str(network), "-o", str(out)]) == 0
    shown = _json(capsys, ["bn", "show", str(out), "--json"])
    assert isinstance(shown, dict)
    assert len(shown["arcs"]) == 66
    lls = shown["node_log_likelihood"]
    total = sum(v for k, v in lls.items() if k not in ("Action", "Color", "Shape", "Size"))
    assert total == pytest.approx(-14723.61822813, abs=1e-6)


def test_learn_with_zero_columns_and_query(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--unseen zero: the toolbox's columns; the query renormalises over what they leave."""
    out = tmp_path / "zero.json"
    bag = shared_data / "salvi2012/sent-1-5_lab_aff_bag.txt"
    assert main(["bn", "learn", str(bag), "--unseen", "zero", "-o", str(out)]) == 0
    shown = _json(capsys, ["bn", "show", str(out), "--json"])
    assert isinstance(shown, dict)
    assert shown["zero_columns"] == {"and": 3, "but": 3, "falls": 3, "falling": 3}
    assert 0 < shown["removed_mass"] < 0.05
    scene = ["Color=yellow", "Size=big", "Shape=circle", "ObjVel=fast"]
    action = _json(
        capsys, ["bn", "query", str(out), "--query", "Action", "--evidence", *scene, "--json"]
    )
    assert isinstance(action, dict)
    assert action["Action"]["tap"] == pytest.approx(0.6963, abs=5e-5)
    argv = ["bn", "query", str(out), "--query", "Action", "--evidence", "ObjVel=fast"]
    assert main([*argv, "HandVel=slow", "Contact=long"]) == 2
    assert "unseen=zero" in capsys.readouterr().err


def test_demo_runs_offline(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("BEYOND_DATA", "/nonexistent")
    assert main(["demo", "--network"]) == 0
    out = " ".join(capsys.readouterr().out.split())  # undo rich's line wrapping
    assert "P(Action | effects)" in out
    assert "P(ObjVel | Shape, Action=tap)" in out
    assert "tapped" in out
