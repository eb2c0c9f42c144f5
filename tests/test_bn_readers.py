"""Readers of the network definition and bag-of-words formats, and of the reference BN_lab.mat."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from beyond_self.cognition.bn.bag import Dataset, load_bag, parse_bag
from beyond_self.cognition.bn.definition import load_definition, parse_definition
from beyond_self.cognition.variables import AFFORDANCE_VARIABLES
from beyond_self.core.errors import InputError

DEF_TEXT = "Action\tgrasp\ttap\ttouch\nShape\tcircle\tbox\nball\t-\tball\nbox\t-\tbox\n"
BAG_TEXT = "Action\tShape\tball\tbox\ntap\tcircle\tball\t-\ngrasp\tbox\t-\tbox\ntouch\tbox\t-\t-\n"


def test_definition_parses_kinds_and_order() -> None:
    d = parse_definition(DEF_TEXT, "def.txt")
    assert d.names == ("Action", "Shape", "ball", "box")
    assert [v.name for v in d.affordance] == ["Action", "Shape"]
    assert [v.word for v in d.words] == ["ball", "box"]
    assert d["Shape"].index("box") == 1
    assert parse_definition(d.to_text()) == d


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            "A x y\nB p q\nA x y\n",
            "def.txt:3: column 1: duplicate node 'A' (first defined on line 1)",
        ),
        ("A x y\nB p\n", "def.txt:2: node 'B' has 1 value(s)"),
        ("A x y y\n", "def.txt:1: column 4: value 'y' of 'A' repeated"),
        ("w - w\nA x y\n", "affordance node 'A' comes after a word node"),
        ("\n\n", "def.txt: no nodes"),
    ],
)
def test_definition_errors_name_file_line_column(text: str, expected: str) -> None:
    with pytest.raises(InputError, match=None) as err:
        parse_definition(text, "def.txt")
    assert expected in str(err.value)
    assert "\n" not in str(err.value)


def test_bag_parses_codes_in_definition_order_whatever_the_column_order() -> None:
    d = parse_definition(DEF_TEXT)
    ds = parse_bag(BAG_TEXT, d, "bag.txt")
    assert ds.data.tolist() == [[1, 0, 1, 0], [0, 1, 0, 1], [2, 1, 0, 0]]
    shuffled = (
        "box\tAction\tball\tShape\n-\ttap\tball\tcircle\nbox\tgrasp\t-\tbox\n-\ttouch\t-\tbox\n"
    )
    assert np.array_equal(parse_bag(shuffled, d).data, ds.data)
    assert np.array_equal(parse_bag(ds.to_text(), d).data, ds.data)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            "Action\tShape\tball\tbox\ntap\tcircle\tball\n",
            "bag.txt:2: 3 columns; the header has 4",
        ),
        (
            "Action\tShape\tball\tbox\ntap\tcircle\tball\t-\ntap\tsphere\tball\t-\n",
            "bag.txt:3: column 2 (Shape): unknown value 'sphere'; valid: circle, box",
        ),
        ("Action\tShape\tball\tbox\tcolour\n", "bag.txt:1: column 5: unknown node 'colour'"),
        ("Action\tShape\tball\tball\n", "bag.txt:1: column 4: node 'ball' repeated"),
        ("Action\tShape\tball\n", "bag.txt:1: header lacks node(s) box"),
        ("", "bag.txt: empty"),
    ],
)
def test_bag_errors_name_file_line_column(text: str, expected: str) -> None:
    with pytest.raises(InputError) as err:
        parse_bag(text, parse_definition(DEF_TEXT), "bag.txt")
    assert expected in str(err.value)


def test_missing_files_are_input_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="does not exist"):
        load_definition(tmp_path / "nope.txt")
    with pytest.raises(InputError, match="does not exist"):
        load_bag(tmp_path / "nope.txt", parse_definition(DEF_TEXT))


def test_dataset_rejects_out_of_range_codes() -> None:
    with pytest.raises(InputError, match="outside"):
        Dataset(parse_definition(DEF_TEXT), np.array([[3, 0, 0, 0]]))


def test_real_files_match_the_reference_network(shared_data: Path) -> None:
    from beyond_self.cognition.bn.reference import load_reference

    d = load_definition(shared_data / "salvi2012/networkDefinition.txt")
    assert len(d.variables) == 57 and len(d.words) == 49
    assert {v.name: v.values for v in d.affordance} == AFFORDANCE_VARIABLES
    ds = load_bag(shared_data / "salvi2012/sent-1-5_lab_aff_bag.txt", d)
    ref = load_reference(shared_data / "saponaro2019/BN_lab.mat")
    assert ref.names == d.names
    assert ref.values == tuple(v.values for v in d.variables)
    assert ds.rows == 1270
    assert np.array_equal(ds.data, ref.data)
    assert int(ref.dag.sum()) == 66
    assert ref.clamped == ("Action", "Color", "Shape", "Size")
