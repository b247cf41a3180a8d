"""Set Baud on a bench (4.4.19, R11): where the DUT answers, a power cycle proven at whichever rate it answers after,
and the ``rate0`` fixture that puts the DUT and the host back at the bit rate they were found at, whatever the test
did. Used by the Set Baud section and by the robustness section's malformed Set Baud.

Where the DUT answers is found by reopening the host's bus at each rate of the code table and asking 242; a power
cycle is proven by the power-up counter (241 option 2) at whichever rate the DUT answers after it.
"""

from __future__ import annotations

import pytest

from ckesc.bench.dut import restoring
from ckesc.bench.errors import RestoreFailed
from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat

from .answers import RESTORE_IN_WINDOW_S

RATES = cat.BAUD_RATES  # 4.4.19-T: code -> bit/s
CODES = {rate: code for code, rate in RATES.items()}


def set_baud(dut, code):
    return dut.request("set_baud", {"baud": code})


def reopen(dut, rate):
    """The host's bus at ``rate``. Work-around: ``RealtimeEmulatorLane.reopen`` only records the rate, so
    the emulator's bus is set to it through its control channel here (reported as a harness bug)."""
    dut.lane.reopen(rate)
    control = getattr(dut.lane, "control", None)  # RealtimeEmulatorLane: (host, port) of `ckesc emulate --control`
    if control is not None:
        from ckesc.emulator.control import control_request

        control_request(control[1], {"cmd": "bitrate", "bitrate": rate}, host=control[0])


def answers_here(dut):
    """Whether the DUT answers 242 at the host's current rate. Heard reporting there but not answering, it is asked
    once more: coming to its rate, the host meets first what the DUT queued while nobody acknowledged it (R20), and
    a queue full of those may have had no room for the first answer."""
    since = dut.now()
    if dut.request("get_major_configuration", {"option": 0}).response is not None:
        return True
    return bool(dut.frames(since=since, source=dut.node_id)) and (
        dut.request("get_major_configuration", {"option": 0}).response is not None)


def find_rate(dut, first=None):
    """The bit rate the DUT answers at (the host is left there), or None."""
    for rate in dict.fromkeys([r for r in (first, dut.lane.bitrate) if r] + list(RATES.values())):
        if dut.lane.bitrate != rate:
            reopen(dut, rate)
        if answers_here(dut):
            return rate
    return None


def cycle(dut, expect):
    """A power cycle after which the host listens at ``expect`` bit/s; proven by the power-up counter
    at whichever rate the DUT answers then (``dut.power_cycle`` asks only at the host's current rate).
    Returns the rate the DUT answers at."""
    if not dut.lane.power.available:
        raise Inconclusive("this test needs a power cycle and no power control was given (--power)")
    before = dut.power_up_count() if find_rate(dut, first=dut.lane.bitrate) is not None else None
    on = dut.switch_power()
    rate = find_rate(dut, first=expect)
    after = dut.power_up_count() if rate is not None else None
    dut.record.observe("power-up counter", f"{before} -> {after} (answering at {rate} bit/s)")
    if before is None or after is None or after != (before + 1) & 0xFFFF:
        raise Inconclusive(f"power cycle not proven: power-up counter {before} -> {after} (DUT found at {rate} bit/s)")
    dut.proved_power_up(on, before, after)
    return rate


def move_to(dut, code):
    """Setup: the DUT running at ``code``'s rate and the host with it, its window freshly open (raises Inconclusive
    if Set Baud cannot get it there: whether it does is 4.4.19's verdict, not the calling test's)."""
    if dut.lane.bitrate == RATES[code] and answers_here(dut):
        dut.open_window()
        return
    dut.open_window()
    set_baud(dut, code)
    rate = cycle(dut, RATES[code])
    if rate != RATES[code]:
        raise Inconclusive(f"setup: Set Baud {code} did not bring the DUT to {RATES[code]} bit/s (it is at {rate})")


def restore(dut, rate0):
    """Put the DUT back at ``rate0`` and the host with it; verified (RestoreFailed, the harness's, when not). Set Baud
    goes inside the window of the DUT's current power-up while enough of it is left, else (or when that did not
    take) in a fresh one."""
    with restoring(f"the DUT at {rate0} bit/s"):
        rate = find_rate(dut, first=rate0)
        if rate == rate0:
            return
        if rate is None:
            raise RestoreFailed(f"could not put the DUT back at {rate0} bit/s: it answers at no rate of the code table")
        if dut.window_left() >= RESTORE_IN_WINDOW_S:  # inside the window of the current power-up, while it lasts
            set_baud(dut, CODES[rate0])
            try:
                rate = cycle(dut, rate0)  # proven: the next test may act in this window
            except Inconclusive:
                rate = find_rate(dut, first=rate0)
        if rate != rate0:
            dut.switch_power()  # a fresh 120 s window (R11)
            set_baud(dut, CODES[rate0])
            dut.switch_power()
        if find_rate(dut, first=rate0) != rate0:
            raise RestoreFailed(f"could not put the DUT back at {rate0} bit/s (it answers at {dut.lane.bitrate})")


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
        restore(dut, rate)
