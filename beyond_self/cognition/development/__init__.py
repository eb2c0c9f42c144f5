"""Developmental learning: from the robot's own experience to recognising a person's actions.

`run_learning(LearningConfig(), robot_data=..., human_data=...)` (`learning`) runs the steps,
`write_outputs` (`report`) writes learning.md, results.json and PNGs; `demonstrations` makes the
demonstrations the robot watches. The choices and why are in docs/science/development.md. Each
name is imported from its own module (the package re-exports nothing).
"""
