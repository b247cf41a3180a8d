"""The bus rules in the background of a suite run: one :class:`LaneRules` listener per lane.

The plugin puts one on every lane it opens (``lane.listeners``), so the engine sees every frame the
lane reads, both directions (the host's own frames are their echo, ``is_rx`` False), with the lane's
timestamps. What it finds while a test runs (setup, call and teardown) fails that test:
:meth:`LaneRules.begin` at the start of a test, :meth:`LaneRules.take` when its verdict is made.
"""

from __future__ import annotations

import re
from collections import Counter

import can

from ..protocol.judgements import timing_tolerance
from .rules import BusRules, Violation

#: Violations quoted in a failure message; the rest are counted.
QUOTED = 3
_KEPT = 50


def tolerance_for(lane) -> float:
    """The timing tolerance of a lane (:func:`ckesc.protocol.judgements.timing_tolerance`)."""
    return timing_tolerance(lane.clock, lane.timing_error)


class LaneRules(can.Listener):
    """The bus rules over one lane's frames, violations kept per test."""

    def __init__(self, lane, *, jitter: float = 0.0) -> None:
        """``jitter``: the DUT's report-interval jitter allowance (seconds; the profile's ``jitter_s``)."""
        self.lane = lane
        # the simulated lane hears every frame on its bus; a real bus or socketcand may drop some
        # the suite's power cycles go through Dut.switch_power, which tells the rules (power_switched)
        # the host's own frames' stamps: their echo's, or without one the host clock's (the bench's stated errors)
        self.rules = BusRules(tolerance=tolerance_for(lane), bitrate=lane.bitrate, complete=lane.clock == "simulated",
                              jitter=jitter, power_known=True, own_error=getattr(lane, "own_error", 0.0))
        self._reopens = lane.reopens
        self.found: list[Violation] = []
        self.count = 0
        self.between = 0  # violations while no test ran (session fixtures)
        #: rule ids whose violations a test has excused for a while (:meth:`excuse`), and those it excused
        self.excused: frozenset[str] = frozenset()
        self.excused_found: list[Violation] = []

    def on_message_received(self, msg: can.Message) -> None:
        if self.lane.reopens != self._reopens:  # the host reopened its bus (Set Baud's tests)
            self._reopens = self.lane.reopens
            self.rules.rejoined(self.lane.bitrate)
        found = self.rules.feed_message(msg)
        if found and self.excused:
            self.excused_found += [v for v in found if v.rules[0] in self.excused]
            found = [v for v in found if v.rules[0] not in self.excused]
        if found:
            self.count += len(found)
            room = _KEPT - len(self.found)
            if room > 0:
                self.found.extend(found[:room])

    def excuse(self, rules: frozenset[str]) -> list[Violation]:
        """From now on, a violation whose first rule is one of ``rules`` fails no test but is kept in
        :attr:`excused_found` (a reading that makes the rule OBSERVE while the test's stimulus lasts: R18 above
        half load); ``frozenset()`` ends it. Returns what was excused until now, and forgets it."""
        excused, self.excused_found = self.excused_found, []
        self.excused = frozenset(rules)
        return excused

    def power_switched(self, when: float) -> None:
        """The host switched the DUT's power at lane time ``when`` (see BusRules.power_switched)."""
        self.rules.power_switched(when)

    def begin(self) -> None:
        """A test starts: what was found before it is nobody's test's."""
        self.between += self.count
        self.found, self.count = [], 0

    def take(self) -> tuple[list[Violation], int]:
        """What was found since :meth:`begin` or the last take: (the first few, how many in all)."""
        found, count = self.found, self.count
        self.found, self.count = [], 0
        return found, count

    @property
    def closed(self) -> bool:
        return bool(getattr(self.lane.bus, "_is_shutdown", False))


def failure_text(found: list[Violation], count: int) -> tuple[str, list[str]]:
    """The failure message of a test during which the bus broke rules, and the requirement ids named."""
    ids = list(dict.fromkeys(rid for v in found for rid in v.rules))
    head = f"[bus rules {' '.join(ids)}] {count} violation(s) of the rules that hold at all times while this test ran"
    shown = "\n".join(str(v) for v in found[:QUOTED])
    more = f"\n... {count - QUOTED} more" if count > QUOTED else ""
    return f"{head}:\n{shown}{more}", ids


# a test's own failure message carries no typed cause: reporting/causes.py groups it by its text with these (a
# violation's cause is its fields, :func:`cause_key`)
_PARENS = re.compile(r"\s*\([^()]*\)")
#: a number on its own (a transfer id, a time, a count; not the 1 of msg1 or the 14 of raw_command_14b)
_VARYING = re.compile(r"(?<![A-Za-z_\d.])(?:0x[0-9A-Fa-f]+|\d+(?:\.\d+)?)(?=(?:ms|us|s|V|A|Hz|rpm)?(?![A-Za-z_\d]))")
_LIST = re.compile(r"\[[^\]]*\]")


def without_context(text: str) -> str:
    """``text`` without its parenthesised parts, nested ones included."""
    while True:
        out = _PARENS.sub("", text)
        if out == text:
            return out
        text = out


def generalise(text: str) -> str:
    """``text`` with what varies per occurrence made ``#``: numbers on their own and bracketed lists."""
    return _VARYING.sub("#", _LIST.sub("[#]", text))


def _short_ms(seconds: float) -> str:
    """A time as short as it goes: ``0.03`` -> ``30 ms``, ``0.0301234`` -> ``30.123 ms``."""
    return f"{round(seconds * 1000, 3):g} ms"


def cause_key(v: Violation) -> str:
    """A stable key of what was wrong, the same for every occurrence of one problem across tests, from the
    violation's fields (never its message): the leading rule id (the clauses a violation adds to it, e.g. R13 for a
    period kept across a silence, are the same problem), strength, node, check, what broke the rule and what the
    rule wanted (:class:`~.findings.Violation`'s ``subject`` and ``expected``)."""
    return f"{v.rules[0] if v.rules else ''}|{v.strength}|{v.node}|{v.check}|{v.subject}|{v.expected}"


def cause_what(v: Violation) -> str:
    """What was wrong in one line, from an occurrence: ``MSG1 of node 1 every 30 ms, not 20 ms`` (a report's
    interval), else ``node 1: <what broke it>; expected <what the rule wanted>``."""
    where = f"node {v.node}" if v.node is not None else "the bus"
    if v.check == "report-interval" and v.measured_s is not None and v.expected_s is not None:
        return f"{v.subject.upper()} of {where} every {_short_ms(v.measured_s)}, not {_short_ms(v.expected_s)}"
    return f"{where}: {v.subject}; expected {v.expected}"


def causes(found: list[Violation]) -> list[dict]:
    """The distinct problems among ``found`` (a test's violations, in order), each with its key, what was
    wrong (:func:`cause_what`), rules, strength, node, check, how many of ``found`` it is, and its first
    occurrence with its frames."""
    counts = Counter(cause_key(v) for v in found)
    out: dict[str, dict] = {}
    for v in found:
        key = cause_key(v)
        if key not in out:
            out[key] = {"key": key, "what": cause_what(v), "rules": list(v.rules), "strength": v.strength,
                        "node": v.node, "check": v.check, "count": counts[key], "first": str(v)}
        else:
            out[key]["rules"] = list(dict.fromkeys(out[key]["rules"] + list(v.rules)))
    return list(out.values())
