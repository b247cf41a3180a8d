"""Spec section 4.4.22: Set/Get Freq (214) - the MSG1/MSG2/MSG3 report intervals."""

import pytest

from ckesc.protocol import catalogue as cat
from ckesc.protocol.legality import illegal_cases

from .settings import changes, check_neighbours_kept, listed, neighbours_moved, other_intervals
from .telemetry import R9_GAPS, at_report_phase, check_restart, settle_reports

SECTION = "4.4.22"
INTERVALS = cat.INTERVAL_FIELDS
REPORTS = {v: k for k, v in cat.REPORT_INTERVAL_FIELDS.items()}


def _read(dut):
    return dut.request("set_freq", cat.FREQ_READ)


@pytest.mark.requirement("4.4.22-2", "F4")
def test_read_answers_the_current_settings(dut):
    """A read ignores the values sent and answers the settings in force."""
    before = dut.settings()
    ex = dut.request("set_freq", {"option": 0, "msg1_interval": 77, "msg2_interval": 88, "msg3_interval": 99})
    assert ex.response is not None, "no answer to Set/Get Freq read"
    assert not ex.mismatch, f"answer does not match the request: {ex.mismatch}"
    got = {k: ex.response.fields[k] for k in INTERVALS}
    assert not (d := changes(before, got, INTERVALS)), f"the read answered other intervals than the settings': {d}"
    assert not (d := changes(before, dut.settings())), f"a read changed the settings: {d}"


@pytest.mark.requirement("4.4.22-1", "4.4.22-3", "R9", "R9a", "4.4.5-2", "4.4.6-2")
@pytest.mark.parametrize("values", [(10, 50, 250), (25, 10, 100), (250, 250, 10)], ids=lambda v: "-".join(map(str, v)))
def test_write_sets_the_report_intervals(dut, values):
    """After a legal write every report comes at its new interval (value x 2 ms): the first within the longer of
    its old and new interval plus a slack, the gaps up to the second not judged (R9a), the mean of ten gaps from
    the third on the new interval (R9). The write goes half an MSG1 interval off MSG1's grid."""
    fields = dict(zip(INTERVALS, values))
    before = dut.settings()
    settle_reports(dut)  # no report still due on an interval of before (a previous test's restore)
    at_report_phase(dut, "msg1", before)
    ex = dut.request("set_freq", {"option": 1, **fields})
    assert ex.response is not None, "no answer to Set/Get Freq write"
    assert not (d := changes(fields, ex.response.fields, INTERVALS)), f"the write's answer is not the values written: {d}"
    check_restart(dut, ex.sent.time, fields, "the Set Freq write", gaps=R9_GAPS, old=before, clock=ex.sent.clock,
                  error_ms=ex.sent.error * 1000)


@pytest.mark.requirement("R10", "4.4.22-3")
@pytest.mark.parametrize("case", illegal_cases(cat.spec("set_freq")), ids=lambda c: c.id)
def test_illegal_write_changes_nothing(dut, case):
    """A write with any interval outside 10..250 is ignored as a whole - read back now."""
    before = dut.settings()
    legal = {"msg1_interval": 20, "msg2_interval": 60, "msg3_interval": 200}
    legal = {k: (v if v != before[k] else v + 1) for k, v in legal.items()}  # differs from the current values
    fields = {**legal, case.field: case.value}
    ex = dut.request("set_freq", {"option": 1, **fields})
    dut.record.observe("answer to the illegal write (R10-answer)", ex.response.fields if ex.response else "none")
    changed = changes(before, dut.settings(), (case.field, *INTERVALS))  # the illegal one first
    assert not changed, f"illegal {case.field}={case.value} changed {changed} (R10: ignored, never partly applied)"


ILLEGAL_WRITE = {"msg1_interval": 20, "msg2_interval": 9, "msg3_interval": 200}


def _write_illegal(dut):
    before = dut.settings()
    dut.request("set_freq", {"option": 1, **ILLEGAL_WRITE})
    return before


@pytest.mark.requirement("R10", "4.4.22-3", "4.4.22-6")
@pytest.mark.power_cycle
@pytest.mark.cold_boot(_write_illegal, touches="intervals")
def test_illegal_write_changes_nothing_after_power_cycle(dut, cold_boot):
    """Nothing of an illegal write surfaces after a power cycle either."""
    before = cold_boot()
    changed = changes(before, dut.settings(), INTERVALS)
    assert not changed, f"after the illegal write {listed(ILLEGAL_WRITE)} and a power cycle: {changed} (R10: ignored)"


def _write_intervals(dut):
    fields = {"msg1_interval": 15, "msg2_interval": 45, "msg3_interval": 240}
    dut.ask("set_freq", {"option": 1, **fields})
    return fields


@pytest.mark.requirement("4.4.22-6", "R13", "4.4.22-2")  # read back through Set/Get Freq's read (4.4.22-2)
@pytest.mark.power_cycle
@pytest.mark.cold_boot(_write_intervals, touches="intervals")
def test_intervals_persist_across_power_cycle(dut, cold_boot):
    fields = cold_boot()
    lost = changes(fields, dut.settings(), INTERVALS)
    assert not lost, f"a power cycle changed the intervals written: {lost}"


@pytest.mark.requirement("4.4.22-4")
def test_observe_current_intervals(dut):
    """Factory defaults are 10/50/250; a DUT in the field may differ: recorded, never failed."""
    s = dut.settings()
    dut.record.observe("intervals", {k: s[k] for k in INTERVALS})
    assert (s["msg1_interval"], s["msg2_interval"], s["msg3_interval"]) == (10, 50, 250), "not at factory defaults"


@pytest.mark.requirement("R13", "4.4.22-6", "4.4.21-4", "4.4.23-4", "4.4.22-2", "4.4.28-1")
@pytest.mark.power_cycle
def test_write_leaves_the_other_settings(dut):
    """A Set Freq write rewrites nothing else: the other persisted settings, moved since this power-up, are as they
    were, at once and after a power cycle (a save rewriting a whole flash block can clobber them)."""
    with neighbours_moved(dut, but="intervals") as moved:
        fields = other_intervals(moved)
        dut.ask("set_freq", {"option": 1, **fields})
        check_neighbours_kept(dut, moved, f"Set Freq {listed(fields)}", fields)
