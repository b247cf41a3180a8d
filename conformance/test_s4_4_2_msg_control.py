"""Spec section 4.4.2: MSG Control (20010) - suspend / resume active reporting, MSG_EXP mode, the answer.

The helpers the report and broadcast modules share with this one are in ``conformance/telemetry.py``
(reports, MSG Control, MSG_EXP capture), ``conformance/answers.py`` (the answer slot timing of R2)
and ``conformance/multi_esc.py`` (the :func:`escs` fixture).
"""

from __future__ import annotations

from typing import Any

import pytest

from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import classify

from . import multi_esc
from .answers import answer_window_s, check_answer_slot, settle, slot_node
from .multi_esc import several_escs
from .settings import changes, listed
from .telemetry import (
    EXP_FRAMES,
    INTERVALS,
    REACT_S,
    REPORTS,
    at_report_phase,
    check_restart,
    check_suspended,
    describe_garbled,
    exp_capture,
    exp_mode,
    garbled,
    interval_s,
    longest_interval_s,
    ms,
    msg_control,
    next_report_start,
    react_s,
    report_starts,
    reported,
    restart_limit_s,
    resume,
)

SECTION = "4.4.2"

COMMANDS = {"suspend": cat.MSG_CONTROL_SUSPEND, "resume": cat.MSG_CONTROL_RESUME, "resume_exp": cat.MSG_CONTROL_RESUME_EXP}
escs = multi_esc.escs  # fixture: several ESCs on one bus, with the run's emulator faults
#: The parameter changes R12 holds back while reporting is suspended (4.4.2-3): every persisted setting's writer. Set ID
#: and Set Baud, limited to the 120 s window (R11) and read back their own way, are checked in their sections
#: (test_set_id_while_suspended_changes_nothing, test_set_baud_while_suspended_changes_nothing).
HELD = tuple(s.writer for s in cat.PERSISTED_SETTINGS if not s.window)


# ------------------------------------------------------------------------------------------ helpers
def _other(codes, current: int) -> int:
    return next(c for c in sorted(codes) if c != current)


def _change(name: str, before: dict) -> tuple[dict[str, Any], dict[str, int]]:
    """A legal request of ``name`` that changes a setting, and the settings it should change."""
    if name == "set_rotation":
        new = _other(cat.spec("set_rotation").response.field("rotation").codes, before["rotation"])
        return {"rotation": new}, {"rotation": new}
    if name == "throttle_select":
        new = _other(cat.spec("throttle_select").response.field("source").codes, before["throttle_source"])
        return {"source": new}, {"throttle_source": new}
    if name == "set_freq":
        lo, hi = cat.REPORT_INTERVAL_RANGE
        new = {k: before[k] for k in INTERVALS}
        new["msg1_interval"] = before["msg1_interval"] + 5 if before["msg1_interval"] + 5 <= hi else max(lo, before["msg1_interval"] - 5)
        return {"option": 1, **new}, new
    if name == "set_led":
        color = before["led_color"] ^ int(cat.LedColor.RED | cat.LedColor.GREEN | cat.LedColor.BLUE)
        return {"option": 0, "color": color, "blink": before["led_blink"]}, {"led_color": color}
    raise KeyError(name)


# ------------------------------------------------------------------------------------------ tests
@pytest.mark.requirement("R2", "4.4.2-4", "4.4.2-T")
@pytest.mark.may_power_cycle  # slot_node: Set ID in a fresh window on a coarse bench
@pytest.mark.parametrize("command", list(COMMANDS))
def test_answer_is_command_zero_in_the_node_slot(dut, command):
    """Every command is answered once: a 20010 message with option 0 and command 0x00000000, from the
    DUT's node id, starting (node_id % 32) x 2 ms after the request and never later than 64 ms. On a bench
    whose error is not smaller than node 1's slot, at a node id whose slot it can tell (slot_node)."""
    with slot_node(dut) as node:
        settle(dut)
        try:
            sent = msg_control(dut, COMMANDS[command])
            dut.wait(answer_window_s(dut))  # a late answer is seen, and measured
            answers = [f for f in dut.frames("msg_control", since=sent.time, source=node)]
            bad = garbled(dut, "msg_control", source=node, since=sent.time)
        finally:
            resume(dut)
        assert not bad, f"MSG Control answer does not decode: {describe_garbled(bad)}"
        assert answers, (f"no answer from node {node} to MSG Control {command} (0x{COMMANDS[command]:08X}) within "
                         f"{ms(answer_window_s(dut))} ms")
        assert len(answers) == 1, f"{len(answers)} answers to one MSG Control command: {answers}"
        a = answers[0]
        assert (a.fields["option"], a.fields["command"]) == (0, cat.MSG_CONTROL_ANSWER), (
            f"[R2 READING] the answer is option {a.fields['option']}, command 0x{a.fields['command']:08X}; "
            f"expected option 0, command 0x{cat.MSG_CONTROL_ANSWER:08X}")
        check_answer_slot(dut, a, sent, node, "MSG Control", "4.4.2-4")


@pytest.mark.requirement("4.4.2-1", "4.4.2-T", "R9a", "R9")
def test_suspend_stops_and_resume_restarts_reporting(dut):
    """0x55555555 stops MSG1/MSG2/MSG3 for as long as it lasts; 0xAAAAAAAA brings each back at once
    (R9a: its first frame within one of its intervals plus a slack; the timer restarted or its old grid kept, the
    gaps up to the second frame are not judged, the next ones are the interval). The resume goes half an MSG1
    interval off the grid MSG1 had before the suspension (a DUT that kept it reports mid-interval)."""
    s = dut.settings()
    longest = max(interval_s(s, w) for w in REPORTS)
    err = dut.lane.timing_error
    try:
        last = next_report_start(dut, "msg1")
        off = msg_control(dut, cat.MSG_CONTROL_SUSPEND)
        dut.wait(2 * longest + err)
        leaked = reported(dut, off.time + err, source=dut.node_id)  # not held against it: react_s()
        assert not leaked, f"{len(leaked)} reports while suspended, first {leaked[0][0]} {ms(leaked[0][1] - off.time)} ms after 0x55555555"
        if last is not None:
            at_report_phase(dut, "msg1", s, last=last)
        on = msg_control(dut, cat.MSG_CONTROL_RESUME)
        check_restart(dut, on.time, s, "0xAAAAAAAA", clock=on.clock, error_ms=on.error * 1000)
    finally:
        resume(dut)


@pytest.mark.requirement("R13", "4.4.2-1")
@pytest.mark.power_cycle
def test_suspension_is_lost_at_power_off(dut):
    """MSG Control suspension is not persisted (R13): after 0x55555555 and a power cycle the ESC
    reports MSG1/MSG2/MSG3 again without being told to resume."""
    s = dut.settings()
    longest = max(interval_s(s, w) for w in REPORTS)
    try:
        off = msg_control(dut, cat.MSG_CONTROL_SUSPEND)
        check_suspended(dut, off.time, s)
        dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
        since = dut.now()
        dut.wait(2 * longest + dut.lane.timing_error)
        back = {n for n, _ in reported(dut, since, source=dut.node_id, names=REPORTS)}
        missing = [w.upper() for w in REPORTS if w not in back]
        assert not missing, (f"no {', '.join(missing)} within {ms(2 * longest)} ms after a power cycle that followed "
                             "0x55555555: the suspension survived power-off (R13: not persisted)")
    finally:
        resume(dut)


@pytest.mark.requirement("4.4.2-1", "4.4.2-2", "4.4.2-4", "R2")
def test_every_esc_answers_in_its_slot_and_obeys(escs):
    """All ESCs on the bus answer each command in their own slot and act on it."""
    nodes = several_escs(escs, "all ESCs")
    longest = max(longest_interval_s(escs, n) for n in nodes)
    settle(escs)
    try:
        for command in ("suspend", "resume"):
            sent = msg_control(escs, COMMANDS[command])
            escs.wait(2 * cat.ANSWER_DELAY_MAX_S)
            for node in nodes:
                answers = escs.frames("msg_control", since=sent.time, source=node)
                assert len(answers) == 1, f"node {node}: {len(answers)} answers to MSG Control {command} (4.4.2-2: all respond)"
                check_answer_slot(escs, answers[0], sent, node, f"MSG Control {command}", "4.4.2-4")
            escs.wait(longest + REACT_S)
            for node in nodes:
                reports = reported(escs, sent.time, source=node, names=REPORTS)
                if command == "suspend":
                    assert not reports, f"node {node} still reports after 0x55555555 (4.4.2-1)"
                else:
                    assert reports, f"node {node} does not report after 0xAAAAAAAA (4.4.2-1)"
    finally:
        resume(escs)


@pytest.mark.requirement("4.4.2-3", "R12")
@pytest.mark.parametrize("name", HELD)
def test_settings_do_not_change_while_suspended(dut, name):
    """While reporting is suspended a change is not applied, neither then nor on resume; the same
    request after resume is (else the DUT ignores it anyway and nothing is shown: INCONCLUSIVE)."""
    if name == "set_led" and not dut.profile.has("led"):
        pytest.skip(f"the DUT profile {dut.profile.name!r} lacks capability 'led'")
    before = dut.settings()
    fields, expected = _change(name, before)
    try:
        off = msg_control(dut, cat.MSG_CONTROL_SUSPEND)
        dut.wait(2 * interval_s(before, "msg1") + REACT_S)
        dut.record.observe("MSG1 after 0x55555555", len(reported(dut, off.time, source=dut.node_id, names=("msg1",))))
        ex = dut.request(name, fields)
        dut.record.observe(f"answer to {name} while suspended", ex.response.fields if ex.response else "none")
        during = dut.settings()
    finally:
        resume(dut)
    after = dut.settings()
    assert not (d := changes(before, during, expected)), f"{name} {listed(fields)} took effect while suspended: {d}"
    assert not (d := changes(before, after, expected)), f"{name} {listed(fields)} sent while suspended took effect on resume: {d}"
    dut.ask(name, fields)
    control = dut.settings()
    if missed := changes(expected, control, expected):
        raise Inconclusive(f"{name} {listed(fields)} does not take effect with reporting on either (wanted -> 242: "
                           f"{missed}): that it is ignored while suspended shows nothing")


@pytest.mark.requirement("4.4.2-T", "R9")
def test_exp_mode_replaces_msg1_to_msg3(dut):
    """0xEEEEEEEE: MSG1..MSG3 stop and MSG_EXP frames come instead; 0xAAAAAAAA brings MSG1 back."""
    frames, bad, start, window = exp_capture(dut)
    names = [f.name for f in frames] + [classify(g.msg.arbitration_id)[4].name for g in bad
                                        if classify(g.msg.arbitration_id)[4] is not None]
    normal = [n for n in names if n in REPORTS]
    exp = [n for n in names if n in EXP_FRAMES]
    dut.record.observe("MSG_EXP frames", sorted(set(exp)))
    assert not normal, f"{len(normal)} MSG1..MSG3 in MSG_EXP mode (first: {normal[0]}); R9: MSG_EXP frames replace them"
    assert exp, f"no MSG_EXP frame in {window:.3f} s after 0xEEEEEEEE"
    end = start + window  # 0xAAAAAAAA follows (exp_capture), and MSG1 within one interval and its slack (R9a)
    if not report_starts(dut, "msg1", end):
        dut.wait(restart_limit_s(dut, dut.settings(), "msg1") + react_s(dut))
    assert report_starts(dut, "msg1", end), "no MSG1 after 0xAAAAAAAA ended MSG_EXP mode"


@pytest.mark.requirement("R9a", "R9")
def test_reports_after_leaving_exp_mode(dut):
    """0xAAAAAAAA after MSG_EXP mode: each of MSG1..MSG3 comes back within one of its intervals plus a slack, and from its
    third frame on at its interval (R9a: the gaps up to the second are not judged)."""
    s = dut.settings()
    last = next_report_start(dut, "msg1")
    with exp_mode(dut) as on:
        dut.wait(longest_interval_s(dut) + react_s(dut))
        if not reported(dut, on.time + react_s(dut), source=dut.node_id, names=EXP_FRAMES):
            raise Inconclusive("no MSG_EXP frame after 0xEEEEEEEE (see test_exp_mode_replaces_msg1_to_msg3): "
                               "leaving MSG_EXP mode cannot be shown")
        if last is not None:  # half an MSG1 interval off the grid MSG1 had (a DUT that kept it reports mid-interval)
            at_report_phase(dut, "msg1", s, last=last)
        off = msg_control(dut, cat.MSG_CONTROL_RESUME)
        check_restart(dut, off.time, s, "0xAAAAAAAA after MSG_EXP mode",
                      silent_is="whether 0xAAAAAAAA resumes reporting is test_exp_mode_replaces_msg1_to_msg3's verdict",
                      clock=off.clock, error_ms=off.error * 1000)


@pytest.mark.requirement("R9-exp")
def test_observe_exp_mode_reporting(dut):
    """Which MSG_EXP frames come in MSG_EXP mode, and how often: recorded."""
    frames, bad, start, window = exp_capture(dut, 3 * longest_interval_s(dut) + REACT_S)
    dut.record.observe("window", f"{ms(window)} ms")
    for name in EXP_FRAMES + REPORTS:
        stamps = [f.timestamp for f in frames if f.name == name]
        if not stamps:
            continue
        mean = (stamps[-1] - stamps[0]) / (len(stamps) - 1) if len(stamps) > 1 else None
        dut.record.observe(name, f"{len(stamps)} frames" + (f", mean interval {ms(mean)} ms" if mean else ""))
    if bad:
        dut.record.observe("undecodable frames", describe_garbled(bad))
    assert any(f.name in EXP_FRAMES for f in frames), "no MSG_EXP frame at all"
