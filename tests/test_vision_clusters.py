"""Learned discretisation: k-means, naming by majority, the versioned JSON file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from beyond_self.cognition.variables import AFFORDANCE_VARIABLES
from beyond_self.cognition.vision.clusters import (
    DEFAULT_PATH,
    ClusterModel,
    learn_discretiser,
    name_by_majority,
)
from beyond_self.core.errors import InputError


def _speeds(seed: int) -> tuple[np.ndarray, list[str]]:
    rng = np.random.default_rng(seed)
    centres = {"slow": 0.01, "medium": 0.17, "fast": 0.5}
    x, truth = [], []
    for name, c in centres.items():
        x.extend(c * np.exp(rng.normal(0, 0.15, 40)))
        truth.extend([name] * 40)
    return np.array(x)[:, None], truth


def test_kmeans_finds_the_three_speed_groups_and_names_them() -> None:
    x, truth = _speeds(0)
    noisy = list(truth)
    noisy[0] = "fast"  # one wrong label does not change a name
    disc = learn_discretiser("ObjVel", x, noisy, seed=1)
    assert sorted(disc.names) == ["fast", "medium", "slow"]
    assert disc.label(0.012) == "slow" and disc.label(0.2) == "medium" and disc.label(0.7) == "fast"
    # log-space centres near the generating ones
    assert np.exp(np.sort(disc.centers[:, 0])) == pytest.approx([0.01, 0.17, 0.5], rel=0.1)
    dist = disc.distribution(0.2)
    assert sum(dist.values()) == pytest.approx(1.0) and max(dist, key=dist.get) == "medium"
    again = learn_discretiser("ObjVel", x, noisy, seed=1)
    assert np.array_equal(again.centers, disc.centers)


def test_names_are_a_one_to_one_majority_assignment() -> None:
    # cluster 0 holds mostly "b", cluster 1 mostly "b" too but cluster 0 more so
    assign = np.array([0, 0, 0, 1, 1, 1, 1])
    truth = ["b", "b", "b", "b", "b", "a", "a"]
    assert name_by_majority(assign, truth, ["a", "b"], 2) == ["b", "a"]


def test_json_round_trip_and_person_renaming(tmp_path: Path) -> None:
    x, truth = _speeds(1)
    model = ClusterModel({"ObjVel": learn_discretiser("ObjVel", x, truth, seed=0)})
    model.rename("ObjVel", {"fast": "quick"})
    path = model.save(tmp_path / "c.json")
    back = ClusterModel.load(path)
    assert back.variables["ObjVel"].names == model.variables["ObjVel"].names
    assert back.label("ObjVel", {"object_speed": 0.6}) == "quick"
    data = json.loads(path.read_text())
    assert data["version"] == 1 and "object_speed" in data["feature_definitions"]
    with pytest.raises(InputError, match="cluster name"):
        model.rename("ObjVel", {"nope": "x"})


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{not json", "not readable JSON"),
        ('{"format": "other"}', "not a clusters file"),
        ('{"format": "beyond-self/vision-clusters", "version": 99}', "version 99"),
        ('{"format": "beyond-self/vision-clusters", "version": 1, "variables": {}}', "no variab"),
        (
            '{"format": "beyond-self/vision-clusters", "version": 1, "variables": {"Size": '
            '{"features": ["diameter_m"], "transform": "log", "standardize": false, '
            '"offset": [0], "scale": [1], "centers": [[1], [2]], "spread": [1], "names": ["a"]}}}',
            "inconsistent",
        ),
    ],
)
def test_malformed_cluster_files(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(InputError, match=message):
        ClusterModel.load(path)
    with pytest.raises(InputError, match="does not exist"):
        ClusterModel.load(tmp_path / "missing.json")


def test_too_few_samples_are_refused() -> None:
    with pytest.raises(InputError, match="too few"):
        learn_discretiser("Color", np.zeros((5, 3)), None)


def test_the_shipped_default_file() -> None:
    model = ClusterModel.load()
    assert DEFAULT_PATH.is_file()
    for var in ("Color", "Shape", "Size", "ObjVel", "ObjHandVel", "HandVel", "Contact"):
        assert sorted(model.variables[var].names) == sorted(AFFORDANCE_VARIABLES[var])
    assert "beyond segment --learn" in model.created_by
    assert model.training["experiments"] >= 100
    # sizes: the learned boundaries separate the rendered diameters (4.5 / 6.5 / 9 cm)
    size = model.variables["Size"]
    assert [size.label(d) for d in (0.045, 0.065, 0.09)] == ["small", "medium", "big"]
