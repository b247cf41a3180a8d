"""Running the motor so that its running-time counters move (MSG_EXP9/10, 241): :func:`run_motor`
(not a section: no tests here).
"""

from __future__ import annotations

from ckesc.bench.outcomes import Inconclusive

from .telemetry import need_decoded
from .throttle import STREAM_PERIOD_S, can_throttle, command_for

#: Throttle for run_motor: a gentle spin, enough to count running time
RUN_THROTTLE = 500
#: Test allowance for a motor to coast to a stop
COAST_S = 5.0
#: How long the MSG_EXP9 / MSG_EXP10 tests run the motor (4.4.11, 4.4.12)
RUN_S = 2.0
#: Two readings of a whole-seconds counter taken apart differ by the truncation: one second
SECOND = 1


def run_motor(dut, seconds: float) -> bool:
    """Spin the motor for ``seconds`` and wait until it has stopped (MSG1 speed 0), so that the
    running-time counters move (MSG_EXP9/10, 241). Only with --allow-motor-spin and a motor; returns
    whether it ran."""
    if not (dut.allow_motor_spin and dut.profile.has("motor")):
        dut.record.observe("motor", "not run (needs --allow-motor-spin and capability motor)")
        return False
    s = can_throttle(dut)
    dut.throttle_stream("raw_command_12b", command_for("raw_command_12b", s["throttle_channel"], RUN_THROTTLE), STREAM_PERIOD_S)
    dut.wait(seconds)
    dut.stop_throttle()
    dut.throttle_stream("raw_command_12b", command_for("raw_command_12b", s["throttle_channel"], 0), STREAM_PERIOD_S)
    t = dut.now()
    stopped = dut.wait_for("msg1", COAST_S, where=lambda f: f.fields["speed"] == 0)
    dut.stop_throttle()
    if stopped is None:
        need_decoded(dut, "msg1", [], t, "the motor speed")
        raise Inconclusive(f"the motor did not stop within {COAST_S} s of zero throttle")
    dut.record.observe("motor", f"run {seconds} s at throttle {RUN_THROTTLE}, stopped")
    return True
