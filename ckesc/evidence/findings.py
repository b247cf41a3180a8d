"""What the bus rules found, kept in bounded memory: one :class:`Violation` per finding (a broken rule, or
with strength OBSERVE something recorded that is never a failure), the first few of each kind
(:class:`Findings`), and running interval statistics (:class:`Intervals`). Sans-IO."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..protocol.histogram import Histogram
from ..protocol.requirements import strongest

KEEP = 20  # findings and events kept per (node, check); the rest are counted
_HIST_BIN_S = 0.0005
HIST_BINS = 1200  # 0 .. 600 ms, then one overflow bin


def quote(can_id: int, data, timestamp: float, *, remote: bool = False, own: bool = False, note: str = "") -> str:
    """One frame in candump -L style: ``(12.345678) 1F4E5201#3412E8030181C3``, with a note."""
    body = "R" if remote else bytes(data).hex().upper()
    text = f"({timestamp:.6f}) {can_id:08X}#{body}{' T' if own else ''}"
    return f"{text}  {note}" if note else text


def ms(seconds: float) -> str:
    return f"{seconds * 1000:.3f} ms"


@dataclass(frozen=True)
class Violation:
    """A rule the bus broke (or, with strength OBSERVE, something recorded that is never a failure).

    ``rules``: requirement ids; ``check``: a short stable name of the check; ``message``: what was
    expected and what was seen; ``frames``: the offending frame(s) in candump -L style. The cause, as fields (a
    finding's cause is never read back from ``message``): ``subject``, what broke the rule, the same for every
    occurrence of one problem (``msg1``, ``set_freq response``); ``expected``, what the rule wanted, in words, the
    same for every occurrence too; ``measured_s`` and ``expected_s``, the time measured and the time wanted, where
    the rule is one of time."""

    rules: tuple[str, ...]
    strength: str
    timestamp: float
    node: int | None
    check: str
    message: str
    frames: tuple[str, ...] = ()
    subject: str = ""
    expected: str = ""
    measured_s: float | None = None
    expected_s: float | None = None

    @property
    def fails(self) -> bool:
        return self.strength != "OBSERVE"

    def __str__(self) -> str:
        where = f"node {self.node}" if self.node is not None else "bus"
        head = f"[{' '.join(self.rules)} {self.strength}] t={self.timestamp:.6f} {where}: {self.message}"
        return "\n    ".join((head, *self.frames))

    def to_json(self) -> dict[str, Any]:
        return {"rules": list(self.rules), "strength": self.strength, "timestamp": self.timestamp, "node": self.node,
                "check": self.check, "message": self.message, "frames": list(self.frames), "subject": self.subject,
                "expected": self.expected, "measured_s": self.measured_s, "expected_s": self.expected_s}



class Tally:
    """Findings of one kind: a count and the first few."""

    __slots__ = ("count", "first")

    def __init__(self) -> None:
        self.count = 0
        self.first: list[Violation] = []

    def add(self, v: Violation) -> None:
        self.count += 1
        if len(self.first) < KEEP:
            self.first.append(v)


class Intervals(Histogram):
    """Running statistics of one stream's intervals, in bounded memory: count, mean, stdev, min, max and a fixed-bin
    histogram (0.5 ms bins up to 600 ms, then an overflow bin). The project's one :class:`Histogram`, read by its bins'
    middles (the figures check-log and the reports show), a gap of exactly 20 ms in the 20.0 bin, not 19.5."""

    __slots__ = ()

    def __init__(self) -> None:
        super().__init__(_HIST_BIN_S, HIST_BINS, middle=True, nudge=1e-6)

    def to_json(self) -> dict[str, Any]:
        if not self.n:
            return {"count": 0}
        ms = lambda s: None if s is None else round(s * 1000, 4)  # noqa: E731
        return {"count": self.n, "mean_ms": ms(self.total / self.n), "stdev_ms": ms(self.stdev), "min_ms": ms(self.lo),
                "p50_ms": ms(self.quantile(0.5)), "p99_ms": ms(self.quantile(0.99)), "max_ms": ms(self.hi),
                "histogram_bin_ms": _HIST_BIN_S * 1000,
                "histogram": {str(round(i * _HIST_BIN_S * 1000, 1)) if i < HIST_BINS else "overflow": c
                              for i, c in enumerate(self.counts) if c}}


class Findings:
    """The findings of an engine: violations (:meth:`_violation`) and observations (:meth:`_observe`), the first
    few of each (node, check) kept, the rest counted."""

    def __init__(self) -> None:
        self._tallies: dict[tuple[int | None, str], Tally] = {}
        self._observed: dict[tuple[int | None, str], Tally] = {}
        self._by_rule: dict[str, int] = {}

    def _violation(self, out: list | None, rules: tuple[str, ...], ts: float, node: int | None, check: str, message: str,
                   frames: tuple[str, ...], *, subject: str, expected: str, measured_s: float | None = None,
                   expected_s: float | None = None) -> list:
        v = Violation(rules, strongest(rules), ts, node, check, message, frames, subject, expected, measured_s, expected_s)
        tally = self._tallies.get((node, check))
        if tally is None:
            tally = self._tallies[(node, check)] = Tally()
        tally.add(v)
        for rid in rules:
            self._by_rule[rid] = self._by_rule.get(rid, 0) + 1
        if out is None:
            out = []
        out.append(v)
        return out

    def _observe(self, rules: tuple[str, ...], ts: float, node: int | None, check: str, message: str,
                 frames: tuple[str, ...] = ()) -> None:
        tally = self._observed.get((node, check))
        if tally is None:
            tally = self._observed[(node, check)] = Tally()
        tally.add(Violation(rules, "OBSERVE", ts, node, check, message, frames))

    @property
    def violations(self) -> int:
        return sum(t.count for t in self._tallies.values())

    def findings(self, *, observations: bool = False) -> list[Violation]:
        """The first few findings of each kind, in time order."""
        tallies = self._observed if observations else self._tallies
        return sorted((v for t in tallies.values() for v in t.first), key=lambda v: v.timestamp)

