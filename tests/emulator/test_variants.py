"""The report-timing variants (ckesc/emulator/variants.py, R9a and R9) do what they say, on the sans-IO model
itself with exact due times: every report timer after a resume, CAN Test off and leaving MSG_EXP mode, every
Set Freq timer after a write, and the report jitter (off the grid, never drifting) that the emulated DUT
declares as its profile's jitter_s. Each keeps its first report within R9a's limit, and the fault
'report_restart_late' does not."""

from __future__ import annotations

import pytest

from ckesc.emulator import variants
from ckesc.emulator.model import EscConfig, EscModel
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import classify, encode

BOOT = EscConfig().boot_time  # the first reports at 250 ms, MSG1 every 20 ms, MSG2 100 ms, MSG3 500 ms after
EVENT = 0.4071  # 2.9 ms before MSG1's grid point at 410 ms (and 42.9 ms before MSG2's at 450 ms)


def esc(**config) -> EscModel:
    model = EscModel(EscConfig(node_id=1, **config))
    model.power_on(0.0)
    return model


def run(model: EscModel, until: float) -> list[tuple[float, str]]:
    """(due time, frame name) of everything the ESC sends until ``until``."""
    out = []
    while (due := model.next_deadline()) is not None and due <= until:
        out += [(w.timestamp, classify(w.arbitration_id)[4].name) for w in model.poll(due)]
    return out


def send(model: EscModel, name: str, fields: dict, now: float, **kw) -> list[tuple[float, str]]:
    """Run to ``now``, then the host's frame at ``now``; what the ESC sent before it."""
    before = run(model, now)
    model.receive(encode(name, fields, source=0, transfer_id=0, **kw), now)
    return before


def dues(sent, name: str, since: float, n: int = 3) -> list[float]:
    """The first ``n`` due times of ``name`` at or after ``since``, from ``since``."""
    return [round(t - since, 6) for t, f in sent if f == name and t >= since][:n]


def suspended_then(model: EscModel, event) -> None:
    send(model, "msg_control", {"option": 0, "command": cat.MSG_CONTROL_SUSPEND}, 0.3)
    event(model)


def resume(model):
    suspended_then(model, lambda m: send(m, "msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME}, EVENT))


def can_test_off(model):
    send(model, "can_test", {"option": cat.CAN_TEST_ON, "count": 0}, 0.3)
    send(model, "can_test", {"option": cat.CAN_TEST_OFF, "count": 0}, EVENT)


def leave_exp(model):
    send(model, "msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME_EXP}, 0.3)
    send(model, "msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME}, EVENT)


#: report_timer -> MSG1's first three due times after the event (the grid's next point is 2.9 ms away)
TIMERS = {
    "restart": [0.0, 0.02, 0.04],  # at once, then one interval apart
    "grid": [0.0, 0.0029, 0.0229],  # at once, then the old grid
    "next_tick": [0.0029, 0.0229, 0.0429],  # the old grid's next point
    "one_interval": [0.02, 0.04, 0.06],  # the timer restarted: one full interval later
}


def test_every_report_timer_is_a_listed_freedom():
    assert set(TIMERS) == set(variants.FREEDOMS["report_timer"].choices)


@pytest.mark.parametrize("event", [resume, can_test_off, leave_exp], ids=["resume", "can-test-off", "leaving-exp-mode"])
@pytest.mark.parametrize("timer", list(TIMERS))
def test_each_report_timer_when_reporting_comes_back(timer, event):
    model = esc(report_timer=timer)
    event(model)
    sent = run(model, EVENT + 1.2)
    assert dues(sent, "msg1", EVENT) == TIMERS[timer]
    for name, interval in (("msg1", 0.02), ("msg2", 0.1), ("msg3", 0.5)):
        first = dues(sent, name, EVENT, 1)[0]
        assert first <= interval + 1e-9, (name, first)  # R9a: within one interval (and its slack)


def test_the_late_restart_fault_breaks_r9a():
    model = esc(faults=frozenset({"report_restart_late"}))
    resume(model)
    first = dues(run(model, EVENT + 0.1), "msg1", EVENT, 1)[0]
    assert first == pytest.approx(0.03) and first > cat.restart_limit_s(0.02)


#: set_freq_timer -> MSG2's first three due times after a write from 100 to 20 ms at EVENT (the last MSG2 at
#: 350 ms, the next one due at 450 ms on the old interval)
SET_FREQ_TIMERS = {
    "last_report": [0.0, 0.02, 0.04],  # 350 + 20 ms is past: at once, then 20 ms apart
    "old_deadline": [0.0429, 0.0629, 0.0829],  # the report due at 450 ms first, then 20 ms from it
    "restart": [0.02, 0.04, 0.06],  # one new interval after the write
    "at_once": [0.0, 0.02, 0.04],
}
WRITE = {"option": 1, "msg1_interval": 10, "msg2_interval": 10, "msg3_interval": 250}


def test_every_set_freq_timer_is_a_listed_freedom():
    assert set(SET_FREQ_TIMERS) == set(variants.FREEDOMS["set_freq_timer"].choices)


@pytest.mark.parametrize("timer", list(SET_FREQ_TIMERS))
def test_each_set_freq_timer_after_a_write_to_a_shorter_interval(timer):
    model = esc(set_freq_timer=timer)
    send(model, "set_freq", WRITE, EVENT, kind="request", destination=1)
    got = dues(run(model, EVENT + 0.2), "msg2", EVENT)
    assert got == SET_FREQ_TIMERS[timer]
    assert got[0] <= cat.restart_limit_s(0.1)  # R9a: within the longer of old (100 ms) and new (20 ms), + slack


@pytest.mark.parametrize("timer", list(SET_FREQ_TIMERS))
def test_each_set_freq_timer_after_a_write_to_a_longer_interval(timer):
    """MSG1 from 20 to 100 ms at EVENT (the last at 390 ms, due at 410 ms on the old interval)."""
    model = esc(set_freq_timer=timer)
    send(model, "set_freq", {**WRITE, "msg1_interval": 50}, EVENT, kind="request", destination=1)
    got = dues(run(model, EVENT + 0.4), "msg1", EVENT)
    first = {"last_report": 0.0829, "old_deadline": 0.0029, "restart": 0.1, "at_once": 0.0}[timer]
    assert got == pytest.approx([first, first + 0.1, first + 0.2])
    assert got[0] <= cat.restart_limit_s(0.1)


def test_the_late_restart_fault_after_a_write_is_late_by_the_longer_interval():
    model = esc(faults=frozenset({"report_restart_late"}))
    send(model, "set_freq", WRITE, EVENT, kind="request", destination=1)
    first = dues(run(model, EVENT + 0.2), "msg2", EVENT, 1)[0]
    assert first == pytest.approx(0.15) and first > cat.restart_limit_s(0.1)  # 1.5 x the old 100 ms


@pytest.mark.parametrize("jitter", [0.001, 0.003])
def test_report_jitter_strays_off_the_grid_but_never_drifts(jitter):
    model = esc(report_jitter_s=jitter)
    sent = run(model, BOOT + 3.99)  # the grid points 250 ms .. 4.23 s
    msg1 = [t for t, f in sent if f == "msg1"]
    off = [t - (BOOT + 0.02 * i) for i, t in enumerate(msg1)]
    assert len(msg1) == 200 and max(abs(o) for o in off) <= jitter / 2 + 1e-9  # each within +- half of it
    assert len({round(o, 6) for o in off}) > 100  # really off the grid, at random
    assert min(t - BOOT for t in msg1) >= 0  # never before the first report may come
    gaps = [b - a for a, b in zip(msg1, msg1[1:])]
    assert max(abs(g - 0.02) for g in gaps) <= jitter + 1e-9  # one interval strays by at most the declared jitter
    assert abs((msg1[-1] - msg1[0]) / len(gaps) - 0.02) <= jitter / len(gaps) + 1e-9  # the mean stays exact


def test_report_jitter_never_sends_before_the_event():
    model = esc(report_jitter_s=0.003)
    resume(model)
    assert min(dues(run(model, EVENT + 0.1), "msg1", EVENT - 0.01)) >= 0.01  # restart: at once, not before


def test_the_emulated_dut_declares_its_jitter():
    assert variants.declared({"report_jitter_s": 0.002, "report_timer": "grid"}) == {"jitter_s": 0.002}
    assert variants.FREEDOMS["report_jitter_s"].span[1] <= 0.003


def test_jittered_reports_keep_their_order_behind_one_sent_at_once():
    """report_timer grid with jitter: the old grid's point just after the report sent at once never goes before it
    (the transfer ids stay in order, F3)."""
    for seed in range(20):
        model = EscModel(EscConfig(node_id=1, report_timer="grid", report_jitter_s=0.003, seed=seed))
        model.power_on(0.0)
        send(model, "msg_control", {"option": 0, "command": cat.MSG_CONTROL_SUSPEND}, 0.3)
        send(model, "msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME}, 0.4095)  # 0.5 ms before a point
        got = dues(run(model, 0.6), "msg1", 0.4095, 8)
        assert got == sorted(got) and got[0] >= 0, (seed, got)


@pytest.mark.parametrize("check", ["msg1", "tick", "timer"])
def test_with_jitter_the_comm_loss_flag_shows_on_the_first_msg1_due_after_200ms(check):
    """R8 with report jitter: checked when the (jittered) MSG1 goes out, the flag is on the first MSG1 at or after
    200 ms from the last command, never one interval later."""
    for seed in range(10):
        model = EscModel(EscConfig(node_id=1, report_jitter_s=0.003, comm_loss_check=check, seed=seed))
        model.power_on(0.0)
        run(model, 0.5)
        last = 0.5001
        model.receive(encode("raw_command_14b", {"channels": [0, 0, 0, 0]}, source=0, transfer_id=0), last)
        out = []
        while (due := model.next_deadline()) is not None and due <= last + 0.3:
            out += [(w.timestamp, w.data) for w in model.poll(due) if classify(w.arbitration_id)[4].name == "msg1"]
        flags = [(t, bool(d[5] & 0x20)) for t, d in out]
        after = [(t, flag) for t, flag in flags if t >= last + 0.2]
        assert after[0][1], (seed, after[:2])
        assert not [t for t, flag in flags if flag and t < last + 0.2]
