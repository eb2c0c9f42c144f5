"""The Foxglove layout shipped in deploy/foxglove/ (camera with object annotations, the person's
camera with their pose over it, the description log, the 3D skeleton, the action posterior and
the effect predictions on one screen), built with foxglove-sdk's layout types so it follows the
SDK's layout schema.

`beyond foxglove --layout FILE --robot NAME` writes it for another robot (topics name it);
`tests/test_foxglove_layout.py` checks that the shipped file is what this builds, and that
every topic it shows is one the bridge serves."""

from __future__ import annotations

import json

import foxglove.layouts as fl

from beyond_self.cognition.variables import ACTIONS, AFFORDANCE_VARIABLES
from beyond_self.runtime.foxglove.views import VIEWS
from beyond_self.schemas.keys import Keys

PLOTTED_EFFECT = "ObjVel"  # the effect whose prediction the lower plot follows


def _path(topic: str, field: str) -> str:
    # quoted: our topics have no leading "/", which Foxglove's unquoted topic syntax expects
    return f'"{topic}".{field}'


def _image_panel(title: str, image: str, annotations: str) -> fl.ImagePanel:
    return fl.ImagePanel(
        title=title,
        config=fl.ImageConfig(
            image_mode=fl.ImageModeConfig(
                image_topic=image,
                annotations={annotations: fl.ImageAnnotationSettings(visible=True)},
            )
        ),
    )


def layout(robot: str = "robot") -> fl.Layout:
    keys = Keys(robot)
    view = {v.name: v.topic(keys.root) for v in VIEWS}
    image = _image_panel("camera + detected objects", keys.camera_compressed, view["objects"])
    person = _image_panel("person + pose (a camera source)", keys.person_camera, view["pose"])
    scene = fl.ThreeDeePanel(
        title="skeleton",
        config=fl.ThreeDeeConfig(
            topics={view["scene"]: fl.BaseRendererSceneUpdateTopicSettings(visible=True)},
            follow_mode="follow-none",
        ),
    )
    posterior = fl.PlotPanel(
        title="action posterior P(A | gesture so far)",
        config=fl.PlotConfig(
            paths=[
                fl.PlotSeries(value=_path(view["posterior"], f"posterior.{a}"), label=a)
                for a in ACTIONS
            ],
            min_y_value=0.0,
            max_y_value=1.0,
            show_legend=True,
        ),
    )
    effects = fl.PlotPanel(
        title=f"predicted {PLOTTED_EFFECT}",
        config=fl.PlotConfig(
            paths=[
                fl.PlotSeries(
                    value=_path(view["affordance"], f"effects.{PLOTTED_EFFECT}.{value}"),
                    label=f"{PLOTTED_EFFECT}={value}",
                )
                for value in AFFORDANCE_VARIABLES[PLOTTED_EFFECT]
            ],
            min_y_value=0.0,
            max_y_value=1.0,
            show_legend=True,
        ),
    )
    descriptions = fl.LogPanel(
        title="descriptions", config=fl.LogConfig(topic_to_render=view["log"])
    )

    def column(*panels: fl.Content, weights: tuple[float, ...]) -> fl.SplitContainer:
        return fl.SplitContainer(
            direction="column",
            items=[
                fl.SplitItem(proportion=w, content=p) for p, w in zip(panels, weights, strict=True)
            ],
        )

    cameras = column(image, person, descriptions, weights=(3, 3, 1))
    return fl.Layout(
        content=fl.SplitContainer(
            direction="row",
            items=[
                fl.SplitItem(proportion=1.2, content=cameras),
                fl.SplitItem(proportion=1.0, content=scene),
                fl.SplitItem(proportion=1.0, content=column(posterior, effects, weights=(1, 1))),
            ],
        )
    )


def layout_json(robot: str = "robot") -> str:
    """The layout as the file Foxglove imports (stable: sorted keys, newline at the end)."""
    return json.dumps(json.loads(layout(robot).to_json()), indent=2, sort_keys=True) + "\n"
