"""Verdicts and measurements.

A check compares a measured value with a limit and records value, limit, margin and the clock that
measured it. In a lane whose timing has a stated measurement error, a result whose margin is
smaller than that error is INCONCLUSIVE, neither PASS nor FAIL. OBSERVE requirements record what
was seen and never fail.

A failed limit does not stop the test: :class:`Record` keeps every failed limit and the plugin fails
the test at its end (:meth:`Record.failure_message`), the strongest broken requirement first, so an
answer after 80 ms is reported as breaking the SHALL 64 ms bound as well as its READING slot.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass, field
from typing import Any

import pytest

from ..protocol.requirements import STRENGTHS, Verdict

CLOCKS = ("simulated", "bus timestamp", "host clock")

#: the order in which broken requirements lead a failure message
STRENGTH_ORDER = STRENGTHS

_OPS = {"<=": operator.le, "<": operator.lt, ">=": operator.ge, ">": operator.gt, "==": operator.eq}


class Inconclusive(pytest.skip.Exception):  # type: ignore[misc, name-defined]
    """The DUT could not be judged (margin below the measurement error, power cycle not proven,
    capability missing). Reported as INCONCLUSIVE, never as a pass."""

    def __init__(self, msg: str) -> None:
        super().__init__(msg=f"INCONCLUSIVE: {msg}", allow_module_level=False)


class NotClaimed(pytest.skip.Exception):  # type: ignore[misc, name-defined]
    """The test needs a function the DUT profile declares absent (R9b): SKIPPED, "not claimed", and
    the reports say what the conformance claim leaves out."""

    def __init__(self, function: str, profile: str) -> None:
        super().__init__(msg=f"not claimed: {function} (R9b): the DUT profile {profile!r} declares it absent",
                         allow_module_level=False)


@dataclass
class Measurement:
    name: str
    value: float
    limit: float | None
    op: str
    unit: str
    clock: str
    error: float = 0.0  # the lane's stated measurement error for this clock
    verdict: str = Verdict.PASS
    requirement: str | None = None

    @property
    def margin(self) -> float | None:
        if self.limit is None:
            return None
        if self.op in ("<=", "<"):
            return self.limit - self.value
        if self.op in (">=", ">"):
            return self.value - self.limit
        return -abs(self.value - self.limit)

    def as_properties(self, index: int) -> dict[str, str]:
        p = f"measurement.{index}."
        out = {p + "name": self.name, p + "value": f"{self.value:.6g} {self.unit}".strip(), p + "clock": self.clock,
               p + "verdict": self.verdict}
        if self.limit is not None:
            out[p + "limit"] = f"{self.op} {self.limit:.6g} {self.unit}".strip()
            out[p + "margin"] = f"{self.margin:.6g} {self.unit}".strip()
        if self.error:
            out[p + "error"] = f"+-{self.error:.6g} {self.unit}".strip()
        if self.requirement:
            out[p + "requirement"] = self.requirement
        return out

    def __str__(self) -> str:
        s = f"{self.name} = {self.value:.6g}{self.unit}"
        if self.limit is not None:
            s += f" (limit {self.op} {self.limit:.6g}{self.unit}, margin {self.margin:.6g}{self.unit}"
            s += f", {self.clock}" + (f", error +-{self.error:.3g}{self.unit})" if self.error else ")")
        return s


@dataclass
class Record:
    """What one test measured and observed; the plugin turns it into report properties."""

    measurements: list[Measurement] = field(default_factory=list)
    observations: list[tuple[str, Any]] = field(default_factory=list)
    inconclusive: list[str] = field(default_factory=list)
    #: the failed limits, (strength, "[requirement strength] measurement"), in the order measured
    failed: list[tuple[str, str]] = field(default_factory=list)

    def observe(self, what: str, value: Any) -> None:
        self.observations.append((what, value))

    def measure(self, name: str, value: float, *, limit: float | None = None, op: str = "<=", unit: str = "",
                clock: str = "simulated", error: float = 0.0, requirement: str | None = None,
                strength: str = "SHALL") -> Measurement:
        """Record a measurement and judge it. A FAIL (unless the requirement is OBSERVE) is kept in
        :attr:`failed` and fails the test at its end; a margin inside ``error`` makes it
        :class:`Inconclusive` at the end of the test (unless a limit failed)."""
        if clock not in CLOCKS:
            raise ValueError(f"clock must be one of {CLOCKS}")
        m = Measurement(name, value, limit, op, unit, clock, error, requirement=requirement)
        self.measurements.append(m)
        if limit is None:
            return m
        ok = _OPS[op](value, limit)
        margin = m.margin or 0.0
        if error and abs(margin) < error:
            m.verdict = Verdict.INCONCLUSIVE
            self.inconclusive.append(f"{m} is within the measurement error")
            return m
        if not ok:
            m.verdict = Verdict.OBSERVED if strength == "OBSERVE" else Verdict.FAIL
            if strength != "OBSERVE":
                tag = f"[{requirement} {strength}] " if requirement else f"[{strength}] "
                self.failed.append((strength, f"{tag}{m}"))
                return m
            self.observe(name, str(m))
        return m

    def failure_message(self, assertion: str = "", strength: str = "SHALL") -> str:
        """The test's failure message: every failed limit and ``assertion`` (the test's own failed
        assert, of ``strength``), the strongest broken requirement first, the others listed after it;
        "" when nothing failed."""
        broken = list(self.failed)
        if assertion:
            broken.append((_tag_strength(assertion) or strength, assertion))
        if not broken:
            return ""
        broken.sort(key=lambda sb: STRENGTH_ORDER.index(sb[0]) if sb[0] in STRENGTH_ORDER else len(STRENGTH_ORDER))
        head, *others = [text for _, text in broken]
        if not others:
            return head
        return head + f"\nalso broken ({len(others)}):\n" + "\n".join(f"- {o}" for o in others)


def _tag_strength(message: str) -> str | None:
    """The strength a message's leading ``[ids STRENGTH]`` tag names, if it has one."""
    first = message.lstrip().split("]", 1)[0]
    if message.lstrip().startswith("[") and first.rsplit(" ", 1)[-1] in STRENGTH_ORDER:
        return first.rsplit(" ", 1)[-1]
    return None
