"""Spec section 4.4.6: MSG3 (20052) - MOS, capacitor, motor and MCU temperatures."""

from __future__ import annotations

import pytest

from ckesc.protocol import catalogue as cat

from .physics import MAX_PLAUSIBLE_C, SAME_SENSOR_C
from .telemetry import REACT_S, check_interval_follows_set_freq, describe_garbled, garbled, interval_s, ms, need_decoded

SECTION = "4.4.6"

LAYOUT = cat.spec("msg3").layouts[0]
PAYLOAD = LAYOUT.size
TEMPERATURES = ("mos_t", "cap_t", "mcu_t")  # motor_t needs a motor sensor (capability motor_temperature)


@pytest.mark.requirement("4.4.6-1", "4.4.6-T")
def test_msg3_is_reported_unasked(dut):
    """MSG3 - with the table's layout: MSG3 data - comes on its own, at its interval, without any request."""
    window = 2 * interval_s(dut.settings(), "msg3") + 2 * REACT_S
    frames = dut.reports("msg3", window)
    assert frames, f"no MSG3 with the table's layout in {ms(window)} ms"
    dut.record.observe("MSG3", frames[-1].physical())


@pytest.mark.requirement("4.4.6-2", "R9", "R9a")
@pytest.mark.parametrize("interval", [10, 100])
def test_msg3_interval_follows_set_freq(dut, interval):
    """After Set Freq, MSG3 comes every MSG3_SET x 2 ms."""
    check_interval_follows_set_freq(dut, "msg3", interval)


@pytest.mark.requirement("4.4.6-T")
def test_msg3_layout_and_temperatures(dut):
    """7 payload bytes (MOS_T, CAP_T, Motor_T, MCU_T, 3 reserved); temperatures plausible, and MOS_T
    the same sensor as MSG2's temperature."""
    s = dut.settings()
    start = dut.now()
    window = 2 * max(interval_s(s, "msg3"), interval_s(s, "msg2")) + 2 * REACT_S
    frames = dut.reports("msg3", window)
    msg2 = dut.frames("msg2", since=start, source=dut.node_id)
    bad = garbled(dut, "msg3", source=dut.node_id, since=start)
    assert not bad, f"{len(bad)} MSG3 frames are not {PAYLOAD} payload bytes + tail: {describe_garbled(bad)}"
    assert frames, f"no MSG3 in {ms(window)} ms"
    dut.record.observe("reserved bytes", sorted({(f.fields["reserved_1"], f.fields["reserved_2"], f.fields["reserved_3"])
                                                 for f in frames}))
    motor = sorted({f.fields["motor_t"] for f in frames})
    dut.record.observe("Motor_T", motor if dut.profile.has("motor_temperature") else f"{motor} (no motor sensor)")
    checked = TEMPERATURES + (("motor_t",) if dut.profile.has("motor_temperature") else ())
    for f in frames:
        hot = {k: f.fields[k] for k in checked if f.fields[k] > MAX_PLAUSIBLE_C}
        assert not hot, f"implausible temperatures {hot} degC in MSG3 {f.fields}"
    assert need_decoded(dut, "msg2", msg2, start, "MSG2's temperature"), "no MSG2 to compare MOS_T with"
    for f in frames:
        near = min(msg2, key=lambda m: abs(m.timestamp - f.timestamp))
        diff = abs(f.fields["mos_t"] - near.fields["temperature"])
        assert diff <= SAME_SENSOR_C, (f"MSG3 MOS_T {f.fields['mos_t']} degC, MSG2 temperature (MOS) {near.fields['temperature']} "
                                       f"degC {ms(abs(near.timestamp - f.timestamp))} ms apart")
