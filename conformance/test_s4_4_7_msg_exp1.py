"""Spec section 4.4.7: MSG_EXP1 (20053) - speed, voltage and current, in MSG_EXP mode."""

from __future__ import annotations

import pytest

from ckesc.bench.outcomes import Inconclusive

from .physics import CELL_FULL_V, MIN_SUPPLY_V, check_voltage_current, esc_limits
from .telemetry import exp_reports, interval_s

SECTION = "4.4.7"

#: Test allowance: two readings of one supply voltage a second apart agree within 5 %
SAME_VOLTAGE = 0.05


@pytest.mark.requirement("4.4.7-T")
def test_exp1_layout_and_values(dut):
    """Every MSG_EXP1 decodes (6 payload bytes); voltage and current are in MSG2's units (0.01 V /
    0.01 A): in range for the ESC and the voltage agreeing with MSG2's; speed 0 while MSG1 says 0."""
    cells, amps = esc_limits(dut)
    s = dut.settings()
    t = dut.now()
    msg2 = dut.reports("msg2", 2 * max(interval_s(s, "msg2"), interval_s(s, "msg1")))
    msg1 = dut.frames("msg1", since=t, source=dut.node_id)
    if not (msg2 and msg1):
        raise Inconclusive("no decodable MSG1/MSG2 to compare MSG_EXP1 with")
    frames, _ = exp_reports(dut, "msg_exp1")
    dut.record.observe("MSG_EXP1", frames[-1].physical())
    check_voltage_current(dut, frames, cells, amps, "MSG_EXP1", "4.4.7-T")
    ref = sorted(f.physical()["voltage"] for f in msg2)[len(msg2) // 2]
    if not MIN_SUPPLY_V <= ref <= cells * CELL_FULL_V:
        raise Inconclusive(f"MSG2's voltage {ref} V is itself implausible (its own test fails): no reference")
    worst = max(abs(f.physical()["voltage"] - ref) for f in frames)
    dut.record.measure("MSG_EXP1 voltage vs MSG2 voltage", round(worst, 6), limit=round(SAME_VOLTAGE * ref, 6), unit="V",
                       clock=dut.clock, requirement="4.4.7-T")
    if all(f.fields["speed"] == 0 for f in msg1):
        moving = [f.fields["speed"] for f in frames if f.fields["speed"]]
        assert not moving, f"MSG_EXP1 speed {moving} rpm while MSG1 reported 0 rpm at zero throttle"
