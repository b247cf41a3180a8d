"""Spec section 4.4.12: MSG_EXP10 (20062) - this run's time and fault code 2, in MSG_EXP mode."""

from __future__ import annotations

import pytest

from ckesc.protocol import catalogue as cat

from .answers import reference
from .motor import RUN_S, SECOND, run_motor
from .telemetry import exp_reports

SECTION = "4.4.12"

SELF_TEST = cat.spec("self_test").response.field("status").codes


@pytest.mark.requirement("4.4.12-T")
@pytest.mark.spins_motor
def test_exp10_agrees_with_maintenance_information(dut):
    """Time (seconds) is 241 option 1's current running time; fault code 2 is 0 after a normal power-up
    (Self Test passed). The motor runs first, when allowed, so that the time is not zero; a counter
    that also runs at rest may have moved on by the time between the frame and the 241 read."""
    run_motor(dut, RUN_S)

    def log(d):
        return (reference(d, "maintenance_information", {"option": 1}, need=("run_time",))["run_time"],
                d.request("self_test"), d.now())

    frames, (run, self_test, read_at) = exp_reports(dut, "msg_exp10", during=log)
    passed = self_test.response is not None and SELF_TEST.get(self_test.response.fields["status"]) == "passed"
    f = frames[-1]
    dut.record.observe("MSG_EXP10", f.physical())
    dut.record.observe("241 option 1 running time", run)
    dut.record.measure("MSG_EXP10 running time vs 241 option 1", abs(f.fields["run_time"] - run),
                       limit=round(SECOND + read_at - f.timestamp, 6), unit="s", clock=dut.clock, requirement="4.4.12-T")
    codes = sorted({x.fields["fault_code_2"] for x in frames})
    dut.record.observe("fault code 2", codes)
    dut.record.observe("Self Test (216)", self_test.response.fields if self_test.response else "no answer")
    if passed:
        assert codes == [0], f"MSG_EXP10 fault code 2 {codes} while Self Test (216) passed (0 = power-up self-test normal)"
