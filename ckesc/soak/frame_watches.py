"""The soak's watches of what the ESC sends besides its reports and answers' timing: its settings (242's answers
unchanged, R13, :func:`~ckesc.protocol.judgements.r13_read_back`) and the frames it should not send (one that does
not decode, or a frame type normal reporting never sends and the player never asked for)."""

from __future__ import annotations

from typing import Any

from ..protocol import judgements as jd
from ..protocol.errors import DecodeError
from ..protocol.frame import Frame
from .watch import Monitoring, Watch

#: a frame that does not decode: the requirement its reason breaks
DECODE_RULES = {"not-extended-data-frame": "F1", "not-single-frame": "F2", "reserved-node-id": "F7",
                "unknown-type-id": "4.3.1-1"}


class SettingsWatch(Watch):
    name = "settings"
    rules = ("R19", "R13")
    what = "settings changes"
    one = "settings change"

    def __init__(self, monitor: Monitoring) -> None:
        super().__init__(monitor)
        self.first: dict[str, Any] | None = None
        self.now: dict[str, Any] | None = None

    def read(self, frame: Frame, t: float) -> None:
        self.trials += 1
        fields = dict(frame.fields)
        if self.first is None:
            self.first = self.now = fields
            return
        changed = jd.r13_read_back(self.now or {}, fields)
        if changed:
            self.find(t, "Get Major Configuration (242) changed: " + ", ".join(str(d) for d in changed))
        self.now = fields

    def statistics(self) -> dict[str, Any]:
        return {"reads_242": self.trials, "first": self.first, "last": self.now}


class UnexpectedWatch(Watch):
    name = "unexpected frames"
    rules = ("R19",)
    what = "unexpected frames"
    one = "unexpected frame"

    def __init__(self, monitor: Monitoring) -> None:
        super().__init__(monitor)
        self.kinds: dict[str, int] = {}

    def garbled(self, error: DecodeError, t: float) -> None:
        self._note(f"undecodable ({error.reason})", t, f"a frame that does not decode: {error}",
                   (DECODE_RULES.get(error.reason, "R19"),))

    def frame(self, frame: Frame, t: float) -> None:
        self._note(frame.name, t, f"{frame.name} ({frame.kind.label}) {frame.fields}: normal reporting never sends it and "
                   "the flight controller asked for nothing it answers", self.rules)

    def _note(self, kind: str, t: float, message: str, rules: tuple[str, ...]) -> None:
        self.kinds[kind] = self.kinds.get(kind, 0) + 1
        self.find(t, message, rules)

    def statistics(self) -> dict[str, Any]:
        return {"by_kind": self.kinds}
