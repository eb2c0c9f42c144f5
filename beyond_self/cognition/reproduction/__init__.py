"""The article's experiments 1–6 (docs/science/reproduce.md) on the real data, as plain functions.

One module per experiment (`exp1_conflict` ... `exp6_colours`), each computing its numbers from
the network and, where needed, the reference gesture models (`inputs`); `run_all` (`run`) runs
them in order and `write_report` (`report`) turns the results into `report.md`, one PNG per
figure and `results.json`. Everything here is deterministic. The experiments run on the default
network (unseen word columns: P(absent) = 1); `figure_checks` re-runs every figure the article
prints numbers for under each rule for unseen word columns and checks it against the article
(cognition.published): the article's Table II exists only under "zero", the toolbox's.
"""

from beyond_self.cognition.reproduction.exp1_conflict import EXP1_OBSERVED, exp1
from beyond_self.cognition.reproduction.exp2_effects import EXP2_MIXES, exp2, mix_label
from beyond_self.cognition.reproduction.exp3_anticipation import (
    EXP3_EVERY,
    EXP3_FRAMES,
    anticipate,
    by_action,
    exp3,
)
from beyond_self.cognition.reproduction.exp4_words import EXP4_OBSERVED, exp4
from beyond_self.cognition.reproduction.exp5_descriptions import EXP5_GRASP, exp5
from beyond_self.cognition.reproduction.exp6_colours import COLOUR_WORD, EXP6_OBJECTS, exp6
from beyond_self.cognition.reproduction.figure_checks import published, table2
from beyond_self.cognition.reproduction.inputs import (
    EXP3_RECORDING,
    REQUIRED_FILES,
    UNSEEN_COMPARED,
    Inputs,
    load_inputs,
)
from beyond_self.cognition.reproduction.report import (
    check_cell,
    figures_table,
    needs_cell,
    results_json,
    write_report,
)
from beyond_self.cognition.reproduction.run import run_all

__all__ = [
    "COLOUR_WORD",
    "EXP1_OBSERVED",
    "EXP2_MIXES",
    "EXP3_EVERY",
    "EXP3_FRAMES",
    "EXP3_RECORDING",
    "EXP4_OBSERVED",
    "EXP5_GRASP",
    "EXP6_OBJECTS",
    "REQUIRED_FILES",
    "UNSEEN_COMPARED",
    "Inputs",
    "anticipate",
    "by_action",
    "check_cell",
    "exp1",
    "exp2",
    "exp3",
    "exp4",
    "exp5",
    "exp6",
    "figures_table",
    "load_inputs",
    "mix_label",
    "needs_cell",
    "published",
    "results_json",
    "run_all",
    "table2",
    "write_report",
]
