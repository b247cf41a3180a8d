"""Spec section 4.4.26: ESC Information (240) - hardware, protocol and firmware version information."""

from __future__ import annotations

import pytest

from ckesc.protocol import catalogue as cat
from ckesc.protocol.legality import illegal_fields

from .answers import heard_instead
from .codes import code

SECTION = "4.4.26"

SPEC = cat.spec("esc_information")
QUERY = {"option": code("esc_information", "option", "query")}  # "payload[0]=0"


@pytest.mark.requirement("4.4.26-T")
def test_answer_is_seven_plausible_bytes(dut):
    """The answer has 7 bytes Info_1..Info_7 (+ tail): maximum cells (S), maximum current (x10 A),
    hardware version, protocol version, firmware year, month (1..12) and day (1..31). The identity is
    recorded; asked twice, the ESC answers the same."""
    first, second = dut.request("esc_information", QUERY), dut.request("esc_information", QUERY)
    assert first.response is not None, f"no 7-byte answer to ESC Information from node {dut.node_id}" + heard_instead(dut, SPEC)
    layout = SPEC.response
    assert layout is not None and len(first.response.data) == layout.size + 1, f"{len(first.response.data)} data bytes"
    info = first.response.fields
    p = first.response.physical()
    dut.record.observe("ESC identity", {
        "max cells": f"{p['max_cells']}S", "max current": f"{p['max_current']} A", "hardware version": p["hardware_version"],
        "protocol version": p["protocol_version"],
        "firmware date (year, month, day)": (info["firmware_year"], info["firmware_month"], info["firmware_day"])})
    bad = illegal_fields(layout, info)
    assert not bad, "implausible " + ", ".join(f"{f.name} {v} (legal: {f.legal or sorted(f.codes or ())})" for f, v in bad)
    assert second.response is not None and second.response.fields == info, (
        f"asked again, ESC Information answered {second.response.fields if second.response else 'nothing'}, first {info}")
