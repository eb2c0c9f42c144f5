"""`beyond bw KEY`: bandwidth of a key over a sliding window."""

from __future__ import annotations

import argparse

from beyond_self.commands import rate_watch
from beyond_self.runtime.bus.rates import RateStats

HELP = "bandwidth of a key over a sliding window"
add_arguments = rate_watch.add_arguments


def show(key: str, s: RateStats) -> str:
    rate = "-" if s.bytes_per_s is None else f"{s.bytes_per_s / 1e3:.1f} kB/s"
    return (
        f"{key}: {rate}; message mean {s.mean_bytes:.0f} B min {s.min_bytes} B "
        f"max {s.max_bytes} B; window {s.count} messages"
    )


def run(args: argparse.Namespace) -> int:
    return rate_watch.run(args, show)
