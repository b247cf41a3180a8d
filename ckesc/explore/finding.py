"""What the explorer's judge finds (:class:`ExploreFinding`), the bench's limits it judges with (:class:`Params`) and the
report streams it names (:func:`stream_of`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from ..protocol import catalogue as cat
from ..protocol.frame import Frame
from ..protocol.ids import Kind
from ..protocol.requirements import requirement


@dataclass
class ExploreFinding:
    kind: str  # answer | stream | interval | status | recovery (R20) | bus_rule (the reader's: F1..F7, R9 per gap, R9a, resets)
    requirements: list[str]
    what: str
    dut: str
    model: str
    at: float  # lane seconds from the program's start
    step: int | None = None  # the program step it follows (index), None: before any
    strength: str = field(default="")
    subject: str = ""  # what disagrees, without the numbers of this occurrence (the problem's key)

    def __post_init__(self) -> None:
        if not self.strength:
            strengths = [requirement(r).strength for r in self.requirements]  # an unknown id raises: never dropped
            self.strength = "SHALL" if "SHALL" in strengths else ("READING" if "READING" in strengths else "OBSERVE")

    @property
    def key(self) -> str:
        """The same problem, whatever program shows it (and however it got there): kind and subject."""
        return f"{self.kind}|{self.subject or self.what}"

    def to_json(self) -> dict[str, Any]:
        return {**asdict(self), "key": self.key}

    def text(self) -> str:
        where = f"after step {self.step + 1}" if self.step is not None else "before the first step"
        return (f"[{' '.join(self.requirements)} {self.strength}] {self.what} ({where}, t={self.at:.3f} s)\n"
                f"  DUT:   {self.dut}\n  model: {self.model}")


@dataclass
class Params:
    error: float = 0.0  # the bench's timing error (s)
    own_error: float = 0.0  # the error of the host's own frames' times (the request an answer's delay counts from)
    jitter: float = 0.0  # the DUT's declared report jitter (profile jitter_s)
    boot_s: float = 0.5  # power-on to first report (profile)
    bitrate: int = cat.DEFAULT_BITRATE
    host_node: int = 0

    @property
    def host_late(self) -> float:
        """How much later than the DUT heard it a host frame may be stamped, as the bench states it: its stamp's error
        (:attr:`own_error`: its echo's, or without an echo the host clock's at send, ``Lane.own_error``) and the
        error of the DUT's frame it is compared with (:attr:`error`). The oracle hears the host frame at its stamp, so
        what the DUT did on it may show that much early."""
        return self.own_error + self.error


_EXP = frozenset(cat.EXP_REPORT_FRAMES)
#: the report streams judged: MSG1, MSG2, MSG3, the MSG_EXP frames as one, CAN Test
STREAMS = (*cat.REPORT_FRAMES, "exp", "can_test")
#: the stream each report frame (by name) belongs to
STREAM_OF = {**{n: n for n in (*cat.REPORT_FRAMES, "can_test")}, **{n: "exp" for n in _EXP}}


def stream_of(f: Frame) -> str | None:
    """The report stream (:data:`STREAMS`) an ESC's frame belongs to, None: not a report."""
    n = f.name
    if n in (*cat.REPORT_FRAMES, "can_test"):
        return n if f.kind is Kind.MESSAGE else None
    return "exp" if n in _EXP else None
