"""The report's plots and the bus rules read one trace through one tracker (evidence/tracker.py): the
intervals a plot draws are the ones the rules judged, against the same target, and the answer delays
are those of the answers the rules matched with their requests."""

from __future__ import annotations

import pytest

from ckesc.evidence import BusRules
from ckesc.evidence.timing import evidence
from ckesc.evidence.tracker import TimingEvidence
from ckesc.protocol.frame import decode, encode

from .test_rules import BITRATE, INTERVALS, READ, feed, msg1


def _trace():
    """The host reads node 1's intervals (20 ms for MSG1), node 1 answers 3 ms later and reports MSG1 at 20, 20
    and 30 ms; then MSG Control suspends and resumes reporting (the cadence restarts) and it reports again."""
    frames = [(encode("set_freq", READ, source=0, destination=1, transfer_id=4), 0.000),
              (encode("set_freq", {"option": 0, **INTERVALS}, kind="response", source=1, destination=0, transfer_id=4),
               0.003)]
    frames += [(msg1(1, n), t) for n, t in enumerate((0.010, 0.030, 0.050, 0.080))]
    frames += [(encode("msg_control", {"command": c}, source=0, transfer_id=n), t)
               for n, (c, t) in enumerate(((0xBBBBBBBB, 0.085), (0xAAAAAAAA, 0.300)))]
    frames += [(msg1(1, n), t) for n, t in enumerate((0.301, 0.321, 0.341, 0.361), start=4)]
    return frames


def test_the_plot_draws_what_the_rules_judged():
    rules = BusRules(bitrate=BITRATE, complete=True)
    rules.heard = TimingEvidence(node=1)
    found = [v for wire, t in _trace() for v in feed(rules, wire, t)]
    # the rules: one MSG1 30 ms after the previous one, expected 20 ms
    assert [v.check for v in found] == ["report-interval"] and "30.000 ms after" in found[0].message
    # the plot: the intervals judged against the 20 ms the node stated, the 30 ms one among them; none across
    # the suspension, nor the gap up to the second report after the resume (R9a-gaps: not judged)
    gaps = rules.heard.intervals["msg1"]["0.02"]
    assert gaps == [pytest.approx(g) for g in (0.020, 0.020, 0.030, 0.020, 0.020)]
    assert rules.heard.answers == {"1": {"set_freq": [pytest.approx(0.003)]}}


def test_a_tests_evidence_is_the_trackers_over_its_decoded_frames():
    """``evidence`` (what results.json keeps per test) runs the same tracker over ``Dut.trace``'s frames."""
    trace = []
    for wire, t in _trace():
        f = decode(wire)
        f.timestamp = t
        trace.append(f)
    ev = evidence(trace, host=0, node=1)
    rules = BusRules(bitrate=BITRATE, complete=True)
    rules.heard = TimingEvidence(node=1)
    for wire, t in _trace():
        feed(rules, wire, t)
    assert ev == rules.heard.to_json()
    assert ev["intervals"]["msg1"]["0.02"][2] == pytest.approx(0.030)
