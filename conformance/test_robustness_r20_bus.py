"""Robustness (R20): the ESC after its CAN bus was disturbed and freed.

The test shorts the bus (CANH to CANL: every bit dominant) long enough that the ESC, which goes on reporting, meets
32 bit errors and goes bus-off, then frees it. The ESC's controller must recover by itself (128 x 11 recessive bits)
and its reports go on within R20's bound, without a reset and with its settings unchanged; the commands it lost
meanwhile raise its comm flag (R8), and the next command clears it.

The fault is the bench's (:mod:`ckesc.bench.bus_fault`): in the simulated lane its world shorts the bus (the CAN
model's acknowledgement and error confinement on for the fault and its recovery only); on a real bench
``--bus-fault-cmd`` closes a relay across CANH-CANL (docs/robustness.md). A lane without one SKIPs these tests.

Section ``robustness``, not one of its own: R20's bus clauses are, as R17's and R18's, what the ESC does with a bus
the document does not describe, judged by the same signs (:mod:`.resets`, :mod:`.settings`).
"""

from __future__ import annotations

import pytest

from ckesc.bench.bus_fault import NO_CONTROL, bus_fault_control
from ckesc.bench.dut import DutError
from ckesc.protocol.canbus import recovery_seconds

from .resets import reset_signs
from .settings import changes
from .telemetry import REACT_S, interval_s, ms
from .test_robustness_r18_load import timing_unjudged

SECTION = "robustness"
#: How long the bus is shorted: far past the ESC's way to bus-off (32 tries) and past R8's timeout with a margin, so
#: that the commands lost meanwhile raise the comm flag
SHORT_S = 0.5


def _control(dut):
    control = bus_fault_control(dut.lane)
    if control is None:
        pytest.skip(NO_CONTROL)
    return control


def _bound(dut, interval: float) -> float:
    """R20: the recovery time plus two MSG1 intervals plus the bench's error."""
    return recovery_seconds(dut.lane.bitrate) + 2 * interval + dut.lane.timing_error


def _short(dut, control) -> float:
    """Short the bus for :data:`SHORT_S`; when it ended."""
    end = control.cause("short", SHORT_S)
    return dut.now() if end is None else end


def _flushed(dut, s: dict, end: float, bound: float) -> None:
    """Read on until the reports an ESC held through bus-off and sent late (what a controller's mailboxes do; R20
    leaves the first reports after recovery OBSERVE) have each been followed by one on its own grid: the longest
    report interval twice from the bound's end."""
    dut.read_until(end + bound + 2 * max(interval_s(s, k) for k in ("msg1", "msg2", "msg3")))


def _restore(dut, control) -> None:
    """An ESC still silent (bus-off without recovery) comes back at a power cycle, as on a real bench."""
    if not control.settle():
        dut.switch_power()  # (not proven by 241: the ESC was silent before it; the verdict is the test's own)
        control.settle()


@pytest.mark.requirement("R20-recovery")
def test_reports_go_on_after_a_bus_short(dut):
    """After a short that sent it bus-off: MSG1 again within the recovery time + two MSG1 intervals + the bench's
    error, no reset (no report gap with the transfer ids starting again, 241's power-up count unmoved) and the
    settings (242) unchanged."""
    control = _control(dut)
    s = dut.settings()
    ups = dut.power_up_count()
    interval = interval_s(s, "msg1")
    bound = _bound(dut, interval)
    t0 = dut.now()
    try:
        with timing_unjudged(dut, "across the bus fault", "R20: the first reports after recovery are OBSERVE"):
            end = _short(dut, control)
            dut.read_until(end + bound)
            dut.wait(REACT_S)  # what came before the bound, read (the fault's control may have run past it)
            back = [f for f in dut.frames("msg1", since=end, source=dut.node_id) if f.timestamp <= end + bound]
            _flushed(dut, s, end, bound)
        problems = []
        if not back:
            problems.append(f"no MSG1 within {ms(bound):g} ms of the bus being freed (R20: {ms(recovery_seconds(dut.lane.bitrate)):g} "
                            f"ms bus-off recovery + 2 MSG1 intervals of {ms(interval):g} ms + the bench's "
                            f"{ms(dut.lane.timing_error):g} ms)")
        msg1 = dut.frames("msg1", since=t0, source=dut.node_id)
        problems += reset_signs(dut, msg1, interval)
        try:
            after, ups_after = dut.settings(), dut.power_up_count()
        except DutError as exc:
            problems.append(f"afterwards it did not answer: {exc}")
        else:
            if changed := changes(s, after):
                problems.append(f"its settings changed: {changed}")
            problems += reset_signs(dut, [], interval, ups=(ups, ups_after))
        if back:
            dut.record.observe("reports after the short", f"first MSG1 {ms(back[0].timestamp - end):g} ms after the bus "
                               f"was freed (bound {ms(bound):g} ms)")
    finally:
        _restore(dut, control)
    assert not problems, (f"after a {ms(SHORT_S):g} ms bus short (CANH-CANL): " + "; ".join(problems)
                          + " (R20: the ESC recovers from bus-off by itself, without a reset, its settings kept)")
