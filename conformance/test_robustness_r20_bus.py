"""Robustness (R20): the ESC after its CAN bus was disturbed and freed.

The test shorts the bus (CANH to CANL: every bit dominant) long enough that the ESC, which goes on reporting, meets
32 bit errors and goes bus-off, then frees it. The ESC's controller must recover by itself (128 x 11 recessive bits)
and its reports go on within R20's bound, without a reset and with its settings unchanged; the commands it lost
meanwhile raise its comm flag (R8), and the next command clears it.

The fault is the bench's (:mod:`ckesc.bench.bus_fault`): in the simulated lane its world shorts the bus (the CAN
model's acknowledgement and error confinement on for the fault and its recovery only); in the real-time lane the
emulator's hub does (``ckesc control bus``); on a real bench ``--bus-fault-cmd`` closes a relay across CANH-CANL,
a command's or labgrid's (docs/robustness.md). A lane without one SKIPs these tests.

Section ``robustness``, not one of its own: R20's bus clauses are, as R17's and R18's, what the ESC does with a bus
the document does not describe, judged by the same signs (:mod:`.resets`, :mod:`.settings`).
"""

from __future__ import annotations

import pytest

from ckesc.bench.bus_fault import NO_CONTROL, bus_fault_control
from ckesc.bench.outcomes import Inconclusive
from ckesc.bench.power import POWER_COMMAND_TIMEOUT_S
from ckesc.protocol.canbus import recovery_seconds
from ckesc.protocol.catalogue import REPORT_FRAMES, Status

from .resets import afterwards, reset_signs
from .telemetry import REACT_S, interval_s, ms, timing_unjudged
from .throttle import FORMAT_CHANNELS, STREAM_PERIOD_S, can_throttle, command_for

SECTION = "robustness"
#: How long the bus is shorted: far past the ESC's way to bus-off (32 tries) and past R8's timeout with a margin, so
#: that the commands lost meanwhile raise the comm flag
SHORT_S = 0.5


def _control(dut, config, kind: str = "short"):
    control = bus_fault_control(dut.lane, config.getoption("bus_fault_cmd"),
                                config.getoption("power_cmd_timeout") or POWER_COMMAND_TIMEOUT_S)
    if control is None:
        pytest.skip(NO_CONTROL)
    if not control.can(kind):
        pytest.skip(f"the bench's bus-fault control causes no {kind} (a relay shorts the bus only; a --bus-fault-cmd "
                    "naming {kind} is asked for it)")
    return control


def _bound(dut, interval: float) -> float:
    """R20: the recovery time plus two MSG1 intervals plus the bench's error."""
    return recovery_seconds(dut.lane.bitrate) + 2 * interval + dut.lane.timing_error


def _fault(dut, control, kind: str = "short") -> float:
    """Disturb the bus for :data:`SHORT_S`; when it ended."""
    end = control.cause(kind, SHORT_S)
    return dut.now() if end is None else end


def _flushed(dut, s: dict, end: float, bound: float) -> None:
    """Read on until the reports an ESC held through bus-off and sent late (what a controller's mailboxes do; R20
    leaves the first reports after recovery OBSERVE) have each been followed by one on its own grid: the longest
    report interval twice from the bound's end."""
    dut.read_until(end + bound + 2 * max(interval_s(s, k) for k in REPORT_FRAMES))


def _restore(dut, control) -> None:
    """An ESC still silent (bus-off without recovery) comes back at a power cycle, as on a real bench."""
    if not control.settle():
        dut.switch_power()  # (not proven by 241: the ESC was silent before it; the verdict is the test's own)
        control.settle()


#: the bus rules left unjudged from a fault until each report type is back on its grid: the reports' timing, and
#: their transfer-id sequence (R20: whether a recovered ESC's first reports keep it is OBSERVE; an ESC whose mailboxes
#: were full in bus-off dropped some, and the first report after those it held skips their transfer ids)
REPORT_TIMING = frozenset({"R9", "R9a", "F3"})
#: the faults, as the messages name them
FAULTS = {"short": "bus short (CANH-CANL)", "other_bitrate": "node at another bit rate sending"}


@pytest.mark.requirement("R20-recovery")
@pytest.mark.parametrize("kind", list(FAULTS))
def test_reports_go_on_after_a_bus_fault(dut, kind, pytestconfig):
    """After a short that sent it bus-off, or a node at another bit rate sending: MSG1 again within the recovery
    time + two MSG1 intervals + the bench's error, no reset (no report gap with the transfer ids starting again, 241's
    power-up count unmoved) and the settings (242) unchanged."""
    control = _control(dut, pytestconfig, kind)
    s = dut.settings()
    ups = dut.power_up_count()
    interval = interval_s(s, "msg1")
    bound = _bound(dut, interval)
    t0 = dut.now()
    try:
        with timing_unjudged(dut, "across the bus fault", REPORT_TIMING, "R20: the first reports after recovery, their timing and transfer-id sequence, are OBSERVE"):
            end = _fault(dut, control, kind)
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
        problems += afterwards(dut, s, ups, interval)
        if back:
            dut.record.observe("reports after the fault", f"first MSG1 {ms(back[0].timestamp - end):g} ms after the bus "
                               f"was freed (bound {ms(bound):g} ms)")
    finally:
        _restore(dut, control)
    assert not problems, (f"after a {ms(SHORT_S):g} ms {FAULTS[kind]}: " + "; ".join(problems)
                          + " (R20: the ESC recovers from bus-off by itself, without a reset, its settings kept)")


def _flag(f) -> bool:
    return bool(f.fields["status"] & Status.COMM_FAULT)


@pytest.mark.requirement("R20-comm", "R8", "R20-recovery")
def test_comm_flag_rises_through_a_bus_short_and_clears(dut, pytestconfig):
    """Under a zero-throttle stream the flag is clear; the stream stops as the bus is shorted (the commands cannot
    reach the ESC) for longer than R8's timeout and an MSG1 interval: the ESC's reports once they are back carry the
    comm flag, and the next command clears it within two MSG1 intervals. It counts on R20-recovery (the ESC back by
    itself, without a reset: 241's power-up count is read before and after, so that a reset shows in this test)."""
    control = _control(dut, pytestconfig)
    s = can_throttle(dut)
    ups = dut.power_up_count()
    interval = interval_s(s, "msg1")
    name = next(n for n in FORMAT_CHANNELS if command_for(n, s["throttle_channel"]) is not None)
    fields = command_for(name, s["throttle_channel"])
    bound = _bound(dut, interval)
    problems = []
    try:
        dut.throttle_stream(name, fields, STREAM_PERIOD_S)
        dut.wait(4 * interval + dut.lane.timing_error)
        under = dut.frames("msg1", since=dut.now() - 2 * interval, source=dut.node_id)
        if not under or any(_flag(f) for f in under):
            raise Inconclusive(f"the comm flag was not clear under the {ms(STREAM_PERIOD_S):g} ms command stream "
                               "before the fault (R8's test judges that)")
        dut.stop_throttle()
        with timing_unjudged(dut, "across the bus fault", REPORT_TIMING, "R20: the first reports after recovery, their timing and transfer-id sequence, are OBSERVE"):
            end = _fault(dut, control)
            _flushed(dut, s, end, bound)
        fresh = dut.frames("msg1", since=dut.now() - 2 * interval, source=dut.node_id)
        if not fresh:
            problems.append(f"no MSG1 in the {ms(2 * interval):g} ms before the next command")
        elif not all(_flag(f) for f in fresh):
            problems.append(f"MSG1 without the comm flag {ms(dut.now() - end + SHORT_S):g} ms after the last command "
                            "(the commands could not reach it through the short)")
        dut.broadcast(name, fields)
        cleared = dut.wait_for("msg1", 2 * interval + dut.lane.timing_error, source=dut.node_id,
                               where=lambda f: not _flag(f))
        if cleared is None:
            problems.append(f"the next command did not clear the comm flag within {ms(2 * interval):g} ms")
        problems += afterwards(dut, None, ups, interval)
    finally:
        dut.stop_throttle()
        _restore(dut, control)
    assert not problems, (f"after a {ms(SHORT_S):g} ms bus short with the command stream stopped: " + "; ".join(problems)
                          + " (R20: commands lost while the bus is disturbed raise the comm flag as R8 says, the "
                          "next command clears it)")
