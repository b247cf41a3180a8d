"""The bus rules over emulator traffic: the faultless emulator breaks no rule, and each fault that
breaks a bus rule is caught by that rule, citing a requirement the fault names."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from ckesc.emulator.faults import FAULTS
from ckesc.evidence.live import cause_key, cause_what

from .traffic import scripted_run

NODES = (1, 2, 0x7D)  # 0x7D: a factory-fresh ESC, silent on its own (F7)

#: fault -> the checks its traffic fails (every other fault leaves the bus rules silent).
EXPECTED = {
    "tail_toggle_set": {"tail-byte"},
    "tail_not_single_frame": {"tail-byte"},
    "transfer_id_stuck": {"transfer-id"},
    "response_transfer_id_wrong": {"response-match"},
    "response_to_broadcast": {"response-match"},
    "response_as_request": {"frame-layout"},
    "wrong_priority": {"priority"},
    "response_wrong_priority": {"priority"},
    "reports_at_default_id": {"default-node-reports"},
    "debug_frames_reserved_source": {"reserved-node"},
    # a longer interval also brings the first report after a Set Freq write late (R9a)
    "report_interval_wrong": {"report-interval", "first-report"},
    "report_jitter": {"report-interval"},  # +-30 %: its first reports after a restart fall within R9a's quarter slack here
    "report_restart_late": {"first-report"},
    "msg2_interval_ignores_setting": {"report-interval"},
    "intervals_not_persisted": {"report-interval"},  # the intervals stated before the power cycle are not kept
    "set_freq_read_wrong": {"report-interval"},  # the read answer says other intervals than the reports keep
    # extra MSG1 frames answering throttle break the report cadence (R9) besides 4.4.15-1..4.4.17-1, and
    # the ESC at 0x7D then sends MSG1 (F7): the bus rules name R9 and F7, which the fault does not list
    "throttle_answered": {"report-interval", "default-node-reports"},
    # an interaction fault this script meets: its resume after non-default intervals brings the defaults back (R9)
    "resume_reloads_default_intervals": {"report-interval"},
}
#: Faults whose bus-rule violations cite rules the fault does not list (see above).
CITES_OTHER_RULES = {"throttle_answered"}


def test_faultless_emulator_breaks_no_rule():
    run = scripted_run(NODES)
    assert run.violations == [], "\n".join(map(str, run.violations[:5]))
    s = run.rules.summary()
    assert s["frames"] > 900 and {"1", "2", "0"} <= set(s["nodes"])
    assert s["nodes"]["1"]["intervals"]["msg1"]["count"] > 100
    assert s["nodes"]["1"]["comm_loss"], "the emulator sets the comm-loss flag without throttle (R8)"
    # the DroneCAN probe is a host's frame; the emulator does not answer it without its fault
    assert not [o for o in s["observations"] if o["check"] == "foreign-id"]


@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_each_fault(fault):
    run = scripted_run(NODES, (fault,))
    checks = run.checks
    assert set(checks) == EXPECTED.get(fault, set()), "\n".join(map(str, run.violations[:3]))
    if fault not in CITES_OTHER_RULES:
        for check, rules in checks.items():
            assert rules & set(FAULTS[fault].rules), f"{check} cites {sorted(rules)}, the fault breaks {FAULTS[fault].rules}"
    for v in run.violations:
        assert v.frames and v.message and v.strength in ("SHALL", "READING")
        assert v.subject and v.expected, f"{v.check}: its cause as fields (subject, expected)"


def test_a_cause_is_read_from_the_violations_fields_not_its_message():
    """A violation's cause (its key and its one line) comes from its fields: the message may say anything."""
    run = scripted_run(NODES, ("report_interval_wrong",))
    [v, *_] = [v for v in run.violations if v.check == "report-interval" and v.subject == "msg1"]
    assert v.measured_s is not None and v.expected_s == pytest.approx(0.02)
    what = cause_what(v)
    assert what.startswith(f"MSG1 of node {v.node} every ") and what.endswith(", not 20 ms"), what
    reworded = replace(v, message="something else entirely, 12.5 ms (see above)")
    assert cause_key(reworded) == cause_key(v) and cause_what(reworded) == what
    assert json.loads(json.dumps(v.to_json()))["expected_s"] == v.expected_s, "check-log --json carries the fields"


def test_an_esc_answering_dronecan_is_observed():
    run = scripted_run(NODES, ("dronecan_node_info",))
    (o,) = [o for o in run.rules.summary()["observations"] if o["check"] == "foreign-id" and o["rules"] == ["4.3.1-1"]]
    assert o["node"] == 1 and "foreign message 341" in o["message"]
