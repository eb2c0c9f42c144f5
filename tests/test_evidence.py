"""One evidence grammar, one set of rules: `beyond bn query` offline and the reasoner answering
`beyond ask` get the same evidence the same way, so they give the same numbers and refuse the
same bad input with the same message."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from beyond_self.cli import build_parser, main
from beyond_self.cognition.bn import (
    BayesNet,
    learn_network,
    load_model,
    save_model,
    synthetic_dataset,
)
from beyond_self.cognition.bn.evidence import (
    Evidence,
    build_evidence,
    parse_evidence,
    parse_gesture,
    parse_soft,
)
from beyond_self.commands import ask
from beyond_self.core.errors import InputError
from beyond_self.schemas import AffordanceAnswer, AffordanceQuery
from beyond_self.schemas.codec import decode, encode
from beyond_self.services.reasoner import AffordanceReasoner


@pytest.fixture(scope="module")
def model_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("evidence") / "model.json"
    save_model(learn_network(synthetic_dataset()), path)
    return path


@pytest.fixture(scope="module")
def model(model_path: Path) -> BayesNet:
    return load_model(model_path)


def test_the_grammar_needs_no_network() -> None:
    assert parse_evidence(["Shape=box", " Size = big "]) == {"Shape": "box", "Size": "big"}
    assert parse_soft(["Action=grasp:0.2,tap:0.8", "Size=big:1"]) == {
        "Action": {"grasp": 0.2, "tap": 0.8},
        "Size": {"big": 1.0},
    }
    assert parse_gesture(["grasp=0.1,tap=0.8,touch=0.1"]) == {
        "grasp": 0.1,
        "tap": 0.8,
        "touch": 0.1,
    }
    assert parse_gesture([]) == {}


def test_soft_vectors_are_in_definition_order_and_gesture_is_soft_action(model: BayesNet) -> None:
    built = build_evidence(
        model,
        Evidence(
            hard={"Shape": "box"},
            soft={"Size": {"big": 0.25, "small": 0.75}},
            gesture={"touch": 1.0, "grasp": 2.0, "tap": 1.0},
        ),
    )
    assert built.observed == {"Shape": "box"}
    assert model.values["Size"] == ("small", "medium", "big")
    assert built.soft == {"Size": [0.75, 0.0, 0.25], "Action": [0.5, 0.25, 0.25]}


@pytest.mark.parametrize(
    ("old", "names"),
    [
        (lambda: parse_soft(["Action=0.2,0.5,0.3"]), "VAR=value:p,value:p"),
        (lambda: parse_soft(["Action=1"]), "VAR=value:p,value:p"),
        (lambda: parse_gesture(["models.json", "hand.log"]), "--gesture-log MODELS LOG"),
        (lambda: parse_gesture(["models.json"]), "--gesture-log MODELS LOG"),
    ],
)
def test_the_old_forms_are_refused_naming_the_new(old: Any, names: str) -> None:
    with pytest.raises(InputError, match=r"gone|takes P_HMM") as info:
        old()
    assert names in str(info.value)
    assert "\n" not in str(info.value)


# the same evidence fragments, typed after `bn query MODEL` and after `ask`
GOOD = [
    ["--query", "ObjVel"],
    ["--query", "ObjVel", "--evidence", "Shape=circle"],
    ["--query", "ObjVel", "--evidence", "Shape=circle", "--soft", "Size=big:0.3,small:0.7"],
    ["--query", "ObjVel", "Contact", "--soft", "Action=grasp:0.2,tap:0.5,touch:0.3"],
    ["--query", "ObjVel", "--evidence", "Shape=box", "--gesture", "grasp=0.2,tap=0.7,touch=0.1"],
    ["--query", "Action", "ObjVel", "--soft", "Shape=box:0.6,circle:0.4", "--gesture",
     "grasp=0.3,tap=0.3,touch=0.4"],
]  # fmt: skip
BAD = [
    ["--query", "ObjVel", "--evidence", "Shape=ball"],
    ["--query", "ObjVel", "--evidence", "Speed=fast"],
    ["--query", "ObjVel", "--soft", "Speed=fast:1"],
    ["--query", "ObjVel", "--soft", "Action=grasp:0.5,push:0.5"],
    ["--query", "ObjVel", "--soft", "Action=grasp:0.5,tap:0.4,touch:0.4"],
    ["--query", "ObjVel", "--soft", "Action=grasp:0.5"],
    ["--query", "ObjVel", "--gesture", "grasp=1,push=0,touch=0"],
    ["--query", "ObjVel", "--gesture", "grasp=1,tap=0"],
    ["--query", "ObjVel", "--evidence", "Action=tap", "--gesture", "grasp=0,tap=1,touch=0"],
    ["--query", "ObjVel", "--soft", "Action=tap:1", "--gesture", "grasp=0,tap=1,touch=0"],
    ["--query", "Action", "--evidence", "Action=tap"],
]


def _offline(model_path: Path, fragment: list[str], capsys: pytest.CaptureFixture[str]) -> Any:
    capsys.readouterr()
    code = main(["bn", "query", str(model_path), *fragment, "--json"])
    out = capsys.readouterr()
    if code == 2:
        prefix = "beyond bn: error: "
        assert out.err.startswith(prefix) and out.err.count("\n") == 1
        return out.err[len(prefix) :].strip()
    assert code == 0, out.err
    return json.loads(out.out)


async def _asked(model_path: Path, fragment: list[str]) -> AffordanceAnswer | str:
    """What the reasoner answers to `beyond ask FRAGMENT`, through its own handler."""
    args = build_parser("ask").parse_args(["ask", *fragment])
    reasoner = AffordanceReasoner(model=str(model_path))
    reasoner.model = load_model(model_path)  # what setup() loads, without a bus
    try:
        wire = decode(encode(ask.build_query(args)), AffordanceQuery, "ask")  # as it travels
        replies = await reasoner.on_ask("ask", wire)
    except InputError as exc:
        return str(exc)
    message = replies[0][1]
    assert isinstance(message, AffordanceAnswer)
    return message


@pytest.mark.parametrize("fragment", GOOD, ids=" ".join)
async def test_bn_query_and_ask_give_identical_numbers(
    model_path: Path, fragment: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    offline = _offline(model_path, fragment, capsys)
    answer = await _asked(model_path, fragment)
    assert isinstance(answer, AffordanceAnswer)
    if len(answer.variables) == 1:
        (name,) = answer.variables
        asked = {name: {row.assignment[name]: row.p for row in answer.rows}}
    else:
        rows = [{"assignment": row.assignment, "p": row.p} for row in answer.rows]
        asked = {"variables": answer.variables, "rows": rows}
    assert asked == offline  # exactly: the same vectors into the same query


@pytest.mark.parametrize("fragment", BAD, ids=" ".join)
async def test_bn_query_and_ask_refuse_alike(
    model_path: Path, fragment: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    offline = _offline(model_path, fragment, capsys)
    asked = await _asked(model_path, fragment)
    assert isinstance(offline, str) and offline, offline
    assert asked == offline


@pytest.mark.parametrize(
    "old",
    [
        ["--soft", "Action=0.2,0.5,0.3"],
        ["--gesture", "models.json", "hand.log"],
    ],
)
def test_ask_refuses_the_old_forms_before_any_bus(
    old: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert main(["ask", "--query", "Action", *old, "--timeout", "0.1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ("VAR=value:p" in err or "--gesture-log" in err)
