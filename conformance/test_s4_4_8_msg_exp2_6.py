"""Spec section 4.4.8: MSG_EXP2-6 (20054-20058) - debugging data, recorded (OBSERVE)."""

from __future__ import annotations

import pytest

from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import classify

from .telemetry import describe_garbled, exp_capture

SECTION = "4.4.8"

DEBUG_FRAMES = [s.name for s in cat.CATALOGUE if s.section == "4.4.8"]


@pytest.mark.requirement("4.4.8-T")
@pytest.mark.parametrize("name", DEBUG_FRAMES)
def test_observe_debug_frames(dut, name):
    """Whether the DUT sends this debugging frame in MSG_EXP mode, how often, and what it holds."""
    frames, bad, _, window = exp_capture(dut)
    got = [f for f in frames if f.name == name]
    wrong = [g for g in bad if (s := classify(g.msg.arbitration_id)[4]) is not None and s.name == name]
    dut.record.observe(f"frames in {window:.3f} s of MSG_EXP mode", len(got))
    if got:
        dut.record.observe("payloads", sorted({f.data[:-1].hex(" ") for f in got})[:5])
    if wrong:
        dut.record.observe("not 6 payload bytes + tail", describe_garbled(wrong))
