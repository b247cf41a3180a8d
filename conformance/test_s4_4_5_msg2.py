"""Spec section 4.4.5: MSG2 (20051) - input voltage (0.01 V), bus current (0.01 A) and MOS temperature."""

from __future__ import annotations

import pytest

from ckesc.protocol import catalogue as cat

from .physics import check_voltage_current, esc_limits
from .telemetry import (
    check_interval_follows_set_freq,
    describe_garbled,
    garbled,
    interval_s,
    ms,
    need_decoded,
    settle_reports,
)

SECTION = "4.4.5"

PAYLOAD = cat.spec("msg2").layouts[0].size


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


@pytest.mark.requirement("4.4.5-2", "R9", "R9a")
@pytest.mark.parametrize("interval", [10, 120])
def test_msg2_interval_follows_set_freq(dut, interval):
    """After Set Freq, MSG2 comes every MSG2_SET x 2 ms."""
    check_interval_follows_set_freq(dut, "msg2", interval)


@pytest.mark.requirement("4.4.5-T")
def test_voltage_and_current_units(dut):
    """Voltage in 0.01 V within [two cells, max_cells x 4.35 V] of ESC Information (240); current in
    0.01 A, unsigned, at most the ESC's maximum current."""
    cells, amps = esc_limits(dut)
    settle_reports(dut, ("msg2",))  # a write just before (a restore) may hold the next MSG2 as long as R9a allows
    t = dut.now()
    frames = need_decoded(dut, "msg2", dut.reports("msg2", 3 * interval_s(dut.settings(), "msg2")), t, "voltage and current")
    assert frames, "no MSG2"
    dut.record.observe("MOS temperature (degC)", sorted({f.fields["temperature"] for f in frames}))
    check_voltage_current(dut, frames, cells, amps, "MSG2", "4.4.5-T")
