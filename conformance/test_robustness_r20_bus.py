"""Robustness (R20): the ESC after its CAN bus was disturbed and freed.

The test shorts the bus (CANH to CANL: every bit dominant) long enough that the ESC, which goes on reporting, meets
32 bit errors and goes bus-off, then frees it. The ESC's controller must recover by itself (128 x 11 recessive bits)
and its reports go on within R20's bound, without a reset and with its settings unchanged; the commands it lost
meanwhile raise its comm flag (R8), and the next command clears it.

The fault is the bench's (:mod:`ckesc.bench.bus_fault`): in the simulated lane its world shorts the bus (the CAN
model's acknowledgement and error confinement on for the fault and its recovery only); in the real-time lane the
emulator's hub does (``ckesc control bus``); on a real bench ``--bus-fault-cmd`` closes a relay across CANH-CANL,
a command's or labgrid's (docs/robustness.md). A lane without one SKIPs these tests.

An ESC at another bit rate than its bus takes nothing (R20-bitrate): moved to another rate by Set Baud, it is sent
from the host at the bus's rate every command that would show if taken (:mod:`.showing`), and read back at its own
rate and after a power cycle. It needs power control and a host that changes its bit rate (:mod:`.baud`'s ``rate0``).

Section ``robustness``, not one of its own: R20's bus clauses are, as R17's and R18's, what the ESC does with a bus
the document does not describe, judged by the same signs (:mod:`.resets`, :mod:`.settings`).
"""

from __future__ import annotations

import pytest

from ckesc.bench.bus_fault import NO_CONTROL, bus_fault_control
from ckesc.bench.lanes import BusFault
from ckesc.bench.outcomes import Inconclusive, NotClaimed
from ckesc.bench.power import POWER_COMMAND_TIMEOUT_S
from ckesc.protocol import catalogue as cat
from ckesc.protocol.canbus import recovery_seconds
from ckesc.protocol.catalogue import REPORT_FRAMES, Status
from ckesc.protocol.judgements import R20_UNJUDGED, r20_bound_s

from .baud import CODES, RATES, cycle, move_to, rate0, reopen
from .resets import afterwards, reset_signs
from .showing import TAKEN, command, state_bits
from .telemetry import REACT_S, interval_s, ms, timing_unjudged
from .throttle import FORMAT_CHANNELS, STREAM_PERIOD_S, can_throttle, command_for

SECTION = "robustness"
rate0 = rate0  # fixture: the DUT and the host put back at the bit rate they were found at
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
    return r20_bound_s(interval, bitrate=dut.lane.bitrate) + dut.lane.timing_error


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


#: the bus rules left unjudged from a fault until each report type is back on its grid (R20's reading: an ESC whose
#: mailboxes were full in bus-off dropped some, and the first report after those it held skips their transfer ids)
REPORT_TIMING = R20_UNJUDGED
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


# ------------------------------------------------------------------------------------------ an ESC at another rate
#: the commands that change the ESC's reporting go last: an ESC that took them would stop the reports the other
#: signs are read from (and R12 would leave a settings write taken after a suspend unapplied)
_LAST = ("msg_control", "can_test")


def _at_the_old_rate(dut, s: dict, code: int) -> tuple[list[str], list[str]]:
    """From the host at the bus's rate (the ESC at another): every command of :data:`~.showing.TAKEN` that shows
    when taken, a Set Baud ``code`` inside the 120 s window (R11), and a zero-throttle stream through
    :data:`RATE_STREAM_S`. What was sent, and what the bench held (a lone host's frames: nobody at the bus's rate
    acknowledges them, so a real adapter holds them and its queue fills, R20)."""
    sent, held = [], []
    stream = next(n for n in FORMAT_CHANNELS if command_for(n, s["throttle_channel"]) is not None)
    try:
        dut.request("set_baud", {"baud": code}, expect_response=False)
        sent.append(f"Set Baud {code} ({RATES[code]} bit/s)")
        for name in TAKEN:
            if name in _LAST:  # (sent after the stream)
                continue
            _send(dut, name, command(dut, name, s), sent)
        dut.throttle_stream(stream, command_for(stream, s["throttle_channel"]), STREAM_PERIOD_S)
        dut.wait(RATE_STREAM_S)
        dut.stop_throttle()
        sent.append(f"{stream} at zero throttle every {ms(STREAM_PERIOD_S):g} ms for {ms(RATE_STREAM_S):g} ms")
        for name in _LAST:
            _send(dut, name, command(dut, name, s), sent)
        dut.wait(cat.ANSWER_DELAY_MAX_S)
    except BusFault as exc:
        held.append(str(exc))
    finally:
        dut.stop_throttle()
    return sent, held


def _send(dut, name: str, fields: dict | None, sent: list[str]) -> None:
    """``name``'s command ``fields`` as the host sends it (a request not waited for), said in ``sent``; nothing for a
    frame that cannot address the DUT's channel or a function its profile declares absent."""
    if fields is None:
        return
    try:
        if cat.spec(name).service:
            dut.request(name, fields, expect_response=False)
        else:
            dut.broadcast(name, fields, layout="query" if name == "get_esc_id" else None)
    except NotClaimed:
        return
    sent.append(f"{name} {fields}")


#: how long the zero-throttle stream runs at the bus's rate: past an MSG1 interval of the longest legal (the ESC that
#: took it has its comm flag cleared at its next MSG1, R8)
RATE_STREAM_S = 0.25


@pytest.mark.requirement("R20-bitrate", "R11", "R8")
@pytest.mark.power_cycle
def test_an_esc_at_another_bit_rate_takes_nothing(dut, rate0):
    """The ESC moved to another bit rate (Set Baud and a proven power cycle, as 4.4.19 does); from the host back at the
    bus's rate, every command that shows when taken (settings writes, a Set Baud to the bus's rate inside the 120 s
    window, queries, reads, a zero-throttle stream, then MSG Control suspend and CAN Test on). Then, the host at the
    ESC's rate: it sent nothing but its reports (no answer, no CAN Test frame), still reports with its state bits as
    they were and its comm flag raised (no command reached it: R8), its settings unchanged, no reset. The ESC and the
    host are put back at the bus's rate whatever happened (``rate0``). Zero throttle throughout."""
    code = next(c for c, r in sorted(RATES.items()) if r not in (rate0, cat.DEFAULT_BITRATE))
    move_to(dut, code)  # the ESC and the host at the other rate, the 120 s window of its power-up open
    other = RATES[code]
    s = can_throttle(dut)
    ups = dut.power_up_count()
    interval = interval_s(s, "msg1")
    err = dut.lane.timing_error
    raised = dut.wait_for("msg1", cat.COMM_LOSS_TIMEOUT_S + 2 * interval + err, source=dut.node_id, where=_flag)
    if raised is None:
        raise Inconclusive(f"setup: the comm flag did not rise at {other} bit/s with no command since the power-up "
                           "(R8's test judges that): a command taken at the bus's rate would not show")
    reopen(dut, rate0)  # the host at the bus's rate; the ESC at another
    dut.lane.alone = f"the ESC was at {other} bit/s"  # nobody here acknowledges: its adapter's error-passive expected
    sent, held = _at_the_old_rate(dut, s, CODES[rate0])
    reopen(dut, other)
    t1 = dut.now()
    dut.wait(2 * interval + cat.ANSWER_DELAY_MAX_S + err)
    problems = []
    took = sorted({f.name for f in dut.frames(since=t1, source=dut.node_id) if f.name not in cat.REPORT_FRAMES})
    took += [f"an undecodable frame {g.msg.arbitration_id:08X}" for g in dut.undecoded(since=t1, source=dut.node_id)]
    if took:
        problems.append(f"it sent {', '.join(took)} (answers to the host's frames, or what they started)")
    msg1 = dut.frames("msg1", since=t1, source=dut.node_id)
    if not msg1:
        problems.append(f"no MSG1 at {other} bit/s in the {ms(2 * interval + err):g} ms after (reporting stopped: a "
                        "suspend, CAN Test or a reset taken)")
    elif cleared := [f for f in msg1 if not _flag(f)]:
        problems.append(f"MSG1 without the comm flag {ms(cleared[0].timestamp - t1):g} ms after the host came back: "
                        "a RawCommand at the bus's rate refreshed its comm watchdog")
    if msg1 and state_bits(msg1[-1]) != state_bits(raised):
        problems.append(f"MSG1 state bits 0x{state_bits(raised):04X} -> 0x{state_bits(msg1[-1]):04X}")
    problems += afterwards(dut, s, ups, interval)
    try:  # a Set Baud taken shows at the next power-up (R11), proven by 241 at whichever rate the ESC answers then
        after = cycle(dut, other)
    except Inconclusive:
        if not problems:
            raise
        after = other  # the FAIL stands; where the rate went is then not known
    if after != other:
        problems.append(f"after the next power-up it answers at {after} bit/s: it took the Set Baud {CODES[rate0]} "
                        f"sent at {rate0} bit/s")
    dut.record.observe(f"sent at {rate0} bit/s", "; ".join(sent))
    if held:  # (nobody acknowledged: a controller that takes a frame acknowledges it, ISO 11898-1, so none was taken)
        dut.record.observe(f"the host's frames at {rate0} bit/s, not acknowledged: no node took them", held[0])
    assert not problems, (f"an ESC at {other} bit/s, after the host's commands at {rate0} bit/s (the bus's): "
                          + "; ".join(problems) + " (R20: an ESC at another bit rate than the bus takes nothing, "
                          "answers nothing and changes nothing)")
