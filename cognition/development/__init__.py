"""Developmental learning: from the robot's own experience to recognising a human's actions.

    from beyond_self.cognition.development.learning import LearningConfig, run_learning
    from beyond_self.cognition.development.report import write_outputs
    results = run_learning(LearningConfig(), robot_data="synthetic", human_data="synthetic")
    write_outputs(results, "out/")        # learning.md, results.json, PNGs

`demonstrations` makes the human demonstrations the robot watches (gesture, object, effects,
words, each imperfect); `learning` holds the steps (network posteriors, the labelling rule,
training on inferred labels, tempered gesture evidence, fusion, scores); `report` writes the
outputs. The module docstrings say what was chosen and why. Each name is imported from its own
module (the package re-exports nothing: one import path per name).
"""
