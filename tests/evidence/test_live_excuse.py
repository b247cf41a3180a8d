"""A test may excuse rules of the live bus rules for a while (LaneRules.excuse: R18 makes report timing OBSERVE
above half load): what breaks them then fails no test, and is handed back to be recorded."""

from ckesc.bench.dut import Dut
from ckesc.bench.profile import DutProfile
from ckesc.bench.sim_lane import SimLane
from ckesc.evidence.live import LaneRules


def _lane_with_rules(faults):
    lane = SimLane(nodes=(1,), faults=faults)
    rules = LaneRules(lane)
    lane.listeners.append(rules)
    dut = Dut(lane, DutProfile.load("emulator"), node_id=1)
    dut.wait(0.4)
    dut.settings()  # the rules learn MSG1's interval from the Set/Get Freq read
    return lane, rules, dut


def test_an_excused_rule_fails_nothing_while_excused_and_is_handed_back():
    lane, rules, dut = _lane_with_rules(["report_interval_wrong"])  # MSG1 every 30 ms, not 20
    try:
        rules.take()
        dut.wait(0.2)
        found, count = rules.take()
        assert count and found[0].rules[0] == "R9"
        assert rules.excuse(frozenset({"R9"})) == []
        dut.wait(0.2)
        assert rules.take() == ([], 0)
        excused = rules.excuse(frozenset())
        assert excused and all(v.rules[0] == "R9" for v in excused)
        dut.wait(0.2)
        assert rules.take()[1]  # judged again
    finally:
        lane.close()
