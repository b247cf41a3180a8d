"""Spec section 4.4.24: Self Test (216) - the query of the power-up self-test's status.

The answer is judged against the other places the ESC reports that self-test: 241 option 2's
power-on self-test fault code (4.4.27), MSG_EXP9's fault code 1 (4.4.11) and MSG1's self-test error
bits 7..0 (4.4.4, R7). A suite cannot make a real DUT fail its power-up self-test over the bus; where
the bench can (the emulator's, in the simulated lane), a failed self-test is provoked and must be
answered "failed"."""

from __future__ import annotations

import pytest

from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat

from .codes import code
from .telemetry import exp_capture

SECTION = "4.4.24"

STATUS = cat.spec("self_test").response.field("status")  # type: ignore[union-attr]
FAILED = code("self_test", "status", "failed", layout="response")


def _label(status: int) -> str:
    return (STATUS.codes or {}).get(status, f"undefined ({status})")


@pytest.mark.requirement("4.4.24-1")
def test_self_test_answers_passed_or_failed(dut):
    """Self Test (an empty request) is answered with one status byte: 0 passed, 1 failed; asked twice,
    it answers the same (the power-up self-test ran once)."""
    answers = [dut.request("self_test", {}) for _ in range(2)]
    assert all(ex.response is not None for ex in answers), f"no answer to Self Test from node {dut.node_id}"
    statuses = [ex.response.fields["status"] for ex in answers]  # type: ignore[union-attr]
    dut.record.observe("self-test status", _label(statuses[0]))
    assert STATUS.is_legal(statuses[0]), f"Self Test status {statuses[0]}: the document defines {dict(STATUS.codes or {})}"
    assert statuses[0] == statuses[1], f"Self Test answered {statuses[0]}, then {statuses[1]}"


@pytest.mark.requirement("4.4.24-1")
def test_self_test_agrees_with_the_reported_fault_codes(dut):
    """Self Test says failed exactly when 241 option 2's power-on self-test fault code is not 0 ("0
    after normal power-on") and when MSG_EXP9's fault code 1 is not 0 ("0 = power-up self-test
    normal"); a MSG1 self-test error bit (bits 7..0) means failed too. (A failed self-test need not light
    a MSG1 bit: the document maps no fault code to a bit.)"""
    ex = dut.request("self_test", {})
    assert ex.response is not None, f"no answer to Self Test from node {dut.node_id}"
    status = ex.response.fields["status"]
    failed = status == FAILED
    m = dut.request("maintenance_information", {"option": 2})
    fault = m.response.fields.get("fault_code") if m.response is not None else None
    msg1 = dut.reports("msg1", 3 * dut.settings()["msg1_interval"] * cat.INTERVAL_UNIT_S)
    bits = sorted({f.fields["status"] & cat.SELFTEST_ERROR_MASK for f in msg1})
    frames, _, _, _ = exp_capture(dut, if_claimed=True)
    exp9 = sorted({f.fields["fault_code_1"] for f in frames if f.name == "msg_exp9"})
    dut.record.observe("self-test reports", {
        "Self Test": _label(status), "241 fault code": "no answer" if fault is None else f"{fault:#06x}",
        "MSG1 bits 7..0": [f"{b:#04x}" for b in bits], "MSG_EXP9 fault code 1": [f"{c:#06x}" for c in exp9] or "no MSG_EXP9 (R9-exp)"})
    assert STATUS.is_legal(status), f"Self Test status {status} is neither passed nor failed"
    if fault is None and not exp9 and not msg1:
        raise Inconclusive("no other report of the power-up self-test to compare Self Test with (241, MSG_EXP9, MSG1)")
    problems = []
    if fault is not None and failed != (fault != 0):
        problems.append(f"241 option 2 reports power-on self-test fault code {fault:#06x}")
    if exp9 and any(failed != (c != 0) for c in exp9):
        problems.append(f"MSG_EXP9 reports fault code 1 {[f'{c:#06x}' for c in exp9]}")
    if not failed and any(bits):
        problems.append(f"MSG1 reports self-test error bits {[f'{b:#04x}' for b in bits if b]}")
    assert not problems, f"Self Test says {_label(status)}, but " + "; ".join(problems)


def self_test_bench(dut):
    """The bench's control of what the DUT's next power-up self-test finds (fault code 1, 0: passed),
    if the lane has one: the emulator's bench in the simulated lane. Real benches have none yet."""
    bench = getattr(getattr(dut.lane, "sim", None), "bench", None)
    setter = getattr(bench, "set_self_test_fault", None)
    if setter is None:
        raise Inconclusive(f"the {dut.lane.name} lane cannot make the DUT's power-up self-test fail (only the simulated lane's bench can)")
    return lambda fault_code: setter(fault_code, dut.node_id)


#: a fault code 1 the attachment defines (the first that is not "normal")
FAILING_CODE = next(c for c in cat.FAULT_CODES_1 if c)


@pytest.mark.requirement("4.4.24-1", "4.2.1-1")
@pytest.mark.power_cycle
def test_failed_power_up_self_test_is_answered_failed(dut):
    """After a power-up whose self-test found a fault, Self Test answers failed (1). (Whether 241 and
    MSG_EXP9 name that fault is their sections' verdict.)"""
    set_fault = self_test_bench(dut)
    try:
        set_fault(FAILING_CODE)
        dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
        ex = dut.request("self_test", {})
        assert ex.response is not None, f"no answer to Self Test from node {dut.node_id}"
        status = ex.response.fields["status"]
        dut.record.observe("self-test status after a failed power-up self-test", _label(status))
        assert status == FAILED, (f"Self Test answers {_label(status)} after a power-up self-test that found fault "
                                  f"{FAILING_CODE:#04x} ({cat.FAULT_CODES_1[FAILING_CODE]})")
    finally:
        set_fault(0)
        dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
