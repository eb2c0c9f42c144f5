"""What a service process loads once and every robot it serves shares (runtime.fleet).

A fleet's workstation runs each service once for many robots, a run per robot; the models a
run reads (the Affordance–Words network, the gesture HMMs, the colour and shape clusters) never
change while it runs, and the object segmenter's frame describer is a process of its own. Each
is loaded once per process, by path, and shared: a robot that joins costs its per-run state,
not another copy of the models (0.7 s to learn the default network) or another process. The
tables the science makes on its first call (the network's first query, the grammar's layout) are
made before the process joins the bus too (`warm_*`, called by the services' `warm`).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import TYPE_CHECKING

from beyond_self.cognition.bn import BayesNet, learn_network, load_model, synthetic_dataset
from beyond_self.cognition.descriptions import nbest_exact
from beyond_self.cognition.descriptions.space import SentenceSpace
from beyond_self.cognition.episodes import FusionJoin
from beyond_self.cognition.fusion import ACTION
from beyond_self.cognition.gestures import GestureModels
from beyond_self.cognition.gestures.default_models import pipeline_models

if TYPE_CHECKING:  # the object segmenter's alone: imported when it first asks
    from beyond_self.cognition.vision.clusters import ClusterModel
    from beyond_self.services.frame_describer import FrameDescriber


@functools.cache
def network(path: str | None) -> BayesNet:
    """The reasoner's network: the file's, or learned from the synthetic data."""
    return load_model(Path(path)) if path else learn_network(synthetic_dataset())


@functools.cache
def warm_fusion(path: str | None) -> None:
    """One gesture through fusion, so that the network's first query (about 4 ms of tables
    made once per process) is not paid by the first robot to end a gesture."""
    model = network(path)
    join: FusionJoin[None] = FusionJoin(model, expect_objects=False)
    actions = model.definition[ACTION].values
    join.started(1, 1)
    join.belief(1, 1, 2, dict.fromkeys(actions, 1 / len(actions)), None, True)
    join.ended(1, 1, 2)


@functools.cache
def warm_descriptions(n: int) -> None:
    """One N-best search, so that the grammar's tables (about 4 ms, once per process) are made
    before the first robot's words come."""
    vocabulary = SentenceSpace.of().vocabulary
    nbest_exact(dict.fromkeys(vocabulary, 0.5), n)


@functools.cache
def gesture_models(path: str | None) -> GestureModels:
    return pipeline_models(path)


@functools.cache
def clusters(path: str | None) -> ClusterModel:
    from beyond_self.cognition.vision.clusters import ClusterModel

    return ClusterModel.load(path)


_describers: dict[tuple[str | None, int], tuple[FrameDescriber, int]] = {}


def frame_describer(clusters: str | None, niceness: int) -> FrameDescriber:
    """The process's describer for these clusters and priority, started by the first run that
    asks; give it back with `release_describer` (the last one out stops it)."""
    from beyond_self.services.frame_describer import FrameDescriber

    key = (clusters, niceness)
    describer, users = _describers.get(key) or (FrameDescriber(clusters, niceness), 0)
    _describers[key] = (describer, users + 1)
    return describer


def release_describer(describer: FrameDescriber) -> None:
    for key, (known, users) in list(_describers.items()):
        if known is describer:
            if users > 1:
                _describers[key] = (known, users - 1)
            else:
                del _describers[key]
                known.close()
            return
    describer.close()
