"""Spec section 4.4.19: Set Baud (211) - the CAN bit rate, taking effect at the next power-up.

Every test opens the 120 s window (R11) with a proven power cycle first, and puts the DUT back at the
bit rate it was found at in a ``finally`` (Set Baud in a fresh window, a power cycle, the host
reopened at that rate), verified. Where the DUT answers is found by reopening the host's bus at each
rate of the code table and asking 242; a power cycle is proven by the power-up counter (241 option 2)
at whichever rate the DUT answers after it.
"""

import pytest

from ckesc.bench.dut import DutError
from ckesc.bench.epochs import AFTER, INSIDE
from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.legality import illegal_cases

from .answers import RESTORE_IN_WINDOW_S
from .telemetry import msg_control, resume

SECTION = "4.4.19"
SPEC = cat.spec("set_baud")
RATES = cat.BAUD_RATES  # 4.4.19-T: code -> bit/s
CODES = {rate: code for code, rate in RATES.items()}
ILLEGAL = illegal_cases(SPEC)  # R10: codes above 6
WINDOW_TEST_TIMEOUT_S = int(3 * cat.CONFIG_WINDOW_S)  # they wait the window out: in real time, minutes


# ------------------------------------------------------------------------------------------ helpers
def _reopen(dut, rate):
    """The host's bus at ``rate``. Work-around: ``RealtimeEmulatorLane.reopen`` only records the rate, so
    the emulator's bus is set to it through its control channel here (reported as a harness bug)."""
    dut.lane.reopen(rate)
    control = getattr(dut.lane, "control", None)  # RealtimeEmulatorLane: (host, port) of `ckesc emulate --control`
    if control is not None:
        from ckesc.emulator.control import control_request

        control_request(control[1], {"cmd": "bitrate", "bitrate": rate}, host=control[0])


def _answers(dut):
    return dut.request("get_major_configuration", {"option": 0}).response is not None


def _find_rate(dut, first=None):
    """The bit rate the DUT answers at (the host is left there), or None."""
    for rate in dict.fromkeys([r for r in (first, dut.lane.bitrate) if r] + list(RATES.values())):
        if dut.lane.bitrate != rate:
            _reopen(dut, rate)
        if _answers(dut):
            return rate
    return None


def _cycle(dut, expect):
    """A power cycle after which the host listens at ``expect`` bit/s; proven by the power-up counter
    at whichever rate the DUT answers then (``dut.power_cycle`` asks only at the host's current rate).
    Returns the rate the DUT answers at."""
    if not dut.lane.power.available:
        raise Inconclusive("this test needs a power cycle and no power control was given (--power)")
    before = dut.power_up_count() if _find_rate(dut, first=dut.lane.bitrate) is not None else None
    on = dut.switch_power()
    rate = _find_rate(dut, first=expect)
    after = dut.power_up_count() if rate is not None else None
    dut.record.observe("power-up counter", f"{before} -> {after} (answering at {rate} bit/s)")
    if before is None or after is None or after != (before + 1) & 0xFFFF:
        raise Inconclusive(f"power cycle not proven: power-up counter {before} -> {after} (DUT found at {rate} bit/s)")
    dut.proved_power_up(on, before, after)
    return rate


def _silent_at(dut, old, new, what):
    """The failure message when the DUT went silent at ``old`` bit/s after Set Baud to ``new``: whether it
    answers at ``new`` already (the host is put back at ``old``)."""
    _reopen(dut, new)
    try:
        at_once = _answers(dut)
    finally:
        _reopen(dut, old)
    if at_once:
        return f"answered at {new} bit/s at once; the new rate is due after the next power-up ({what})"
    return f"{what}, and no answer at {new} bit/s either"


def _set_baud(dut, code):
    return dut.request("set_baud", {"baud": code})


def _move_to(dut, code):
    """Setup: the DUT running at ``code``'s rate, its window freshly open (raises Inconclusive if Set
    Baud cannot get it there: what that test checks is then another test's business)."""
    if dut.lane.bitrate == RATES[code] and _answers(dut):
        dut.open_window()
        return
    dut.open_window()
    _set_baud(dut, code)
    rate = _cycle(dut, RATES[code])
    if rate != RATES[code]:
        raise Inconclusive(f"setup: Set Baud {code} did not bring the DUT to {RATES[code]} bit/s (it is at {rate})")


def _restore(dut, rate0):
    """Put the DUT back at ``rate0`` and the host with it; verified. Set Baud goes inside the window of the
    DUT's current power-up while enough of it is left, else (or when that did not take) in a fresh one."""
    rate = _find_rate(dut, first=rate0)
    if rate == rate0:
        return
    if rate is None:
        raise DutError(f"the DUT answers at no rate of the code table; it was at {rate0} bit/s")
    if dut.window_left() >= RESTORE_IN_WINDOW_S:  # inside the window of the current power-up, while it lasts
        _set_baud(dut, CODES[rate0])
        try:
            rate = _cycle(dut, rate0)  # proven: the next test may act in this window
        except Inconclusive:
            rate = _find_rate(dut, first=rate0)
    if rate != rate0:
        dut.switch_power()  # a fresh 120 s window (R11)
        _set_baud(dut, CODES[rate0])
        dut.switch_power()
    if _find_rate(dut, first=rate0) != rate0:
        raise DutError(f"could not put the DUT back at {rate0} bit/s (it answers at {dut.lane.bitrate})")


@pytest.fixture
def rate0(dut):
    """The bit rate the DUT runs at; put back (and the host with it) after the test, whatever happened."""
    rate = dut.lane.bitrate
    if not getattr(dut.lane, "can_change_bitrate", True):
        pytest.skip(f"the {dut.lane.name} lane cannot move the host to another bit rate (see --can-bitrate-cmd)")
    if rate not in CODES:
        pytest.skip(f"the host runs at {rate} bit/s, which is not in Set Baud's code table")
    try:
        yield rate
    finally:
        _restore(dut, rate)


def _other_code(*avoid_rates):
    return next(code for code, rate in RATES.items() if rate not in avoid_rates)


# ------------------------------------------------------------------------------------------ tests
@pytest.mark.requirement("4.4.19-1", "4.4.19-T", "R11", "R13")
@pytest.mark.power_cycle
@pytest.mark.parametrize("code", sorted(RATES), ids=lambda c: f"code{c}-{RATES[c]}")
def test_new_rate_only_after_the_next_power_up(dut, rate0, code):
    """Set Baud is answered with the code; until the next power-up the DUT keeps answering and
    reporting at the old rate; after it, it answers at the code's rate, and only there."""
    start_code = CODES[rate0] if RATES[code] != rate0 else _other_code(rate0)
    _move_to(dut, start_code)  # from another rate, so that the change shows
    old = RATES[start_code]
    ex = _set_baud(dut, code)
    assert ex.response is not None, _silent_at(dut, old, RATES[code], f"no answer to Set Baud at {old} bit/s")
    assert ex.response.fields["baud"] == code, f"Set Baud {code} answered {ex.response.fields}"
    interval = dut.settings()["msg1_interval"] * cat.INTERVAL_UNIT_S
    start = dut.now()
    dut.wait(3 * interval)
    heard = [f for f in dut.frames(since=start, source=dut.node_id) if f.timestamp > start]
    heard += [g for g in dut.garbled if (g.msg.timestamp or 0.0) > start and (g.msg.arbitration_id & 0x7F) == dut.node_id]
    assert heard, _silent_at(dut, old, RATES[code], f"nothing from the DUT at {old} bit/s before the next power-up")
    assert _answers(dut), _silent_at(dut, old, RATES[code], f"no answer at {old} bit/s before the next power-up")
    rate = _cycle(dut, RATES[code])
    assert rate == RATES[code], f"after the power-up the DUT answers at {rate} bit/s, not {RATES[code]} (code {code})"
    _reopen(dut, old)
    assert not _answers(dut), f"after the power-up the DUT still answers at {old} bit/s"
    _reopen(dut, rate)


@pytest.mark.requirement("4.4.19-3", "R13")
@pytest.mark.power_cycle
def test_rate_persists_across_power_cycles(dut, rate0):
    """'This parameter will be saved in FLASH ... will not be lost when power is turned off.'"""
    code = _other_code(rate0, cat.DEFAULT_BITRATE)
    dut.open_window()
    _set_baud(dut, code)
    for n in (1, 2):
        rate = _cycle(dut, RATES[code])
        assert rate == RATES[code], f"after power cycle {n} the DUT answers at {rate} bit/s, not {RATES[code]}"


@pytest.mark.requirement("R10", "R10-answer", "4.4.19-T", "R13")
@pytest.mark.power_cycle
@pytest.mark.parametrize("case", ILLEGAL, ids=lambda c: c.id)
def test_illegal_code_changes_nothing(dut, rate0, case):
    """A code above 6 is ignored: after the next power-up the DUT is still at its rate. Run from a
    rate that is not the default, so that a device falling back to 500 kbit/s shows."""
    base = _other_code(rate0, cat.DEFAULT_BITRATE)
    _move_to(dut, base)
    ex = _set_baud(dut, case.value)
    dut.record.observe("answer to the illegal code (R10-answer)", ex.response.fields if ex.response else "none")
    rate = _cycle(dut, RATES[base])
    assert rate == RATES[base], f"Set Baud {case.value}: after a power-up the DUT answers at {rate}, not {RATES[base]}"


@pytest.mark.requirement("R11", "R13")
@pytest.mark.power_cycle
@pytest.mark.window(INSIDE)
@pytest.mark.timeout(WINDOW_TEST_TIMEOUT_S)
def test_set_baud_just_inside_the_window_is_obeyed(dut, rate0):
    """Sent a second before 120 s after power-up, Set Baud takes effect at the next power-up."""
    code = _other_code(rate0)
    epoch = dut.at_window_moment(INSIDE)
    ex = _set_baud(dut, code)
    dut.record.observe("sent at (s after power-on, at most)", round(ex.sent.time - epoch.on_earliest, 3))
    rate = _cycle(dut, RATES[code])
    assert rate == RATES[code], f"Set Baud {code} inside the window: after a power-up the DUT answers at {rate}"


@pytest.mark.requirement("R11", "R10-answer")
@pytest.mark.power_cycle
@pytest.mark.window(AFTER)
@pytest.mark.timeout(WINDOW_TEST_TIMEOUT_S)
def test_set_baud_after_the_window_is_ignored(dut, rate0):
    """Sent a second after 120 s from power-up, Set Baud changes nothing, after the next power-up either."""
    code = _other_code(rate0)
    epoch = dut.at_window_moment(AFTER)
    ex = _set_baud(dut, code)
    dut.record.observe("sent at (s after power-on, at least)", round(ex.sent.time - epoch.ready, 3))
    dut.record.observe("answer to the late Set Baud", ex.response.fields if ex.response else "none")
    rate = _cycle(dut, rate0)
    assert rate == rate0, f"Set Baud {code} after the window: after a power-up the DUT answers at {rate}, not {rate0}"


@pytest.mark.requirement("4.4.2-3", "R12", "R11", "R13")
@pytest.mark.power_cycle
def test_set_baud_while_suspended_changes_nothing(dut, rate0):
    """'Parameter changes do not take effect when ... suspended' (4.4.2-3, R12): a Set Baud inside the 120 s window
    (R11) while reporting is suspended is not stored: after the resume and the next power-up the DUT answers at its
    rate. The same Set Baud with reporting on, inside the window of that power-up, takes effect at the next one
    (else the DUT ignores it anyway and nothing is shown: INCONCLUSIVE)."""
    code = _other_code(rate0)
    dut.open_window()
    try:
        msg_control(dut, cat.MSG_CONTROL_SUSPEND)
        ex = _set_baud(dut, code)
        dut.record.observe("answer to Set Baud while suspended", ex.response.fields if ex.response else "none")
    finally:
        resume(dut)
    rate = _cycle(dut, rate0)
    assert rate == rate0, (f"Set Baud {code} sent while suspended took effect: after the resume and a power-up the "
                           f"DUT answers at {rate} bit/s, not {rate0}")
    _set_baud(dut, code)
    if (rate := _cycle(dut, RATES[code])) != RATES[code]:
        raise Inconclusive(f"Set Baud {code} with reporting on does not take effect either (after a power-up the DUT "
                           f"answers at {rate} bit/s): that it is ignored while suspended shows nothing")


@pytest.mark.requirement("4.4.19-2")
def test_observe_bit_rate(dut):
    """'Default bus rate is 500KHz': the rate the DUT answers at is recorded (no factory reset here)."""
    dut.record.observe("bit rate the DUT answers at", dut.lane.bitrate)
    assert dut.lane.bitrate == cat.DEFAULT_BITRATE, f"the DUT runs at {dut.lane.bitrate} bit/s, not the default"
