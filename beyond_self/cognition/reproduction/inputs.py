"""What the article's experiments run on: the network learned from the real data under each
rule for unseen word columns, the reference gesture models, a recorded tap and the article's
sentence list, each checked present first."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from beyond_self.cognition.bn.bag import load_bag
from beyond_self.cognition.bn.definition import load_definition
from beyond_self.cognition.bn.model import BayesNet, learn_network
from beyond_self.cognition.gestures.hmm import GestureModels
from beyond_self.cognition.gestures.model_files import load_models
from beyond_self.cognition.paths import SOURCES
from beyond_self.core.errors import InputError

EXP3_RECORDING = "tap_notable_seated_1"

UNSEEN_COMPARED = ("absent", "zero")  # the default and the reference toolbox's semantics

REQUIRED_FILES = (
    "salvi2012/networkDefinition.txt",
    "salvi2012/sent-1-5_lab_aff_bag.txt",
    "saponaro2019/human_data/HMM_M3_Q6_mixsplit.mat",
    f"saponaro2019/human_data/{EXP3_RECORDING}/data.log",
    "saponaro2019/sentence_10000samples_uniq.txt",
)


@dataclass(frozen=True)
class Inputs:
    """What the experiments run on: the network learned from the real data (`model`, default
    rule for unseen word columns; `networks`, the same data under each of UNSEEN_COMPARED), the
    reference gesture models, and the paths of the recording and sentence list."""

    model: BayesNet
    networks: Mapping[str, BayesNet]
    gestures: GestureModels
    recording: Path
    sentences: Path


def load_inputs(data: Path) -> Inputs:
    missing = [f for f in REQUIRED_FILES if not (data / f).is_file()]
    if missing:
        raise InputError(
            f"data folder {data} lacks {', '.join(missing)}; these files come from {SOURCES}; "
            "give --data (or BEYOND_DATA) the folder that holds them"
        )
    definition = load_definition(data / "salvi2012/networkDefinition.txt")
    dataset = load_bag(data / "salvi2012/sent-1-5_lab_aff_bag.txt", definition)
    networks = {rule: learn_network(dataset, unseen=rule) for rule in UNSEEN_COMPARED}
    gestures = load_models(data / "saponaro2019/human_data/HMM_M3_Q6_mixsplit.mat")
    return Inputs(
        model=networks["absent"],
        networks=networks,
        gestures=gestures,
        recording=data / "saponaro2019/human_data" / EXP3_RECORDING,
        sentences=data / "saponaro2019/sentence_10000samples_uniq.txt",
    )
