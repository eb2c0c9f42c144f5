"""Chaos acceptance, seeds 4-7 (issue 39; the run is tests/chaos.py): under SIGKILLs and
freezes drawn from the seed, `up` stops cleanly, prints the gesture lines `beyond analyse`
prints, and says each sentence once."""

import chaos

expected, runs, test_chaos_changes_nothing = chaos.seed_tests([4, 5, 6, 7])
