"""Chaos acceptance, seeds 0-3 (issue 39; the run is tests/chaos.py): under SIGKILLs and
freezes drawn from the seed, `up` stops cleanly, prints the gesture lines `beyond analyse`
prints, and says each sentence once."""

import chaos

expected, runs, test_chaos_changes_nothing = chaos.seed_tests([0, 1, 2, 3])
