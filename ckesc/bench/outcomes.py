"""Verdicts and measurements.

A check compares a measured value with a limit and records value, limit, margin and the clock that
measured it. In a lane whose timing has a stated measurement error, a result whose margin is
smaller than that error is INCONCLUSIVE, neither PASS nor FAIL. OBSERVE requirements record what
was seen and never fail.

A failed limit does not stop the test: :class:`Record` keeps every failed limit and the plugin fails
the test at its end (:meth:`Record.failure_message`), the strongest broken requirement first, so an
answer after 80 ms is reported as breaking the SHALL 64 ms bound as well as its READING slot.

What broke travels typed (:class:`Broken`: its requirements, strength and what the DUT did; :meth:`Measurement.as_json`:
its numbers), into the results as fields; the message is their rendering, never read back.
"""

from __future__ import annotations

import operator
from dataclasses import asdict, dataclass, field
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


@dataclass(frozen=True)
class Broken:
    """One broken requirement of a test: the requirement ids it breaks (none named: the test's own of that strength),
    its strength, and what the DUT did (a measurement against its limit, or a failed assert's message)."""

    requirements: tuple[str, ...]
    strength: str
    text: str

    def __str__(self) -> str:
        return f"[{' '.join((*self.requirements, self.strength))}] {self.text}"

    def as_json(self) -> dict[str, Any]:
        return {"requirements": list(self.requirements), "strength": self.strength, "text": self.text}

    @classmethod
    def of_assertion(cls, message: str, requirements: list[str], strength: str) -> Broken:
        """A test's failed assert: its message, led by the requirement it breaks where the test names one of those it
        cites (``assert ok, "[R1 READING] ..."``: the test's own words, read once as it failed), else the test's
        requirements of ``strength``, its strongest."""
        head, sep, rest = message.removeprefix("[").partition("]") if message.startswith("[") else ("", "", "")
        *ids, word = head.split() or [""]
        if sep and word in STRENGTHS:
            return cls(tuple(ids), word, rest.strip())
        return cls(tuple(requirements), strength, message)


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

    def as_json(self) -> dict[str, Any]:
        """Its fields and margin as numbers (results.json's ``measured``; ``as_properties`` renders them for JUnit)."""
        return {**asdict(self), "margin": self.margin}

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
    #: the failed limits, in the order measured
    failed: list[Broken] = field(default_factory=list)

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
                self.failed.append(Broken((requirement,) if requirement else (), strength, str(m)))
                return m
            self.observe(name, str(m))
        return m

    def broken(self, assertion: Broken | None = None) -> list[Broken]:
        """Every failed limit and ``assertion`` (the test's own failed assert), the strongest first (in the order
        measured among equals)."""
        broken = [*self.failed, *((assertion,) if assertion else ())]
        return sorted(broken, key=lambda b: STRENGTH_ORDER.index(b.strength) if b.strength in STRENGTH_ORDER
                      else len(STRENGTH_ORDER))

    def failure_message(self, assertion: Broken | None = None) -> str:
        """The test's failure message (:func:`failure_text` of :meth:`broken`); "" when nothing failed."""
        return failure_text(self.broken(assertion))


def failure_text(broken: list[Broken]) -> str:
    """A failure message: the strongest broken requirement, the others listed after it ("" for none)."""
    if not broken:
        return ""
    head, *others = map(str, broken)
    if not others:
        return head
    return head + f"\nalso broken ({len(others)}):\n" + "\n".join(f"- {o}" for o in others)
