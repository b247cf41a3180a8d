"""The results of a run as the reports read them: one :class:`Result` per test, the run's info."""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ..protocol.requirements import Verdict

#: how a requirement's result is drawn from its tests' verdicts: the first that occurs
WORST_FIRST = (Verdict.FAIL, Verdict.ERROR, Verdict.INCONCLUSIVE, Verdict.PASS, Verdict.OBSERVED, Verdict.SKIPPED)
#: a requirement no test of the run checked
NOT_CHECKED = "NOT CHECKED"


def requirement_result(outcomes: Iterable[str]) -> str:
    """A requirement's (or a section's) result from its tests' verdicts: the worst (:data:`WORST_FIRST`), or
    :data:`NOT_CHECKED` when there are none."""
    outcomes = set(outcomes)
    return next((v for v in WORST_FIRST if v in outcomes), NOT_CHECKED)


def measurements(properties: Mapping[str, str]) -> list[dict[str, str]]:
    """A test's measurements (name, value, limit, margin, clock, error, verdict), in order, from its
    ``measurement.<n>.<key>`` properties."""
    found: dict[int, dict[str, str]] = defaultdict(dict)
    for key, value in properties.items():
        parts = key.split(".")
        if len(parts) == 3 and parts[0] == "measurement" and parts[1].isdigit():
            found[int(parts[1])][parts[2]] = value
    return [found[i] for i in sorted(found)]


@dataclass
class Result:
    """One test's result, as results.json, JUnit and the HTML report write it."""

    nodeid: str
    name: str
    section: str
    requirements: list[str]
    strength: str
    outcome: str = "PASS"  # PASS FAIL INCONCLUSIVE OBSERVED SKIPPED ERROR
    message: str = ""
    duration: float = 0.0
    lane_seconds: float = 0.0  # lane time the test took: in the simulated lane, the waits the protocol imposes
    properties: dict[str, str] = field(default_factory=dict)
    observations: list[tuple[str, str]] = field(default_factory=list)
    #: the test's CAN traces by lane ("": the DUT's, "bench": multi_dut's private bench), relative to the
    #: run's report directory; a lane that heard no frame during the test has none
    traces: dict[str, str] = field(default_factory=dict)
    #: what the test's traffic shows, for the HTML report's plots (answer delays, report intervals, R8
    #: timeline): see evidence.timing
    evidence: dict[str, Any] = field(default_factory=dict)
    #: requirement ids of the bus rules (ckesc/evidence) the traffic broke while the test ran: such a test
    #: FAILs, quoting the frames, and these ids are what it cites besides its own
    bus_rules: list[str] = field(default_factory=list)
    #: the distinct problems among those violations (evidence.live.causes: a stable key per problem, its
    #: title, rules, node, how often among the quoted ones, its first occurrence): report.html, summary.txt
    #: and the console group the run's failures by them
    bus_causes: list[dict[str, Any]] = field(default_factory=list)



def incomplete_banner(info: dict[str, Any]) -> str:
    """One line saying why a run is less than the whole suite ("" for a complete one)."""
    why = info.get("incomplete") or ""
    if not why:
        return ""
    kind = why.split(":")[0].split(" ")[0].upper()
    kind = {"STOPPED": "INCOMPLETE"}.get(kind, kind)
    return f"{kind} - not a conformance result for the whole suite: {why}; {info.get('not_run', 0)} tests not run"


def claim_text(info: dict[str, Any]) -> str:
    """What the conformance claim leaves out (R9b: functions the DUT profile declares absent)."""
    left_out = info.get("not_claimed") or ""
    if not left_out:
        return "claim: every function of the document (the DUT profile declares none absent, R9b)"
    return f"claim: leaves out (declared absent by the DUT profile, R9b; their tests SKIPPED): {left_out}"
