"""Robustness (R17): a flight controller's and a battery's traffic on the ESC's bus is ignored.

With ``--foreign-traffic ardupilot`` (docs/robustness.md) the run plays, for its whole length, what a flight
controller (node 10) and a smart battery (node 40) send, encoded by the ``dronecan`` package: SafetyState on CAN
Test's id (20000, a frame shorter than its table), BatteryCells on MSG Control's id (20010, a multi-frame transfer),
NodeStatus, DroneCAN's own ESC command (zero throttle) and a GET_ESC_ID query once a second. Every other section is
judged with it playing; this one looks at the traffic itself for a while: the ESC never resets (no MSG1 gap after
which its transfer ids count anew, 241's power-up count unmoved), its settings do not change, and it sends
nothing but its reports and its replies to the flight controller's GET_ESC_ID queries (a legitimate query, F6).

On a quiet bus (no ``--foreign-traffic``) the test plays the same traffic itself for its watch and stops it after,
so every run looks at it. The rest of the robustness section (``test_robustness_r17_malformed``) sends its
malformed frames itself, on any bus.
"""

from __future__ import annotations

import pytest

from ckesc.bench.station import ForeignPlay
from ckesc.protocol import catalogue as cat
from ckesc.protocol.ids import Kind

from .answers import answers_another_node
from .resets import afterwards, reset_signs
from .telemetry import interval_s, ms

SECTION = "robustness"
#: what the test plays itself on a quiet bus
OWN_TRAFFIC = "ardupilot"
#: How long the test looks at the traffic: a few of each of its streams (the slowest once a second)
WATCH_S = 3.0


@pytest.mark.requirement("R17")
def test_foreign_traffic_is_ignored(dut):
    """While the flight controller's and the battery's frames play: no reset, no setting changed, nothing sent
    but the reports and the replies to the flight controller's GET_ESC_ID queries."""
    played = dut.lane.foreign_traffic
    if played is not None:
        _watch(dut, played)
        return
    own = ForeignPlay(OWN_TRAFFIC, dut.lane)  # a quiet bus: this test's own, for its watch only
    try:
        _watch(dut, own)
    finally:
        own.stop()
        dut.lane.foreign_traffic = None


def _watch(dut, played: ForeignPlay) -> None:
    nodes = sorted({s["node"] for s in played.traffic.describe()})
    s = dut.settings()
    ups = dut.power_up_count()
    interval = interval_s(s, "msg1")
    t0 = dut.now()
    heard = len(dut.trace)
    dut.wait(WATCH_S)
    t1 = dut.now()
    problems = []
    msg1 = dut.frames("msg1", since=t0, until=t1, source=dut.node_id)
    problems += reset_signs(dut, msg1, interval)  # a gap with the transfer ids starting again (R17, R19)
    if len(msg1) < WATCH_S / interval / 2:
        problems.append(f"{len(msg1)} MSG1 reports in {WATCH_S:g} s at a {ms(interval)} ms interval")
    sent = sorted({f"{f.name} {f.kind.label}" for f in dut.trace[heard:] if f.source == dut.node_id
                   and f.name not in cat.REPORT_FRAMES and not answers_another_node(dut, f)})
    if sent:
        problems.append(f"the ESC sent {', '.join(sent)}")
    problems += afterwards(dut, s, ups, interval)
    replies = [f for f in dut.trace[heard:] if f.source == dut.node_id and f.name == "get_esc_id" and f.kind is Kind.MESSAGE]
    dut.record.observe("foreign traffic watched", f"{played.name} from nodes {nodes} for {WATCH_S:g} s; GET_ESC_ID "
                       f"replies to the flight controller's queries: {len(replies)}")
    assert not problems, (f"with {played.name}'s traffic playing (nodes {', '.join(map(str, nodes))}: SafetyState on "
                          "20000, BatteryCells on 20010, NodeStatus, a zero DroneCAN ESC command, GET_ESC_ID): "
                          + "; ".join(problems) + " (R17: foreign frames get no answer, change nothing and never "
                          "reset the ESC)")
