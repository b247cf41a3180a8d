"""What a soak run shows, in words a release can sign (issue #31): per watched property, the events counted and,
with none, the rule of three: no event in T means the event's rate is below 3 / T at 95 % confidence (with none in n
trials, its probability per trial below 3 / n)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..reporting.durations import duration_text

#: the rule of three: -ln(0.05) = 2.996, rounded up as it is quoted (the 95 % upper bound of a rate with no event)
RULE_OF_THREE = 3
CONFIDENCE = "95 %"


def _rate(value: float) -> str:
    return f"{value:.3g}"


@dataclass(frozen=True)
class Statement:
    """One watched property's line: ``events`` of ``what`` (one is ``one``) in ``seconds`` of run (per ``unit``: ``hour``, or a trial:
    ``minute``, ``answer``, counted in ``trials``)."""

    watch: str
    rules: tuple[str, ...]
    what: str  # the events, plural: "resets"
    one: str  # one of them: "reset"
    events: int
    seconds: float
    unit: str = "hour"
    trials: int = 0

    @property
    def bound(self) -> float | None:
        """The 95 % upper bound of the rate with no event (per hour, or per trial); None with events or no exposure."""
        if self.events:
            return None
        exposure = self.seconds / 3600 if self.unit == "hour" else self.trials
        return RULE_OF_THREE / exposure if exposure > 0 else None

    @property
    def text(self) -> str:
        span = duration_text(self.seconds)
        if self.unit == "hour":
            if self.events:
                return f"{self.events} {self.what} in {span}"
            bound = self.bound
            if bound is None:
                return f"0 {self.what} in {span}: too short a run to bound the rate"
            return f"0 {self.what} in {span}: the {self.one} rate is below {_rate(bound)} per hour at {CONFIDENCE} confidence"
        if self.events:
            return f"{self.events} {self.what} of {self.trials} {self.unit}s judged in {span}"
        bound = self.bound
        if bound is None:
            return f"0 {self.what}: no {self.unit} judged in {span}"
        if bound >= 1:
            return f"0 {self.what} of {self.trials} {self.unit}s judged in {span}: too few to bound the chance"
        return (f"0 {self.what} of {self.trials} {self.unit}s judged in {span}: the chance of one {self.unit} breaking it is below "
                f"{_rate(bound * 100)} % at {CONFIDENCE} confidence")

    def to_json(self) -> dict[str, Any]:
        return {"watch": self.watch, "rules": list(self.rules), "events": self.events, "trials": self.trials,
                "unit": self.unit, "seconds": round(self.seconds, 3), "bound": self.bound, "text": self.text}
