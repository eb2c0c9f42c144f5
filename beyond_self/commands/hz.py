"""`beyond hz KEY`: message rate over a sliding window, from stamps and from arrival."""

from __future__ import annotations

import argparse

from beyond_self.commands import rate_watch
from beyond_self.runtime.bus.rates import RateStats

HELP = "message rate of a key over a sliding window (from stamps and from arrival)"
add_arguments = rate_watch.add_arguments


def show(key: str, s: RateStats) -> str:
    return (
        f"{key}: {rate_watch.hz(s.stamp_hz)} from stamps, {rate_watch.hz(s.arrival_hz)} "
        f"arriving; gaps min {rate_watch.seconds(s.min_interval_s)} "
        f"max {rate_watch.seconds(s.max_interval_s)} std {rate_watch.seconds(s.std_interval_s)}; "
        f"window {s.count} messages"
    )


def run(args: argparse.Namespace) -> int:
    return rate_watch.run(args, show)
