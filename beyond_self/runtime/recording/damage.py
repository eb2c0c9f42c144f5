"""What reading a recording lost, and the one line every command says about it.

One policy for damaged input, the same in `inspect`, `analyse`, `replay` and `up`: every intact
chunk is read, what is readable is played, and what was lost is said in one line (exit 2). Lost
are: unreadable chunks and skipped bytes, a truncated tail, messages on a channel no intact
record defines, messages that do not decode or hold a value out of range (a NaN joint), and
messages whose stamp is not after the previous one on their key (a consumer would refuse them,
so every command drops them the same way, before anyone sees them). Times in the line are
seconds from the recording's first stamp, as `beyond inspect` shows them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from beyond_self.runtime.error_account import bounded

_SHOWN = 3  # damaged chunks described one by one in the line; the others are counted


@dataclass
class Losses:
    path: str
    size: int = 0
    read: int = 0  # messages read from intact records
    expected: int | None = None  # messages the summary says the file holds (a complete summary)
    first_stamp: int | None = None
    truncated: str = ""  # where the file ends before its footer
    damaged: list[str] = field(default_factory=list)  # chunks and byte ranges not read
    dropped: dict[str, int] = field(default_factory=dict)  # why -> messages dropped
    examples: dict[str, str] = field(default_factory=dict)  # why -> the first one, described
    unknown_lost: bool = False  # lost records whose message count nobody knows

    # -- tallying -------------------------------------------------------------------------

    def at(self, stamp: int) -> str:
        """`stamp` as seconds from the first stamp read (or as it is, before any)."""
        if self.first_stamp is None:
            return f"{stamp} ns"
        return f"{(stamp - self.first_stamp) / 1e9:.3f} s"

    def chunk(self, offset: int, span: tuple[int, int] | None, reason: str) -> None:
        """A chunk at byte `offset` whose records could not be read."""
        when = f"{self.at(span[0])}-{self.at(span[1])}, " if span else ""
        self.damaged.append(f"chunk at byte {offset} ({when}{bounded(reason, 120)})")
        self.unknown_lost = True

    def skipped(self, start: int, end: int, reason: str) -> None:
        """Bytes [start, end) that hold no readable record (a damaged record header)."""
        self.damaged.append(f"bytes {start}-{end} ({bounded(reason, 120)})")
        self.unknown_lost = True

    def cut(self, at: int, reason: str) -> None:
        """The file ends at byte `at` without its footer."""
        self.truncated = f"truncated at byte {at} of {self.size} ({bounded(reason, 120)})"
        self.unknown_lost = True

    def drop(self, why: str, example: str) -> None:
        """A message read but not played, for reason `why` (a short phrase, counted)."""
        self.dropped[why] = self.dropped.get(why, 0) + 1
        self.examples.setdefault(why, bounded(example, 200))

    # -- reporting ------------------------------------------------------------------------

    @property
    def any(self) -> bool:
        return bool(self.truncated or self.damaged or self.dropped)

    @property
    def lost(self) -> int | None:
        """Messages lost, when known: dropped ones plus unread ones the summary accounts for."""
        dropped = sum(self.dropped.values())
        if not self.unknown_lost:
            return dropped
        if self.expected is not None and not self.truncated:
            return dropped + max(0, self.expected - self.read)
        return None

    def line(self) -> str:
        """One line: where the file is damaged, how much was lost, what was still read."""
        parts: list[str] = []
        if self.truncated:
            parts.append(self.truncated)
        if self.damaged:
            shown = "; ".join(self.damaged[:_SHOWN])
            more = len(self.damaged) - _SHOWN
            parts.append(f"unreadable: {shown}" + (f"; and {more} more" if more > 0 else ""))
        for why, n in self.dropped.items():
            parts.append(f"{n} message{'s' if n != 1 else ''} dropped ({why}; first: "
                         f"{self.examples[why]})")  # fmt: skip
        lost = self.lost
        if lost is None:
            count = "messages lost (how many: unknown)"
        else:
            of = f" of {self.expected}" if self.expected is not None else ""
            count = f"{lost}{of} message{'s' if lost != 1 or of else ''} lost"
        played = self.read - sum(self.dropped.values())
        return f"{self.path} is damaged: {'; '.join(parts)}; {count}; played the other {played}"
