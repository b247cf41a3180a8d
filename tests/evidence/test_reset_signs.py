"""The one reset bookkeeping (R19, R17: :class:`ckesc.evidence.resets.ResetSigns`) that the bus rules, the soak and the
R17 tests (``conformance/resets.py``) keep. Where their definitions disagreed (issue #35), these say which reading
won: a transfer id that skips without a gap longer than a restart may take (R9a's limit) is F3's, not a reset; the
power-up count is a u16, and 65535 then 0 is a power-up."""

from __future__ import annotations

import json
import subprocess
import sys
from types import SimpleNamespace

import pytest

from ckesc.evidence.resets import POWER_UPS, RUN_TIME, ResetSigns
from ckesc.evidence.rules import BusRules
from ckesc.protocol import catalogue as cat
from ckesc.protocol import judgements as jd
from ckesc.protocol.frame import Decoder
from ckesc.soak.monitor import Monitor
from ckesc.soak.watch import WatchConfig
from conformance.resets import reset_signs

from .test_resets import stream_for
from .traffic import BITRATE, ScriptedHost

MSG1 = 0.020


def reports(signs: ResetSigns, pairs, interval: float = MSG1) -> list:
    """Each (time, transfer id) of MSG1 fed: (the sign or None, whether its counter started again)."""
    return [(signs.report("msg1", t, tid, interval), signs.restarted) for t, tid in pairs]


def test_a_counter_that_counts_on_or_skips_lost_reports_did_not_restart():
    signs = ResetSigns()
    assert reports(signs, [(0.0, 30), (0.02, 31), (0.04, 0), (0.10, 3)]) == [(None, False)] * 4  # a wrap; two lost


def test_a_counter_that_starts_again_restarted_and_is_a_reset_only_after_a_gap_beyond_r9a():
    signs = ResetSigns()
    (_, _), (within, restarted) = reports(signs, [(0.0, 7), (0.02, 0)])
    assert within is None and restarted  # R9a's first report after a restart; no gap, so no reset
    (sign, restarted), = reports(signs, [(0.30, 5)])
    assert restarted and sign is not None and sign.rule == "R19" and "msg1 stopped for 280.0 ms" in sign.text


def test_the_bench_error_and_the_dut_jitter_widen_the_restart_limit_and_judge_false_only_keeps():
    limit = jd.r9a_limit_s(MSG1)
    assert reports(ResetSigns(), [(0.0, 7), (limit + 0.002, 0)])[1][0] is not None
    assert reports(ResetSigns(error=0.001, jitter=0.001), [(0.0, 7), (limit + 0.002, 0)])[1][0] is None
    signs = ResetSigns()
    assert signs.report("msg1", 0.0, 7, MSG1) is None and signs.report("msg1", 0.3, 0, MSG1, judge=False) is None
    assert signs.restarted and signs.report("msg1", 0.32, 1, MSG1) is None  # compared with the one kept


def test_241_counters_with_the_bench_error_given_once():
    signs = ResetSigns(error=0.5)
    assert signs.counter(RUN_TIME, 10, 0.0) is None
    assert signs.counter(RUN_TIME, 17, 5.0) is None  # 5 s + 1 count + 2 x 0.5 s: both readings' stamps
    assert ResetSigns().counter(RUN_TIME, 10, 0.0) is None
    assert signs.counter(RUN_TIME, 3, 6.0).text.startswith("the run time (241 option 1) went back")
    assert signs.counter(POWER_UPS, 7, 0.0) is None and signs.counter(POWER_UPS, 8, 2.0) is not None
    assert signs.last(POWER_UPS).value == 8 and signs.last(RUN_TIME).value == 3
    with pytest.raises(ValueError, match="not one a reset shows in"):
        signs.counter("stops", 1, 0.0)


def test_one_reset_is_counted_once_however_many_signs_show_it():
    """MSG1's and MSG2's gaps across one boot, then the power-up count grown by one: one reset (``same`` for the
    second and third sign); a second reset later, and a count grown by two across both: two, the second new."""
    signs = ResetSigns()
    assert signs.counter(POWER_UPS, 7, 0.0) is None
    for key, interval, t0 in (("msg1", MSG1, 0.001), ("msg2", 0.1, 0.003)):
        signs.report(key, t0, 9, interval)
    assert signs.report("msg1", 0.30, 0, MSG1) is not None and not signs.same and signs.resets == 1
    assert signs.report("msg2", 0.31, 0, 0.1) is not None and signs.same and signs.resets == 1
    assert signs.counter(POWER_UPS, 8, 1.0) is not None and signs.same and signs.resets == 1
    assert signs.report("msg1", 0.32, 1, MSG1) is None and signs.report("msg1", 5.0, 0, MSG1) is not None
    assert not signs.same and signs.resets == 2  # a silence of its own: another reset
    assert signs.counter(POWER_UPS, 10, 6.0) is not None and not signs.same and signs.resets == 3  # one more unseen
    assert signs.counter(RUN_TIME, 50, 6.1) is None and signs.counter(RUN_TIME, 2, 7.0) is not None
    assert not signs.same and signs.resets == 4  # gone back with no reset shown since its last reading


# ------------------------------------------------------------------------------------------ the R17 tests' reading
def dut(error: float = 0.0, jitter: float = 0.0):
    return SimpleNamespace(lane=SimpleNamespace(timing_error=error), profile=SimpleNamespace(jitter_s=jitter))


def msg1(*pairs):
    return [SimpleNamespace(name="msg1", timestamp=t, transfer_id=tid) for t, tid in pairs]


def test_r17_a_transfer_id_that_skips_on_time_is_no_reset():
    """The R17 tests called any transfer id jump a reset; R19's reading (and the bus rules', the soak's) wants a gap
    longer than a restart may take with it. A skip on time is F3's (the bus rules judge it in every test)."""
    assert reset_signs(dut(), msg1((0.0, 5), (0.02, 6), (0.04, 9), (0.06, 10)), MSG1) == []
    assert reset_signs(dut(), msg1((0.0, 5), (0.02, 6), (0.5, 7)), MSG1) == []  # a stall counting on: R9's
    [sign] = reset_signs(dut(), msg1((0.0, 5), (0.02, 6), (0.3, 0)), MSG1)
    assert "came back with transfer id 0 after 6" in sign and sign.endswith("the ESC reset")


def test_r17_the_power_up_count_wraps_and_a_wrap_is_a_power_up():
    """241's power-up count is a u16: 65535 then 0 is one power-up (a reading that asks whether the count grew,
    after > before, misses it), and an unmoved count across the wrap's width is none."""
    assert reset_signs(dut(), [], MSG1, ups=(0xFFFF, 0xFFFF)) == []
    [sign] = reset_signs(dut(), [], MSG1, ups=(0xFFFF, 0))
    assert "went from 65535 to 0" in sign
    assert reset_signs(dut(), [], MSG1, ups=(None, 3)) == []  # not read before: nothing to compare


def test_r17_foreign_traffic_on_an_esc_whose_transfer_ids_are_stuck_fails_f3_not_as_a_reset(tmp_path):
    """End to end, the reading that lost: on transfer_id_stuck (an F3 fault: reports on time, their transfer ids never
    counting) the foreign-traffic test said "MSG1 stopped for 20.0 ms and went on with transfer id 0 after 0 (a
    reset)", an R17 failure for F3's defect. Now its own check holds and the bus rules fail it on F3."""
    test = "conformance/test_robustness_r17_foreign.py::test_foreign_traffic_is_ignored"
    done = subprocess.run([sys.executable, "-m", "ckesc", "run", "-q", "--trace-format", "none", "--reports", str(tmp_path),
                           "--emulator-faults", "transfer_id_stuck", test], capture_output=True, text=True, timeout=600)
    results = tmp_path / "latest" / "results.json"
    assert results.is_file(), done.stdout[-3000:] + done.stderr[-3000:]
    [r] = json.loads(results.read_text())["results"]
    assert r["outcome"] == "FAIL" and "F3" in r["bus_rules"], r
    assert "reset" not in r["message"], r["message"]


# ------------------------------------------------------------------------------------------ one trace, three consumers
def test_one_trace_the_same_reset_for_the_bus_rules_the_soak_and_the_r17_tests():
    """The emulator's watchdog reset after 5 s of stream, heard once: the bus rules report each sign (MSG1's gap, MSG2's,
    the power-up count), the soak's resets watch one finding with the first sign's words and time (the others counted
    with it), and the R17 tests' reading of the same MSG1 reports and counts the same words."""
    host = ScriptedHost((1,), ("reset_after_streaming=5",), keep=True)
    host.run.rules = BusRules(bitrate=BITRATE, complete=True, power_known=True)
    try:  # (the host alone: while the ESC reboots its stream waits in its queue, the bus carries no command)
        host.pump(0.5)
        host.request("maintenance_information", {"option": 2}, 1)
        stream_for(5.5)(host)
        host.request("maintenance_information", {"option": 2}, 1)
        host.pump(0.1)
    finally:
        host.close()
    signs = [v for v in host.run.violations if v.check == "reset"]
    assert [v.message.split(": ", 1)[1].split()[0] for v in signs] == ["msg1", "msg2", "the"], signs

    intervals = {r: cat.DEFAULT_REPORT_INTERVALS[f] * cat.INTERVAL_UNIT_S for r, f in cat.REPORT_INTERVAL_FIELDS.items()}
    monitor = Monitor(WatchConfig(node_id=1, host_node=0, intervals=intervals), t0=0.0)
    for msg in host.run.messages:
        monitor.feed(msg)
    monitor.close(host.run.messages[-1].timestamp)
    [found] = monitor.findings
    assert found.watch == "resets" and found.t == signs[0].timestamp
    assert signs[0].message == f"a reset the host did not make: {found.message}"
    assert monitor.resets.statistics()["signs_of_resets_found"] == len(signs) - 1

    decoder = Decoder()
    heard = [(m.timestamp, f) for m in host.run.messages if (f := decoder.decode(m)).source == 1]
    msg1 = [SimpleNamespace(name=f.name, timestamp=t, transfer_id=f.transfer_id) for t, f in heard if f.name == "msg1"]
    ups = [f.fields["power_ups"] for _, f in heard if f.name == "maintenance_information"]
    shown = reset_signs(dut(), msg1, intervals["msg1"], ups=(ups[0], ups[-1]))
    assert shown == [f"{found.message}: the ESC reset", signs[-1].message.split(": ", 1)[1] + ": the ESC reset"], shown
