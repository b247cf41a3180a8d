"""Spec section 4.4.5: MSG2 (20051) - input voltage (0.01 V), bus current (0.01 A) and MOS temperature."""

from __future__ import annotations

import pytest

from ckesc.harness.verdict import Inconclusive
from ckesc.protocol import catalogue as cat

from .reports import INTERVALS, describe_garbled, garbled, interval_s, ms, need_decoded, report_starts

SECTION = "4.4.5"

PAYLOAD = cat.spec("msg2").layouts[0].size
#: Physics, not protocol: a LiHV cell full is 4.35 V; no drone ESC runs below two cells at 3.0 V.
#: A reading in the wrong unit (0.1 V, 1 mV) falls outside [2 x 3.0 V, max_cells x 4.35 V].
CELL_FULL_V = 4.35
MIN_SUPPLY_V = 2 * 3.0


def esc_limits(dut) -> tuple[int, float]:
    """(max cells, max current in A) from ESC Information (240)."""
    info = dut.ask("esc_information", {"option": 0})
    layout = cat.spec("esc_information").response
    cells, amps = info["max_cells"], layout.field("max_current").physical(info["max_current"])
    dut.record.observe("ESC Information", f"{cells} S, {amps} A")
    if not cells or not amps:
        raise Inconclusive(f"ESC Information (240) gives {cells} S / {amps} A: no bound to check the units against")
    return cells, amps


def check_voltage_current(dut, frames: list, cells: int, amps: float, what: str, requirement: str) -> None:
    """Voltage and current are unsigned 0.01 V / 0.01 A: in range for the ESC's cells and current."""
    volts = [f.physical()["voltage"] for f in frames]
    currents = [f.physical()["current"] for f in frames]
    dut.record.observe(f"{what} voltage (V)", f"{min(volts)}..{max(volts)}")
    dut.record.observe(f"{what} current (A)", f"{min(currents)}..{max(currents)}")
    rec = dut.record
    rec.measure(f"{what} voltage, lowest", min(volts), limit=MIN_SUPPLY_V, op=">=", unit="V", clock=dut.clock,
                requirement=requirement)
    rec.measure(f"{what} voltage, highest", max(volts), limit=round(cells * CELL_FULL_V, 6), unit="V",
                clock=dut.clock, requirement=requirement)
    rec.measure(f"{what} current, highest (unsigned: a negative value reads as ~655 A)", max(currents), limit=amps,
                unit="A", clock=dut.clock, requirement=requirement)


def check_interval_follows_set_freq(dut, report: str, interval: int) -> None:
    """After Set Freq sets ``report``'s interval (the others as they are), ``report`` comes every
    ``interval`` x 2 ms: measured over four intervals once the old schedule has run out (R9)."""
    s = dut.settings()
    fields = {k: s[k] for k in INTERVALS} | {f"{report}_interval": interval}
    dut.ask("set_freq", {"option": 1, **fields})
    target = interval * cat.INTERVAL_UNIT_S
    dut.wait(max(interval_s(s, report), target))  # the old schedule runs out
    t = dut.now()
    dut.wait(4 * target + target / 2)
    stamps = report_starts(dut, report, t)
    what = report.upper()
    assert len(stamps) >= 3, f"only {len(stamps)} {what} in {ms(4.5 * target)} ms at {what}_SET {interval}"
    worst = max(abs((b - a) - target) for a, b in zip(stamps, stamps[1:]))
    dut.record.measure(f"{what} interval error", ms(worst), limit=dut.interval_tolerance_ms, unit="ms", clock=dut.clock,
                       error=dut.lane.timing_error * 1000, requirement="R9")


@pytest.mark.requirement("4.4.5-1")
def test_msg2_is_five_bytes(dut):
    """Every MSG2 carries 5 payload bytes (6 data bytes with the tail)."""
    window = 4 * interval_s(dut.settings(), "msg2")
    start = dut.now()
    frames = dut.reports("msg2", window)
    bad = garbled(dut, "msg2", source=dut.node_id, since=start)
    assert not bad, f"{len(bad)} MSG2 frames are not {PAYLOAD} payload bytes + tail: {describe_garbled(bad)}"
    assert frames, f"no MSG2 in {ms(window)} ms"
    lengths = sorted({len(f.data) - 1 for f in frames})
    assert lengths == [PAYLOAD], f"MSG2 payload lengths {lengths}, expected {PAYLOAD}"


@pytest.mark.requirement("4.4.5-2", "R9")
@pytest.mark.parametrize("interval", [10, 120])
def test_msg2_interval_follows_set_freq(dut, interval):
    """After Set Freq, MSG2 comes every MSG2_SET x 2 ms."""
    check_interval_follows_set_freq(dut, "msg2", interval)


@pytest.mark.requirement("4.4.5-T")
def test_voltage_and_current_units(dut):
    """Voltage in 0.01 V within [two cells, max_cells x 4.35 V] of ESC Information (240); current in
    0.01 A, unsigned, at most the ESC's maximum current."""
    cells, amps = esc_limits(dut)
    t = dut.now()
    frames = need_decoded(dut, "msg2", dut.reports("msg2", 3 * interval_s(dut.settings(), "msg2")), t, "voltage and current")
    assert frames, "no MSG2"
    dut.record.observe("MOS temperature (degC)", sorted({f.fields["temperature"] for f in frames}))
    check_voltage_current(dut, frames, cells, amps, "MSG2", "4.4.5-T")
