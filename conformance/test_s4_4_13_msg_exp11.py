"""Spec section 4.4.13: MSG_EXP11 (20063) - MOS, MCU, capacitor and motor temperatures, in MSG_EXP mode."""

from __future__ import annotations

import pytest

from ckesc.bench.outcomes import Inconclusive

from .physics import SAME_SENSOR_C
from .telemetry import REACT_S, exp_reports, interval_s

SECTION = "4.4.13"


@pytest.mark.requirement("4.4.13-T")
def test_exp11_agrees_with_msg3(dut):
    """MOS_T, MCU_T, CAP_T (this order: not MSG3's) are the temperatures MSG3 reported just before;
    MOS_T also MSG2's; Motor_T only with a motor sensor."""
    s = dut.settings()
    t = dut.now()
    msg3 = dut.reports("msg3", max(interval_s(s, "msg3"), interval_s(s, "msg2")) + REACT_S)
    msg2 = dut.frames("msg2", since=t, source=dut.node_id)
    if not (msg3 and msg2):
        raise Inconclusive("no decodable MSG3/MSG2 to compare MSG_EXP11 with")
    frames, _ = exp_reports(dut, "msg_exp11")
    dut.record.observe("MSG3", msg3[-1].fields)
    dut.record.observe("MSG_EXP11", frames[-1].fields)
    names = ("mos_t", "mcu_t", "cap_t") + (("motor_t",) if dut.profile.has("motor_temperature") else ())
    ref = {k: msg3[-1].fields[k] for k in names}
    for f in frames:
        off = {k: (f.fields[k], ref[k]) for k in names if abs(f.fields[k] - ref[k]) > SAME_SENSOR_C}
        assert not off, f"MSG_EXP11 vs MSG3 (degC, MSG_EXP11 first): {off}"
        mos2 = msg2[-1].fields["temperature"]
        assert abs(f.fields["mos_t"] - mos2) <= SAME_SENSOR_C, f"MSG_EXP11 MOS_T {f.fields['mos_t']}, MSG2 {mos2} degC"
