"""Spec section 4.2: CAN ESC working mechanism - PWM or CAN throttle first, with automatic fallback
(4.2), and the power-up self-test that Self Test (216) queries (4.2.1).

The communication status flag of 4.2's CAN throttle is section 4.4.4's (MSG1 bit 13)."""

from __future__ import annotations

import pytest

from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat

from .codes import code
from .throttle import STREAM_PERIOD_S, command_for

SECTION = "4.2"

SELF_TEST_STATUS = cat.spec("self_test").response.field("status")  # type: ignore[union-attr]
FAILED = code("self_test", "status", "failed", layout="response")
PWM_AND_CAN = code("throttle_select", "source", "PWM+CAN")
CAN_ONLY = code("throttle_select", "source", "CAN")
#: Test values, not protocol facts: two throttles that differ, within 0..2000 (4.4.23-5)
PWM_THROTTLE, CAN_THROTTLE = 600, 300
#: Test allowances: for the ESC's throttle to reach a new command, and for the motor to coast to a stop
SETTLE_S = 0.5
COAST_S = 5.0


def pwm_input(dut):
    """The control of the DUT's analog throttle input, if the lane has one: the emulator's bench in the
    simulated lane (``set_pwm_input(value, node)``; None = no signal). Real benches and the real-time
    lane have none yet."""
    bench = getattr(getattr(dut.lane, "sim", None), "bench", None)
    setter = getattr(bench, "set_pwm_input", None)
    if setter is None:
        raise Inconclusive(f"the {dut.lane.name} lane cannot drive the DUT's PWM input (only the simulated lane can)")
    return lambda value: setter(value, dut.node_id)


def last_msg1(dut, seconds: float):
    frames = dut.reports("msg1", seconds)
    if not frames:  # what MSG1 looks like is section 4.4.4's verdict; here it is only the probe
        raise Inconclusive(f"no decodable MSG1 from node {dut.node_id} in {seconds} s: the throttle in use cannot be read")
    return frames[-1]


def stop_motor(dut) -> bool:
    """Zero throttle and wait for MSG1 speed 0: Throttle Select needs the motor stopped (4.4.23-3)."""
    dut.stop_throttle()
    dut.zero_throttle()
    return dut.wait_for("msg1", COAST_S, where=lambda f: f.fields["speed"] == 0) is not None


def select(dut, source: int) -> None:
    dut.ask("throttle_select", {"source": source})
    if dut.settings()["throttle_source"] != source:
        raise Inconclusive(f"Throttle Select {source} did not take (242): the throttle source cannot be set (4.4.23's verdict)")


@pytest.mark.requirement("4.2-1")
@pytest.mark.spins_motor
def test_pwm_throttle_first_and_can_takes_over_when_pwm_is_lost(dut):
    """With PWM+CAN selected (Throttle Select 1) and both inputs alive, the ESC follows the PWM throttle;
    when the PWM signal is lost while the CAN throttle is normal, it switches to the CAN throttle by
    itself. Which throttle the ESC uses is read from MSG1's throttle output, compared with what it
    shows for the same CAN command under CAN throttle alone (so a CAN decoding fault is not judged here)."""
    set_pwm = pwm_input(dut)
    s = dut.settings()
    fields = command_for("raw_command_12b", s["throttle_channel"], CAN_THROTTLE)
    if fields is None:
        raise Inconclusive(f"throttle channel {s['throttle_channel']} is in no RawCommand_12b group")
    try:
        select(dut, CAN_ONLY)
        dut.throttle_stream("raw_command_12b", fields, STREAM_PERIOD_S)
        can_alone = last_msg1(dut, SETTLE_S).fields["pwm"]
        if not stop_motor(dut):
            raise Inconclusive(f"the motor did not stop within {COAST_S} s of zero throttle")
        dut.record.observe("MSG1 throttle output, CAN throttle alone", can_alone)
        if can_alone in (0, PWM_THROTTLE):
            raise Inconclusive(f"under CAN throttle {CAN_THROTTLE}, MSG1's throttle output is {can_alone}: it cannot tell the inputs apart")
        select(dut, PWM_AND_CAN)
        set_pwm(PWM_THROTTLE)
        dut.throttle_stream("raw_command_12b", fields, STREAM_PERIOD_S)
        both = last_msg1(dut, SETTLE_S).fields["pwm"]
        set_pwm(None)  # the PWM signal is lost; the CAN stream goes on
        can = last_msg1(dut, SETTLE_S).fields["pwm"]
        dut.record.observe("MSG1 throttle output, PWM+CAN", {"PWM and CAN in": both, "PWM lost": can})
        assert both == PWM_THROTTLE, f"PWM {PWM_THROTTLE} and CAN {CAN_THROTTLE} in, PWM first: MSG1 throttle output {both}"
        assert can == can_alone, (f"PWM lost, CAN {CAN_THROTTLE} in: MSG1 throttle output {can}, not the CAN throttle's "
                                  f"{can_alone}: the CAN throttle did not take over")
    finally:
        set_pwm(None)
        if stop_motor(dut):  # else the fixture's restore reports the DUT as not restored
            dut.request("throttle_select", {"source": s["throttle_source"]})  # at zero throttle (4.4.23-3)


@pytest.mark.requirement("4.2.1-1")
def test_self_test_status_can_be_queried(dut):
    """The power-up self-test status can be queried with Self Test: it answers passed (0) or failed (1)."""
    ex = dut.request("self_test", {})
    assert ex.response is not None, f"no answer to Self Test from node {dut.node_id}"
    status = ex.response.fields["status"]
    dut.record.observe("self-test status", (SELF_TEST_STATUS.codes or {}).get(status, status))
    assert SELF_TEST_STATUS.is_legal(status), f"Self Test status {status}: the document defines {dict(SELF_TEST_STATUS.codes or {})}"


@pytest.mark.requirement("4.2.1-1")
@pytest.mark.power_cycle
def test_self_test_runs_at_power_up(dut):
    """Right after a (proven) power-up, Self Test answers, and what it answers is the power-up
    self-test's result: failed exactly when 241 option 2's power-on self-test fault code is not 0."""
    dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
    ex = dut.request("self_test", {})
    assert ex.response is not None, f"no answer to Self Test after power-up (node {dut.node_id})"
    status = ex.response.fields["status"]
    fault = dut.ask("maintenance_information", {"option": 2})["fault_code"]
    dut.record.observe("after power-up", {"self-test status": status, "241 fault code": fault})
    assert SELF_TEST_STATUS.is_legal(status), f"Self Test status {status} is neither passed nor failed"
    assert (status == FAILED) == (fault != 0), (
        f"Self Test says {(SELF_TEST_STATUS.codes or {}).get(status)}, 241 option 2's power-on self-test fault code is {fault:#06x}")
