"""Spec section 4.4.10: MSG_EXP8 (20060) - power-ups, starts and stops, in MSG_EXP mode."""

from __future__ import annotations

import pytest

from .answers import reference
from .telemetry import exp_reports

SECTION = "4.4.10"


@pytest.mark.requirement("4.4.10-T", "4.4.27-T")
def test_exp8_counts_agree_with_maintenance_information(dut):
    """Times1 (power-ups) and Times3 (stops) are the counters 241 option 2 reports. A cross-check of two
    tables: a mismatch breaks one of them (both are cited; which one, the message cannot say)."""

    def log(d):
        runs = d.request("maintenance_information", {"option": 1})
        return (reference(d, "maintenance_information", {"option": 2}, need=("power_ups", "stops")),
                runs.response.fields if runs.response is not None else {})

    frames, (counters, runs) = exp_reports(dut, "msg_exp8", during=log)
    f = frames[-1]
    dut.record.observe("MSG_EXP8", f.fields)
    dut.record.observe("241 option 2", counters)
    dut.record.observe("starts vs 241 option 1 runs", f"{f.fields['starts']} vs {runs.get('runs')}")
    got = {k: f.fields[k] for k in ("power_ups", "stops")}
    expected = {k: counters[k] for k in ("power_ups", "stops")}
    assert got == expected, f"MSG_EXP8 {got}, 241 option 2 {expected}"
