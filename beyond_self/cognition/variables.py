"""The network's affordance variables and their values, named as in the article's data files.

Value names are cluster labels chosen by people; the models never rely on their meaning or order.
`circle` is the data files' name for the sphere shape.
"""

from __future__ import annotations

ACTIONS: tuple[str, ...] = ("grasp", "tap", "touch")

AFFORDANCE_VARIABLES: dict[str, tuple[str, ...]] = {
    "Action": ACTIONS,
    "Color": ("green1", "green2", "yellow", "blue"),
    "Shape": ("circle", "box"),
    "Size": ("small", "medium", "big"),
    "ObjVel": ("slow", "medium", "fast"),
    "ObjHandVel": ("slow", "medium", "fast"),
    "HandVel": ("slow", "fast"),
    "Contact": ("short", "long"),
}

OBJECT_FEATURES: tuple[str, ...] = ("Color", "Shape", "Size")
EFFECTS: tuple[str, ...] = ("ObjVel", "ObjHandVel", "HandVel", "Contact")

# The words a person uses for each colour cluster: both green shades are just "green".
COLOR_WORDS: dict[str, str] = {
    "green1": "green",
    "green2": "green",
    "yellow": "yellow",
    "blue": "blue",
}
