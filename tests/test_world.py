import numpy as np
import pytest

from beyond_self.cognition.world import simulate_effects
from beyond_self.core.errors import InputError


def _labels(action: str, shape: str, n: int = 200) -> list[dict[str, str]]:
    rng = np.random.default_rng(1)
    return [simulate_effects(action, shape, "medium", rng).labels() for _ in range(n)]


def test_tapped_spheres_roll_faster_than_tapped_boxes() -> None:
    sphere = [x["ObjVel"] for x in _labels("tap", "circle")]
    box = [x["ObjVel"] for x in _labels("tap", "box")]
    assert sphere.count("fast") > 0.9 * len(sphere)
    assert box.count("fast") < 0.1 * len(box)


def test_touch_leaves_object_still_and_grasp_holds_long() -> None:
    assert all(x["ObjVel"] == "slow" for x in _labels("touch", "box"))
    assert all(x["Contact"] == "long" for x in _labels("grasp", "circle"))


def test_unknown_values_are_rejected_with_the_valid_ones() -> None:
    with pytest.raises(InputError, match="valid: grasp, tap, touch"):
        simulate_effects("kick", "box", "big", np.random.default_rng(0))
    with pytest.raises(InputError, match="valid: circle, box"):
        simulate_effects("tap", "sphere", "big", np.random.default_rng(0))
