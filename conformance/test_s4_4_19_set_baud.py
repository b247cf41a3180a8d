"""Spec section 4.4.19: Set Baud (211) - the CAN bit rate, taking effect at the next power-up.

Every test opens the 120 s window (R11) with a proven power cycle first, and puts the DUT back at the
bit rate it was found at in a ``finally`` (Set Baud in a fresh window, a power cycle, the host
reopened at that rate), verified. Where the DUT answers is found by reopening the host's bus at each
rate of the code table and asking 242; a power cycle is proven by the power-up counter (241 option 2)
at whichever rate the DUT answers after it.
"""

import pytest

from ckesc.bench.epochs import AFTER, INSIDE
from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.legality import illegal_cases

from .baud import CODES, RATES, answers_here, cycle, move_to, rate0, reopen, set_baud
from .telemetry import msg_control, resume

SECTION = "4.4.19"
SPEC = cat.spec("set_baud")
rate0 = rate0  # fixture: the DUT and the host put back at the bit rate they were found at
ILLEGAL = illegal_cases(SPEC)  # R10: codes above 6
WINDOW_TEST_TIMEOUT_S = int(3 * cat.CONFIG_WINDOW_S)  # they wait the window out: in real time, minutes


# ------------------------------------------------------------------------------------------ helpers
def _silent_at(dut, old, new, what):
    """The failure message when the DUT went silent at ``old`` bit/s after Set Baud to ``new``: whether it
    answers at ``new`` already (the host is put back at ``old``)."""
    reopen(dut, new)
    try:
        at_once = answers_here(dut)
    finally:
        reopen(dut, old)
    if at_once:
        return f"answered at {new} bit/s at once; the new rate is due after the next power-up ({what})"
    return f"{what}, and no answer at {new} bit/s either"


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
    move_to(dut, start_code)  # from another rate, so that the change shows
    old = RATES[start_code]
    ex = set_baud(dut, code)
    assert ex.response is not None, _silent_at(dut, old, RATES[code], f"no answer to Set Baud at {old} bit/s")
    assert ex.response.fields["baud"] == code, f"Set Baud {code} answered {ex.response.fields}"
    interval = dut.settings()["msg1_interval"] * cat.INTERVAL_UNIT_S
    start = dut.now()
    dut.wait(3 * interval)
    heard = [f for f in dut.frames(since=start, source=dut.node_id) if f.timestamp > start]
    heard += [g for g in dut.garbled if (g.msg.timestamp or 0.0) > start and (g.msg.arbitration_id & 0x7F) == dut.node_id]
    assert heard, _silent_at(dut, old, RATES[code], f"nothing from the DUT at {old} bit/s before the next power-up")
    assert answers_here(dut), _silent_at(dut, old, RATES[code], f"no answer at {old} bit/s before the next power-up")
    rate = cycle(dut, RATES[code])
    assert rate == RATES[code], f"after the power-up the DUT answers at {rate} bit/s, not {RATES[code]} (code {code})"
    reopen(dut, old)
    assert not answers_here(dut), f"after the power-up the DUT still answers at {old} bit/s"
    reopen(dut, rate)


@pytest.mark.requirement("4.4.19-3", "R13")
@pytest.mark.power_cycle
def test_rate_persists_across_power_cycles(dut, rate0):
    """'This parameter will be saved in FLASH ... will not be lost when power is turned off.'"""
    code = _other_code(rate0, cat.DEFAULT_BITRATE)
    dut.open_window()
    set_baud(dut, code)
    for n in (1, 2):
        rate = cycle(dut, RATES[code])
        assert rate == RATES[code], f"after power cycle {n} the DUT answers at {rate} bit/s, not {RATES[code]}"


@pytest.mark.requirement("R10", "R10-answer", "4.4.19-T", "R13")
@pytest.mark.power_cycle
@pytest.mark.parametrize("case", ILLEGAL, ids=lambda c: c.id)
def test_illegal_code_changes_nothing(dut, rate0, case):
    """A code above 6 is ignored: after the next power-up the DUT is still at its rate. Run from a
    rate that is not the default, so that a device falling back to 500 kbit/s shows."""
    base = _other_code(rate0, cat.DEFAULT_BITRATE)
    move_to(dut, base)
    ex = set_baud(dut, case.value)
    dut.record.observe("answer to the illegal code (R10-answer)", ex.response.fields if ex.response else "none")
    rate = cycle(dut, RATES[base])
    assert rate == RATES[base], f"Set Baud {case.value}: after a power-up the DUT answers at {rate}, not {RATES[base]}"


@pytest.mark.requirement("R11", "R13")
@pytest.mark.power_cycle
@pytest.mark.window(INSIDE)
@pytest.mark.timeout(WINDOW_TEST_TIMEOUT_S)
def test_set_baud_just_inside_the_window_is_obeyed(dut, rate0):
    """Sent a second before 120 s after power-up, Set Baud takes effect at the next power-up."""
    code = _other_code(rate0)
    epoch = dut.at_window_moment(INSIDE)
    ex = set_baud(dut, code)
    dut.record.observe("sent at (s after power-on, at most)", round(ex.sent.time - epoch.on_earliest, 3))
    rate = cycle(dut, RATES[code])
    assert rate == RATES[code], f"Set Baud {code} inside the window: after a power-up the DUT answers at {rate}"


@pytest.mark.requirement("R11", "R10-answer")
@pytest.mark.power_cycle
@pytest.mark.window(AFTER)
@pytest.mark.timeout(WINDOW_TEST_TIMEOUT_S)
def test_set_baud_after_the_window_is_ignored(dut, rate0):
    """Sent a second after 120 s from power-up, Set Baud changes nothing, after the next power-up either."""
    code = _other_code(rate0)
    epoch = dut.at_window_moment(AFTER)
    ex = set_baud(dut, code)
    dut.record.observe("sent at (s after power-on, at least)", round(ex.sent.time - epoch.ready, 3))
    dut.record.observe("answer to the late Set Baud", ex.response.fields if ex.response else "none")
    rate = cycle(dut, rate0)
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
        ex = set_baud(dut, code)
        dut.record.observe("answer to Set Baud while suspended", ex.response.fields if ex.response else "none")
    finally:
        resume(dut)
    rate = cycle(dut, rate0)
    assert rate == rate0, (f"Set Baud {code} sent while suspended took effect: after the resume and a power-up the "
                           f"DUT answers at {rate} bit/s, not {rate0}")
    set_baud(dut, code)
    if (rate := cycle(dut, RATES[code])) != RATES[code]:
        raise Inconclusive(f"Set Baud {code} with reporting on does not take effect either (after a power-up the DUT "
                           f"answers at {rate} bit/s): that it is ignored while suspended shows nothing")


@pytest.mark.requirement("4.4.19-2")
def test_observe_bit_rate(dut):
    """'Default bus rate is 500KHz': the rate the DUT answers at is recorded (no factory reset here)."""
    dut.record.observe("bit rate the DUT answers at", dut.lane.bitrate)
    assert dut.lane.bitrate == cat.DEFAULT_BITRATE, f"the DUT runs at {dut.lane.bitrate} bit/s, not the default"
