"""Spec section 4.4.11: MSG_EXP9 (20061) - accumulated running time and fault code 1, in MSG_EXP mode."""

from __future__ import annotations

import pytest

from ckesc.protocol import catalogue as cat

from .answers import reference
from .motor import RUN_S, SECOND, run_motor
from .telemetry import exp_reports

SECTION = "4.4.11"


@pytest.mark.requirement("4.4.11-T")
@pytest.mark.spins_motor
def test_exp9_agrees_with_maintenance_information(dut):
    """Time (seconds) is 241 option 0's accumulated running time; Test (fault code 1) is 241 option 2's
    power-on self-test fault code. The motor runs first, when allowed, so that the time is not zero; a
    counter that also runs at rest may have moved on by the time between the frame and the 241 read."""
    run_motor(dut, RUN_S)

    def log(d):
        return (reference(d, "maintenance_information", {"option": 0}, need=("total_run_time",))["total_run_time"],
                reference(d, "maintenance_information", {"option": 2}, need=("fault_code",))["fault_code"], d.now())

    frames, (total, fault, read_at) = exp_reports(dut, "msg_exp9", during=log)
    f = frames[-1]
    dut.record.observe("MSG_EXP9", f.physical())
    dut.record.observe("241", {"total_run_time": total, "fault_code": fault})
    dut.record.measure("MSG_EXP9 running time vs 241 option 0", abs(f.fields["total_run_time"] - total),
                       limit=round(SECOND + read_at - f.timestamp, 6), unit="s", clock=dut.clock, requirement="4.4.11-T")
    codes = sorted({x.fields["fault_code_1"] for x in frames})
    dut.record.observe("fault code 1", [cat.FAULT_CODES_1.get(c, f"0x{c:04X}: not in the attachment's list") for c in codes])
    assert codes == [fault], f"MSG_EXP9 fault code 1 {codes}, 241 option 2 says {fault}"
