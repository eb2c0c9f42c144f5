"""How the simulated world responds to the robot's (or a person's) actions.

One set of rules for everything synthetic (the network's exploration data set, the tabletop
renderer, `beyond simulate`), so the effect the renderer shows is the effect the network was
trained to expect. In words, with log-normal noise on each quantity: touch leaves the object
inert, grasp lifts it at a moderate speed, tap sends a sphere rolling fast and a box sliding;
small objects move a bit faster; tap is a fast stroke, grasp and touch careful approaches; grasp
holds the object (long contact), tap and touch are brief. Colour has no effect on dynamics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from beyond_self.cognition.variables import ACTIONS, AFFORDANCE_VARIABLES
from beyond_self.core.errors import unknown

# Base object speed (m/s) by (action, shape); size scales it.
_OBJECT_SPEED = {
    ("touch", "circle"): 0.01,
    ("touch", "box"): 0.01,
    ("grasp", "circle"): 0.16,
    ("grasp", "box"): 0.16,
    ("tap", "circle"): 0.50,
    ("tap", "box"): 0.17,
}
_SIZE_FACTOR = {"small": 1.2, "medium": 1.0, "big": 0.85}
_HAND_SPEED = {"grasp": 0.25, "tap": 0.9, "touch": 0.22}
_REL_SPEED = {
    ("grasp", "circle"): 0.03,
    ("grasp", "box"): 0.03,
    ("touch", "circle"): 0.20,
    ("touch", "box"): 0.20,
    ("tap", "circle"): 0.60,
    ("tap", "box"): 0.22,
}
_CONTACT_S = {"grasp": 1.2, "tap": 0.12, "touch": 0.25}

# Thresholds turning continuous quantities into labels (the "truth" of a simulation).
OBJECT_SPEED_EDGES = (0.06, 0.32)  # slow | medium | fast
REL_SPEED_EDGES = (0.09, 0.38)  # slow | medium | fast
HAND_SPEED_EDGE = 0.5  # slow | fast
CONTACT_EDGE_S = 0.6  # short | long


@dataclass(frozen=True)
class Effects:
    """Continuous effects of one action on one object, and their discrete labels."""

    object_speed: float  # m/s, peak speed of the object after the action
    hand_speed: float  # m/s, peak hand speed during the approach
    relative_speed: float  # m/s, object speed relative to the hand after contact
    contact_s: float  # s, duration of hand–object contact

    def labels(self) -> dict[str, str]:
        return {
            "ObjVel": _bin(self.object_speed, OBJECT_SPEED_EDGES, ("slow", "medium", "fast")),
            "ObjHandVel": _bin(self.relative_speed, REL_SPEED_EDGES, ("slow", "medium", "fast")),
            "HandVel": _bin(self.hand_speed, (HAND_SPEED_EDGE,), ("slow", "fast")),
            "Contact": _bin(self.contact_s, (CONTACT_EDGE_S,), ("short", "long")),
        }


def _bin(x: float, edges: tuple[float, ...], names: tuple[str, ...]) -> str:
    return names[int(np.searchsorted(np.asarray(edges), x, side="right"))]


def _check(variable: str, value: str) -> None:
    valid = AFFORDANCE_VARIABLES[variable]
    if value not in valid:
        raise unknown(f"{variable} value", value, valid)


def simulate_effects(
    action: str, shape: str, size: str, rng: np.random.Generator, noise: float = 0.15
) -> Effects:
    """Draw the effects of `action` on an object of `shape` and `size` (noise: log-normal sigma)."""
    if action not in ACTIONS:
        raise unknown("action", action, ACTIONS)
    _check("Shape", shape)
    _check("Size", size)

    def jitter(x: float) -> float:
        return float(x * np.exp(rng.normal(0.0, noise)))

    return Effects(
        object_speed=jitter(_OBJECT_SPEED[action, shape] * _SIZE_FACTOR[size]),
        hand_speed=jitter(_HAND_SPEED[action]),
        relative_speed=jitter(_REL_SPEED[action, shape] * _SIZE_FACTOR[size]),
        contact_s=jitter(_CONTACT_S[action]),
    )
