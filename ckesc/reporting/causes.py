"""A run's failures grouped by cause: the k distinct problems of a run, never k copies of one.

One broken bus rule fails every test during which it shows (ckesc/evidence/live.py): 303 tests with
one violation. A group is one problem - a bus rule's violation by its stable key (leading rule id,
node, check, what was wrong: ``evidence.live.cause_key``, recorded per test in ``bus_causes``), or a
test's own failure by its message's first line with the measured values made ``#`` (the key only: the group's
heading is that line as its first test wrote it, never edited) - with every test it showed in and its first
occurrence (message, frames, traces). Groups of FAIL come before ERROR (the
suite's problems), SHALL before READING, then the most widespread first.

A bus rule broken while a test ran whose own verdict is not a FAIL (a test SKIPPED "not claimed", R9b,
or ERRORed) is the rule's failure, not that test's: it is grouped here like any other, the test named
as where it was seen (:func:`rule_failures`), and it fails the run.

Built from ``results.json``'s records (or the plugin's results), so ``ckesc report DIR`` rebuilds it: from their
fields (``broken``, ``bus_causes``), never from their messages' words. A record from before ``bus_causes`` were
recorded is grouped by its message's first line, as a test's own failure.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..evidence.live import generalise, without_context
from ..protocol.requirements import STRENGTHS as STRENGTH_ORDER
from ..protocol.requirements import Verdict
from .results import Result

#: the longest heading: a longer first line is cut, and says so ("...")
_HEADING = 300
_OUTCOMES = (Verdict.FAIL, Verdict.ERROR)


@dataclass
class Group:
    key: str
    outcome: str  # FAIL (the DUT's) or ERROR (the suite's)
    strength: str  # SHALL / READING ("" for an ERROR)
    rules: list[str]
    what: str  # what was wrong, from the first occurrence
    first: str  # the first occurrence: the failure message, or the violation with its frames
    first_test: str
    traces: dict[str, str] = field(default_factory=dict)
    tests: list[str] = field(default_factory=list)
    occurrences: int = 0
    #: tests in ``tests`` whose own verdict is not this FAIL (SKIPPED, ERROR): a bus rule seen while they ran
    unjudged: dict[str, str] = field(default_factory=dict)

    @property
    def title(self) -> str:
        return f"{' '.join(self.rules)}: {self.what}" if self.rules else self.what

    @property
    def headline(self) -> str:
        n = len(self.tests)
        return f"{self.title} - in {n} test{'s' if n != 1 else ''}"


def _record(r: Result | dict[str, Any]) -> Result:
    return r if isinstance(r, Result) else Result.from_json(r)


def broken_outside_a_fail(r: Any) -> bool:
    """Whether the bus broke a rule while test record ``r`` ran and the test's own verdict is not that FAIL
    (it was SKIPPED: not claimed, R9b, or lacking a capability; or it ERRORed). Such a rule's failure is
    not the test's, and it still fails the run."""
    r = _record(r)
    return bool(r.bus_rules) and r.outcome != Verdict.FAIL


def rule_failures(results: list) -> list[dict[str, Any]]:
    """The bus rules broken outside a FAIL (:func:`broken_outside_a_fail`), one entry per test they were
    seen in: results.json's ``rule_failures``, JUnit's "bus rules" testsuite."""
    return [{"test": r.nodeid, "outcome": r.outcome, "rules": list(r.bus_rules),
             "causes": list(r.bus_causes)} for r in map(_record, results) if broken_outside_a_fail(r)]


def _own_cause(r: Result) -> tuple[str, str, str, list[str]] | None:
    """(key, what, strength, rules) of a test's own failure (not the bus rules'), or None. The key groups (its
    context and the values that vary made ``#``); ``what``, the heading, is what the DUT did as the test wrote it
    (the strongest of what it broke, :attr:`~.results.Result.broken`; its requirements and strength shown beside
    it), or for an ERROR, or a FAIL that recorded nothing broken (an exception in the test), its message's first line:
    ``127.0.0.1:40594`` and ``failed (3)`` stay as they are."""
    if r.broken:
        head = r.broken[0]
        text, strength, rules = head["text"].strip().split("\n", 1)[0], head["strength"], list(head["requirements"])
    elif (r.outcome == Verdict.FAIL and r.bus_causes) or not (r.message or "").strip():
        return None  # the bus rules' failure: grouped by its causes
    else:
        text = r.message.strip().split("\n", 1)[0].strip().removeprefix("AssertionError: ")
        strength, rules = ("" if r.outcome == Verdict.ERROR else r.strength), []
    key = f"{r.outcome}|{' '.join(rules)}|{strength}|{generalise(without_context(text)).strip()}"
    what = text if len(text) <= _HEADING else text[:_HEADING - 3] + "..."
    return key, what, strength, rules


def groups(results: list) -> list[Group]:
    """The run's FAILs and ERRORs, and the bus rules broken while any test ran, grouped by cause, the first to
    read first."""
    found: dict[str, Group] = {}
    for r in map(_record, results):
        failed = r.outcome in _OUTCOMES
        if not failed and not r.bus_rules:
            continue
        traces = r.traces or {}
        own = _own_cause(r) if failed else None
        if own is not None:
            key, what, strength, rules = own
            g = found.setdefault(key, Group(key, r.outcome, strength, rules, what, r.message,
                                            r.nodeid, traces))
            g.tests.append(r.nodeid)
            g.occurrences += 1
        for c in r.bus_causes:
            key = "bus|" + c["key"]
            g = found.setdefault(key, Group(key, Verdict.FAIL, c["strength"], list(c["rules"]), c["what"], c["first"],
                                            r.nodeid, traces))
            g.rules = list(dict.fromkeys(g.rules + list(c["rules"])))
            if r.nodeid not in g.tests:
                g.tests.append(r.nodeid)
                if r.outcome != Verdict.FAIL:
                    g.unjudged[r.nodeid] = r.outcome
            g.occurrences += c.get("count", 1)
    order = list(found)
    return sorted(found.values(), key=lambda g: (_OUTCOMES.index(g.outcome),
                                                 STRENGTH_ORDER.index(g.strength) if g.strength in STRENGTH_ORDER else 9,
                                                 -len(g.tests), order.index(g.key)))


def summary_lines(results: list, *, shown: int = 20, names: int = 3) -> list[str]:
    """The grouped failures for summary.txt and the console: one block per cause."""
    gs = groups(results)
    if not gs:
        return []
    tests = {t for g in gs for t in g.tests}
    lines = [f"failures by cause: {len(gs)} distinct, in {len(tests)} tests (SHALL first; the tests of each below it)"]
    for n, g in enumerate(gs[:shown], start=1):
        lines.append(f"{n:>3}. [{g.outcome} {g.strength}]".replace(" ]", "]") + f" {g.headline}")
        trace = next(iter(g.traces.values()), None)
        lines.append(f"       first: {g.first_test}" + (f" (trace {trace})" if trace else ""))
        more = len(g.tests) - names
        lines.append("       tests: " + ", ".join(t.split("::", 1)[-1] + (f" ({g.unjudged[t]}: seen while it ran)"
                                                                          if t in g.unjudged else "")
                                                 for t in g.tests[:names])
                     + (f" ... and {more} more" if more > 0 else ""))
    if len(gs) > shown:
        lines.append(f"  ... {len(gs) - shown} more causes: see report.html")
    return lines
