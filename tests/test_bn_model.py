"""The model file format and the synthetic data set generator."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from beyond_self.cognition.bn import learn_network, load_model, save_model, synthetic_dataset
from beyond_self.cognition.bn.model import FORMAT, VERSION
from beyond_self.cognition.bn.synthetic import DATA_DIR, EXPECTED_OBJVEL, generate, synthetic_paths
from beyond_self.cognition.grammar import DEFAULT_GRAMMAR
from beyond_self.cognition.variables import AFFORDANCE_VARIABLES, COLOR_WORDS
from beyond_self.core.errors import InputError


def test_model_round_trips_exactly(tmp_path: Path) -> None:
    model = learn_network(synthetic_dataset())
    path = tmp_path / "model.json"
    save_model(model, path)
    again = load_model(path)
    assert again.variables == model.variables
    assert again.parents == model.parents
    assert again.node_log_likelihood == model.node_log_likelihood
    for name in model.variables:
        assert np.array_equal(again.cpts[name], model.cpts[name])  # floats round-trip exactly
    assert again.training["unseen"] == "absent"
    scene = {"Shape": "box", "ObjVel": "medium"}
    assert again.word_probabilities(scene) == model.word_probabilities(scene)
    raw = json.loads(path.read_text())
    assert raw["format"] == FORMAT and raw["version"] == VERSION
    node = next(n for n in raw["nodes"] if n["name"] == "ObjVel")
    assert node["parents"] == list(model.parents["ObjVel"])
    assert len(node["cpt"]) == 3 * 2 and all(len(row) == 3 for row in node["cpt"])


def _corrupt(tmp_path: Path, edit: str) -> Path:
    model = learn_network(synthetic_dataset())
    obj = model.to_json()
    if edit == "version":
        obj["version"] = 99
    elif edit == "format":
        obj["format"] = "something else"
    elif edit == "cpt":
        obj["nodes"][4]["cpt"][0] = [0.5, 0.5, 0.5]
    elif edit == "parent":
        obj["nodes"][4]["parents"] = ["Action", "Nope"]
    elif edit == "cycle":
        obj["nodes"][0]["parents"] = ["ObjVel"]
        obj["nodes"][0]["cpt"] = [[1 / 3] * 3] * 3
    elif edit == "missing":
        del obj["nodes"][4]["cpt"]
    path = tmp_path / f"{edit}.json"
    path.write_text(json.dumps(obj))
    return path


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ("version", "format version 99"),
        ("format", "not a beyond-self network model"),
        ("cpt", "CPT of 'ObjVel' is not a probability table"),
        ("parent", "unknown parent of ObjVel 'Nope'"),
        ("cycle", "cycle"),
        ("missing", "malformed model file"),
    ],
)
def test_bad_model_files_are_input_errors(tmp_path: Path, edit: str, message: str) -> None:
    with pytest.raises(InputError) as err:
        load_model(_corrupt(tmp_path, edit))
    assert message in str(err.value)
    assert str(tmp_path) in str(err.value)


def test_missing_or_garbled_model_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="does not exist"):
        load_model(tmp_path / "none.json")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(InputError, match="cannot read model file"):
        load_model(tmp_path / "bad.json")


# -- synthetic data set -------------------------------------------------------------------------


@pytest.mark.numeric  # labels sampled from probabilities: the same on every kernel
def test_bundled_synthetic_set_regenerates_byte_identically(tmp_path: Path) -> None:
    written = generate().write(tmp_path)
    for path in written:
        bundled = DATA_DIR / path.name
        assert bundled.read_bytes() == path.read_bytes(), f"{bundled} is stale: regenerate it"
    definition, bag = synthetic_paths()
    assert definition.exists() and bag.exists()


def test_synthetic_set_has_the_articles_shape_and_vocabulary() -> None:
    data = generate()
    assert len(data.experiments) == 254
    assert data.dataset.rows == 1270
    assert [v.word for v in data.definition.words] == list(DEFAULT_GRAMMAR.vocabulary)
    assert {v.name: v.values for v in data.definition.affordance} == AFFORDANCE_VARIABLES
    combos = Counter(
        (e.values["Action"], e.values["Color"], e.values["Size"], e.values["Shape"])
        for e in data.experiments
    )
    assert len(combos) == 72 and set(combos.values()) <= {3, 4}
    assert generate(seed=7).dataset.data.tolist() != data.dataset.data.tolist()
    assert generate(seed=7).dataset.data.tolist() == generate(seed=7).dataset.data.tolist()


def test_narrator_follows_its_rules() -> None:
    data = generate()
    values = {e.number: e.values for e in data.experiments}
    vocab = set(DEFAULT_GRAMMAR.vocabulary)
    colour_ok = conj_ok = conj_total = 0
    for number, sentence in data.sentences:
        words = sentence.split()
        assert set(words) <= vocab
        v = values[number]
        said = [w for w in words if w in ("green", "yellow", "blue")]
        colour_ok += all(w == COLOR_WORDS[v["Color"]] for w in said)
        if v["Size"] == "medium":
            assert "big" not in words and "small" not in words
        if "and" in words or "but" in words:
            conj_total += 1
            expected = v["ObjVel"] in EXPECTED_OBJVEL[v["Action"]]
            conj_ok += ("and" in words) == expected
    n = len(data.sentences)
    assert colour_ok / n > 0.94
    assert conj_total / n > 0.85  # the clause is rarely omitted
    assert 0.9 < conj_ok / conj_total < 0.99  # the rule, with a little noise
    # Each bag row is the set of the words of its sentence.
    for row, (_, sentence) in zip(data.dataset.data[:50], data.sentences[:50], strict=True):
        present = {
            v.word for v, code in zip(data.definition.variables[8:], row[8:], strict=True) if code
        }
        assert present == set(sentence.split())
