"""Spec section 4.4.14: MSG_EXP12 (20064) - the temperature records, sent once per Get Rec (223); Clear Rec (224)."""

from __future__ import annotations

import pytest

from ckesc.protocol import catalogue as cat

from .answers import reference
from .physics import MAX_PLAUSIBLE_C
from .telemetry import describe_garbled, garbled

SECTION = "4.4.14"

RECORDS = cat.MSG_EXP12_RECORDS  # tail byte 0xC0 | n names record n (R15)
BY_SENSOR = {v: k for k, v in RECORDS.items()}
#: Records of the sensors every ESC has (MSG3 reports them); motor needs a sensor, 0xC5 is reserved
REQUIRED = tuple(BY_SENSOR[s] for s in ("mcu", "mos", "cap"))
#: Test allowance, not protocol: how long the records may take to come after Get Rec
RECORD_WINDOW_S = 0.5
#: Get Rec / Clear Rec payloads tried in turn: the document gives none (R15-payload: OBSERVE)
PAYLOADS = ([], [0x00])


def get_rec(dut) -> tuple[list, list, list[int] | None, object]:
    """Ask for the records with each payload in turn until MSG_EXP12 frames come:
    (decoded records, undecodable MSG_EXP12 frames, the payload that worked, the last answer)."""
    ex = None
    for payload in PAYLOADS:
        t = dut.now()
        ex = dut.request("get_rec", {"payload": payload}, timeout=RECORD_WINDOW_S)
        dut.wait(max(0.0, t + RECORD_WINDOW_S - dut.now()))
        recs = dut.frames("msg_exp12", since=t, source=dut.node_id)
        bad = garbled(dut, "msg_exp12", source=dut.node_id, since=t)
        if recs or bad:
            return recs, bad, payload, ex
    return [], [], None, ex


@pytest.mark.requirement("R15", "4.4.14-T")
def test_get_rec_sends_each_record_once(dut):
    """Get Rec makes the ESC send MSG_EXP12 frames once: 7 payload bytes (T_MAX, TIMES, TIME) + a tail
    byte 0xC1..0xC5 naming the record, each record once (MCU, MOS and CAP at least); the MOS and CAP
    maxima are those 241 option 0 reports; nothing more comes afterwards."""
    recs, bad, payload, ex = get_rec(dut)
    dut.record.observe("Get Rec payload that worked (R15-payload)", payload)
    dut.record.observe("Get Rec answer (R15-payload)", ex.response.fields if ex is not None and ex.response else "none")
    assert not bad, f"MSG_EXP12 frames that do not decode (T_MAX, TIMES, TIME + tail): {describe_garbled(bad)}"
    assert recs, f"no MSG_EXP12 within {RECORD_WINDOW_S} s of Get Rec (223), payloads tried {list(PAYLOADS)}"
    tags = [f.transfer_id for f in recs]
    dut.record.observe("records", {f"0x{0xC0 | f.transfer_id:02X}": f.physical() for f in recs})
    assert all(t in RECORDS for t in tags), (
        f"tail bytes {[hex(f.data[-1]) for f in recs]}: each must name a record, 0xC1..0xC5 (R15)")
    assert len(tags) == len(set(tags)), f"a record sent twice: tail bytes {[hex(f.data[-1]) for f in recs]} (R15: one per record)"
    missing = [RECORDS[t] for t in REQUIRED if t not in tags]
    assert not missing, f"no record for {missing} (tail bytes {[hex(f.data[-1]) for f in recs]})"
    hot = {RECORDS[f.transfer_id]: f.fields["t_max"] for f in recs if f.fields["t_max"] > MAX_PLAUSIBLE_C}
    assert not hot, f"implausible record maxima {hot} degC"
    log = reference(dut, "maintenance_information", {"option": 0}, need=("mos_t_max", "cap_t_max"))
    by_tag = {f.transfer_id: f.fields for f in recs}
    got = {"mos": by_tag[BY_SENSOR["mos"]]["t_max"], "cap": by_tag[BY_SENSOR["cap"]]["t_max"]}
    expected = {"mos": log["mos_t_max"], "cap": log["cap_t_max"]}
    assert got == expected, f"record maxima {got} degC, 241 option 0 says {expected}"
    t = dut.now()
    dut.wait(RECORD_WINDOW_S)
    more = dut.frames("msg_exp12", since=t, source=dut.node_id)
    assert not more, f"{len(more)} more MSG_EXP12 without a new Get Rec ('reported only once')"


@pytest.mark.requirement("R15-payload")
def test_observe_clear_rec(dut):
    """Clear Rec (224, '(retention function)'): whether it is answered and whether the records are
    cleared afterwards, recorded. It clears the DUT's temperature log: the records before are recorded."""
    before, _, payload, _ = get_rec(dut)
    dut.record.observe("records before", {RECORDS.get(f.transfer_id, f.transfer_id): f.fields for f in before})
    ex = dut.request("clear_rec", {"payload": payload if payload is not None else []})
    dut.record.observe("Clear Rec answer", ex.response.fields if ex.response else "none")
    after, _, _, _ = get_rec(dut)
    dut.record.observe("records after", {RECORDS.get(f.transfer_id, f.transfer_id): f.fields for f in after})
    cleared = all(f.fields["times"] == 0 and f.fields["time"] == 0 for f in after) if after else None
    dut.record.observe("cleared (TIMES and TIME zero)", cleared)
