"""The lines a person reads about each gesture, the same offline (`beyond analyse`) and on the bus.

Lines depend only on contents. A gesture's lines are released as one block in frame order once it
is complete (ended, recognised, described, and its beliefs all in), and blocks in segment order,
so services interleaving their messages differently never change what is printed. "Its beliefs
all in" is the final belief, or a belief about a later gesture (beliefs come from one publisher,
in order); the description comes down another path and can overtake a belief held up on a
loaded machine, so it does not count.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

ANTICIPATION_THRESHOLD = 0.6  # an effect value this probable counts as anticipated
ANTICIPATED = ("ObjVel",)
AFTER_ALL_FRAMES = 1 << 62  # recognition and description come after every frame's events
KEPT = 256  # gestures printed (or skipped) kept, the most recent: what a repeat can be about

# order of event kinds within one frame of a gesture's block
STARTED, LOOKS, ANTICIPATES, ENDED, RECOGNISED, DESCRIBED = range(6)


@dataclass
class GestureLines:
    started: int | None = None
    best: str = ""
    end_frame: int | None = None
    anticipated: dict[str, str] = field(default_factory=dict)
    recognised: str = ""
    description: str = ""
    events: list[tuple[int, int, str]] = field(default_factory=list)  # (frame, kind, text)
    final_belief: bool = False
    printed: bool = False
    skipped: bool = False  # never completed, and a later gesture did

    @property
    def complete(self) -> bool:
        """Ended, recognised and described, and its final belief in (see the module's note)."""
        said = self.end_frame is not None and bool(self.recognised) and bool(self.description)
        return said and self.final_belief

    def block(self) -> list[str]:
        """The gesture's lines in frame order; anticipations count only before the end."""
        end = self.end_frame if self.end_frame is not None else AFTER_ALL_FRAMES
        kept = [e for e in self.events if e[1] != ANTICIPATES or e[0] <= end]
        return [text for _, _, text in sorted(kept, key=lambda e: (e[0], e[1]))]


class GestureReport:
    """Feed it what the pipeline produced; `release()` gives the lines ready to print."""

    def __init__(self) -> None:
        self.gestures: dict[int, GestureLines] = {}
        self.beliefs_about = 0  # the latest gesture a belief was about: the ones before are in

    def _g(self, segment_id: int) -> GestureLines:
        g = self.gestures.get(segment_id)
        if g is None:
            g = self.gestures[segment_id] = GestureLines(
                final_belief=segment_id < self.beliefs_about
            )
        return g

    def started(self, segment_id: int, frame: int) -> None:
        g = self._g(segment_id)
        if g.started is None:
            g.started = frame
            g.events.append((frame, STARTED, f"started at frame {frame}"))

    def ended(self, segment_id: int, frame: int) -> None:
        g = self._g(segment_id)
        if g.end_frame is None:
            g.end_frame = frame
            g.events.append((frame, ENDED, f"ended at frame {frame}"))

    def cancelled(self, segment_id: int) -> None:
        self.gestures.pop(segment_id, None)

    def belief(
        self, segment_id: int, frame: int, actions: Sequence[str], p: Sequence[float]
    ) -> None:
        """A non-final P_HMM at `frame`: a line when the most likely action changes."""
        self._beliefs_reached(segment_id)
        g = self._g(segment_id)
        i = max(range(len(p)), key=p.__getitem__)
        if actions[i] != g.best:
            g.best = actions[i]
            g.events.append(
                (frame, LOOKS, f"frame {frame}, looks like {g.best} (P_HMM {p[i]:.2f})")
            )

    def believed(self, segment_id: int) -> None:
        """The final P_HMM of the gesture: every belief about it is in."""
        self._beliefs_reached(segment_id)
        self._g(segment_id).final_belief = True

    def _beliefs_reached(self, segment_id: int) -> None:
        if segment_id > self.beliefs_about:
            for earlier, g in self.gestures.items():  # their final beliefs came first, or never
                if earlier < segment_id:
                    g.final_belief = True
            self.beliefs_about = segment_id

    def anticipation(
        self, segment_id: int, frame: int, effects: Mapping[str, Mapping[str, float]]
    ) -> None:
        g = self._g(segment_id)
        for var in ANTICIPATED:
            dist = effects.get(var)
            if not dist:
                continue
            value = max(dist, key=dist.__getitem__)
            if dist[value] >= ANTICIPATION_THRESHOLD and g.anticipated.get(var) != value:
                g.anticipated[var] = value
                text = (
                    f"anticipates {var}={value} (P {dist[value]:.2f}) at frame {frame}, "
                    "before the gesture ends"
                )
                g.events.append((frame, ANTICIPATES, text))

    def recognised(
        self, segment_id: int, action_belief: Mapping[str, float], evidence: Mapping[str, str]
    ) -> None:
        g = self._g(segment_id)
        if g.recognised:
            return
        action = max(action_belief, key=action_belief.__getitem__)
        g.recognised = action
        given = ", ".join(f"{k}={v}" for k, v in evidence.items()) or "nothing"
        text = f"recognised {action} (P {action_belief[action]:.2f}) given {given}"
        g.events.append((AFTER_ALL_FRAMES, RECOGNISED, text))

    def described(self, segment_id: int, sentence: str) -> None:
        g = self._g(segment_id)
        if not g.description:
            g.description = sentence
            g.events.append((AFTER_ALL_FRAMES, DESCRIBED, f'"{sentence}"'))

    def release(self) -> list[str]:
        """Lines of every complete gesture not printed yet, in segment order; a gesture waits for
        the incomplete ones before it that have started. Descriptions come in segment order
        (the reasoner emits gestures in order), so an incomplete gesture followed by a complete
        one will never complete (a stray or withdrawn start): it is skipped, not waited for."""
        lines: list[str] = []
        ids = sorted(self.gestures)
        for n, segment_id in enumerate(ids):
            g = self.gestures[segment_id]
            if g.printed or g.skipped:
                continue
            if not g.complete:
                if g.started is None:
                    continue  # never started here (a stray message): holds nothing back
                if any(self.gestures[later].complete for later in ids[n + 1 :]):
                    g.skipped = True
                    continue
                break
            lines += [f"gesture {segment_id}: {line}" for line in g.block()]
            g.printed = True
        told = [n for n in ids if self.gestures[n].printed or self.gestures[n].skipped]
        for segment_id in told[:-KEPT]:  # a long run: keep only the recent ones
            del self.gestures[segment_id]
        return lines

    @property
    def all_ended_printed(self) -> bool:
        """Every gesture that ended has been printed (or skipped): once the source's streams
        are all handled, a start with no end is a stray, not a gesture still under way."""
        return all(
            g.printed or g.skipped for g in self.gestures.values() if g.end_frame is not None
        )

    @property
    def all_printed(self) -> bool:
        return all(g.printed or g.skipped for g in self.gestures.values() if g.started is not None)

    @property
    def described_count(self) -> int:
        return sum(1 for g in self.gestures.values() if g.description)
