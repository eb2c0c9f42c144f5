"""The live terminal view of `beyond up`: service health (with how many times each service was
restarted after dying), a camera source's pose rate and the frames it shed, the action
posterior as bars, the effect prediction and the last description, redrawn as messages arrive
(rich)."""

from __future__ import annotations

from rich.console import Group, RenderableType
from rich.panel import Panel
from rich.table import Table

from beyond_self.monitor import POSE_WINDOW_S, PipelineMonitor

BAR = 28


def _bar(p: float) -> str:
    filled = round(max(0.0, min(1.0, p)) * BAR)
    return "█" * filled + "·" * (BAR - filled)


def render(monitor: PipelineMonitor, expected: list[str]) -> RenderableType:
    health = Table(title="services", expand=True)
    columns = (
        "service", "in", "out", "dropped", "skipped", "malformed", "errors", "restarts",
        "last error",
    )  # fmt: skip
    for col in columns:
        health.add_column(col, justify="left" if col in ("service", "last error") else "right")
    for name in expected:
        h = monitor.health_reports.get(name)
        if h is None:
            health.add_row(name, *["-"] * (len(columns) - 2), "starting")
            continue
        health.add_row(
            name, str(h.messages_in), str(h.messages_out), str(h.dropped), str(h.skipped),
            str(h.malformed), str(h.errors), str(h.restarts), h.last_error[:40],
        )  # fmt: skip
    parts: list[RenderableType] = [health]
    if monitor.poses:  # a camera source: how fast its pose model goes, what it shed
        ingest = monitor.health_reports.get("ingest")
        shed = f", {ingest.skipped} frame(s) shed to keep up" if ingest else ""
        parts.append(
            f"pose: {monitor.pose_rate:.1f} Hz over the last {POSE_WINDOW_S:g} s, "
            f"{monitor.poses} frame(s) with a person{shed}"
        )
    post = monitor.posterior
    if post is not None:
        t = Table.grid(padding=(0, 1))
        for action, p in zip(post.actions, post.posterior, strict=True):
            t.add_row(action, _bar(p), f"{p:.2f}")
        title = f"gesture {post.segment_id}, frame {post.frame}: P_HMM(action)"
        parts.append(Panel(t, title=title))
    pred = monitor.prediction
    if pred is not None:
        t = Table.grid(padding=(0, 1))
        for action, p in pred.action_belief.items():
            t.add_row("Action", action, _bar(p), f"{p:.2f}")
        for var, dist in pred.effects.items():
            for value, p in dist.items():
                t.add_row(var, value, _bar(p), f"{p:.2f}")
        kind = "final" if pred.final else "anticipated"
        parts.append(Panel(t, title=f"gesture {pred.segment_id}: fused belief ({kind})"))
    if monitor.description is not None and monitor.description.sentences:
        d = monitor.description
        lines = "\n".join(f"{s.score:8.4f}  {s.text}" for s in d.sentences[:3])
        parts.append(Panel(lines, title=f"gesture {d.segment_id}: description"))
    return Group(*parts)
