"""Spec section attachment: Fault Code Definitions - the power-on self-test fault codes an ESC may report.

Fault code 1 is reported by 241 option 2 (Info_6..5, 4.4.27) and by MSG_EXP9 (Test_2..1, 4.4.11):
0 after a normal power-up, else one of the attachment's codes. Error code 2 (MSG_EXP10) is "not
currently defined": what a DUT reports there is recorded."""

from __future__ import annotations

import pytest

from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat

from .telemetry import exp_capture

SECTION = "attachment"


def _named(code: int) -> str:
    return f"{code:#06x} ({cat.FAULT_CODES_1.get(code, 'not in the attachment')})"


@pytest.mark.requirement("A-1")
def test_reported_fault_codes_are_the_attachment_s(dut):
    """241 option 2's power-on self-test fault code and MSG_EXP9's fault code 1 are 0 or one of the
    attachment's fault codes (0x01, 0x02, 0x11..0x13, 0x21..0x23)."""
    reported: dict[str, list[int]] = {}
    ex = dut.request("maintenance_information", {"option": 2})
    if ex.response is not None:
        reported["241 option 2"] = [ex.response.fields["fault_code"]]
    frames, _, _, _ = exp_capture(dut, if_claimed=True)
    exp9 = sorted({f.fields["fault_code_1"] for f in frames if f.name == "msg_exp9"})
    if exp9:
        reported["MSG_EXP9 fault code 1"] = exp9
    exp10 = sorted({f.fields["fault_code_2"] for f in frames if f.name == "msg_exp10"})
    dut.record.observe("fault codes", {k: [_named(c) for c in v] for k, v in reported.items()})
    dut.record.observe("MSG_EXP10 error code 2 (not defined)", [f"{c:#06x}" for c in exp10] or "no MSG_EXP10")
    if not reported:
        raise Inconclusive("neither 241 option 2 nor MSG_EXP9 reported a fault code")
    undefined = {k: [_named(c) for c in v if c not in cat.FAULT_CODES_1] for k, v in reported.items()}
    undefined = {k: v for k, v in undefined.items() if v}
    assert not undefined, f"fault codes outside the attachment's table: {undefined}"
