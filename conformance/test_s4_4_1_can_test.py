"""Spec section 4.4.1: CAN Test (20000) - bus test mode: counting frames instead of every other report."""

from __future__ import annotations

import pytest

from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat

from . import multi_esc
from .multi_esc import several_escs
from .telemetry import (
    EXP_FRAMES,
    REACT_S,
    REPORTS,
    at_report_phase,
    check_restart,
    check_suspended,
    longest_interval_s,
    ms,
    msg_control,
    next_report_start,
    reported,
    resume,
)

SECTION = "4.4.1"
escs = multi_esc.escs  # fixture: several ESCs on one bus, with the run's emulator faults

COUNT_MODULO = cat.spec("can_test").layouts[0].field("count").mask + 1  # "accumulated cyclically" (4.4.1-2)


def can_test(dut, option: int, count: int = 0):
    return dut.broadcast("can_test", {"option": option, "count": count})


def _window(dut, node: int | None = None) -> float:
    """Long enough for every report of the node to have come at least once (and CAN Test frames to
    come several times)."""
    return longest_interval_s(dut, node) + 2 * REACT_S


def _test_frames(dut, since: float, node: int) -> list:
    return [f for f in dut.frames("can_test", since=since + REACT_S, source=node)]


def _check_counting(dut, frames: list, node: int) -> None:
    """R16: option 0x00, the count one more than the previous frame's (cyclically)."""
    assert frames, f"node {node}: no CAN Test frame after 0xAA (4.4.1-2)"
    if len(frames) < 2:
        raise Inconclusive(f"node {node}: one CAN Test frame only: its count cannot be seen to grow")
    options = sorted({f.fields["option"] for f in frames})
    assert options == [cat.CAN_TEST_REPORT], f"node {node}: CAN Test frames with option {options}, expected 0x00 only (R16)"
    counts = [f.fields["count"] for f in frames]
    steps = [(b - a) % COUNT_MODULO for a, b in zip(counts, counts[1:])]
    wrong = [(i, counts[i], counts[i + 1]) for i, st in enumerate(steps) if st != 1]
    assert not wrong, f"node {node}: the count does not grow by one per frame (R16): {wrong[:3]} of {counts[:8]}..."


@pytest.mark.requirement("4.4.1-1", "4.4.1-2", "R16")
@pytest.mark.parametrize("count", [0, COUNT_MODULO - 1], ids=lambda c: f"count=0x{c:08X}")
def test_on_sends_counting_frames_and_nothing_else(dut, count):
    """0xAA (with any count: 'arbitrary value') starts CAN Test frames with option 0 and a count that
    grows by one per frame; no other report comes meanwhile."""
    window = _window(dut)
    late = dut.lane.timing_error  # a report due before 0xAA may start that much after it (react_s)
    on = can_test(dut, cat.CAN_TEST_ON, count)
    try:
        dut.wait(window + late)
        frames = _test_frames(dut, on.time, dut.node_id)
        others = reported(dut, on.time + late, source=dut.node_id)
    finally:
        can_test(dut, cat.CAN_TEST_OFF)
        dut.wait(REACT_S)
    if frames:
        stamps = [f.timestamp for f in frames]
        dut.record.observe("first count", f"0x{frames[0].fields['count']:08X}")
        if len(stamps) > 1:
            dut.record.observe("CAN Test interval", f"{ms((stamps[-1] - stamps[0]) / (len(stamps) - 1))} ms")
    assert not others, (f"{len(others)} other reports in CAN Test mode (4.4.1-2: other reporting is disabled), "
                        f"first {others[0][0]} {ms(others[0][1] - on.time)} ms after 0xAA")
    _check_counting(dut, frames, dut.node_id)


def _enter(dut, state: str) -> None:
    """Put the DUT in a reporting state, and check it is in it (else INCONCLUSIVE: the state to
    return to does not exist)."""
    command = {"suspended": cat.MSG_CONTROL_SUSPEND, "exp": cat.MSG_CONTROL_RESUME_EXP}.get(state, cat.MSG_CONTROL_RESUME)
    sent = msg_control(dut, command)
    if state == "suspended":
        check_suspended(dut, sent.time, dut.settings())
    elif state == "exp":
        window = _window(dut)
        dut.wait(window)
        if not reported(dut, sent.time, source=dut.node_id, names=EXP_FRAMES):
            raise Inconclusive(f"no MSG_EXP frame in {ms(window)} ms of MSG_EXP mode: its return cannot be seen")
    else:
        dut.wait(cat.ANSWER_DELAY_MAX_S)


def _check_state(dut, state: str, since: float, window: float, what: str) -> None:
    """What the DUT reports in ``state`` over the window after ``since`` (already read)."""
    normal = reported(dut, since, source=dut.node_id, names=REPORTS)
    exp = reported(dut, since, source=dut.node_id, names=EXP_FRAMES)
    if state == "normal":
        missing = [w for w in REPORTS if not any(n == w for n, _ in normal)]
        assert not missing, f"{what}: no {', '.join(m.upper() for m in missing)} within {ms(window)} ms, the state before was normal reporting"
        assert not exp, f"{what}: MSG_EXP frames ({exp[0][0]}), the state before was normal reporting"
    elif state == "suspended":
        assert not normal and not exp, f"{what}: {(normal + exp)[0][0]} reported, the state before was suspended (0x55555555)"
    else:
        assert exp, f"{what}: no MSG_EXP frame within {ms(window)} ms, the state before was MSG_EXP mode"
        assert not normal, f"{what}: {normal[0][0]} reported, the state before was MSG_EXP mode"


@pytest.mark.requirement("4.4.1-3", "R16")
@pytest.mark.parametrize("state", ["normal", "suspended", "exp"])
def test_off_returns_to_the_state_before(dut, state):
    """0x55 ends CAN Test mode and the ESC reports as it did before 0xAA: normally, not at all
    (suspended), or MSG_EXP frames."""
    window = _window(dut)
    try:
        _enter(dut, state)
        on = can_test(dut, cat.CAN_TEST_ON)
        dut.wait(window)
        if not _test_frames(dut, on.time, dut.node_id):
            raise Inconclusive("CAN Test mode did not start (0xAA): its end cannot be shown")
        off = can_test(dut, cat.CAN_TEST_OFF)
        dut.wait(window)
        late = _test_frames(dut, off.time, dut.node_id)
        assert not late, f"{len(late)} CAN Test frames after 0x55, the last {ms(late[-1].timestamp - off.time)} ms after it"
        _check_state(dut, state, off.time, window, "after 0x55")
    finally:
        can_test(dut, cat.CAN_TEST_OFF)
        resume(dut)


@pytest.mark.requirement("R9a", "R9")
def test_reports_after_test_mode_ends(dut):
    """0x55 ends CAN Test mode: each of MSG1..MSG3 comes back within one of its intervals plus a slack, and from its third
    frame on at its interval (R9a: the timer restarted or its old grid kept, the gaps up to the second frame
    are not judged)."""
    s = dut.settings()
    try:
        last = next_report_start(dut, "msg1")
        on = can_test(dut, cat.CAN_TEST_ON)
        dut.wait(_window(dut))
        if not _test_frames(dut, on.time, dut.node_id):
            raise Inconclusive("CAN Test mode did not start (0xAA): its end cannot be shown")
        if last is not None:  # half an MSG1 interval off the grid MSG1 had (a DUT that kept it reports mid-interval)
            at_report_phase(dut, "msg1", s, last=last)
        off = can_test(dut, cat.CAN_TEST_OFF)
        check_restart(dut, off.time, s, "CAN Test 0x55",
                      silent_is="whether 0x55 ends test mode is test_off_returns_to_the_state_before's verdict",
                      clock=off.clock, error_ms=off.error * 1000)
    finally:
        can_test(dut, cat.CAN_TEST_OFF)
        resume(dut)


@pytest.mark.requirement("4.4.1-4", "R16")
@pytest.mark.power_cycle
def test_test_mode_is_lost_at_power_off(dut):
    """CAN Test mode does not survive a power cycle: after it the ESC reports normally."""
    window = _window(dut)
    try:
        on = can_test(dut, cat.CAN_TEST_ON)
        dut.wait(window)
        if not _test_frames(dut, on.time, dut.node_id):
            raise Inconclusive("CAN Test mode did not start (0xAA): its loss cannot be shown")
        dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
        since = dut.now()
        dut.wait(window)
        frames = _test_frames(dut, since, dut.node_id)
        assert not frames, f"{len(frames)} CAN Test frames after a power cycle: test mode survived it"
        _check_state(dut, "normal", since, window, "after a power cycle")
    finally:
        can_test(dut, cat.CAN_TEST_OFF)
        dut.wait(REACT_S)


@pytest.mark.requirement("4.4.1-1", "4.4.1-2", "4.4.1-3", "R16")
def test_every_esc_enters_and_leaves_test_mode(escs):
    """The broadcast reaches every ESC: each counts, none reports otherwise; after 0x55 each reports again."""
    nodes = several_escs(escs, "every ESC")
    window = max(_window(escs, n) for n in nodes)
    try:
        on = can_test(escs, cat.CAN_TEST_ON)
        escs.wait(window)
        for node in nodes:
            others = reported(escs, on.time, source=node)
            assert not others, f"node {node}: {others[0][0]} reported in CAN Test mode (4.4.1-2)"
            _check_counting(escs, _test_frames(escs, on.time, node), node)
        off = can_test(escs, cat.CAN_TEST_OFF)
        escs.wait(window)
        for node in nodes:
            assert not _test_frames(escs, off.time, node), f"node {node}: CAN Test frames after 0x55"
            assert reported(escs, off.time, source=node, names=REPORTS), f"node {node}: no report after 0x55 (4.4.1-3)"
    finally:
        can_test(escs, cat.CAN_TEST_OFF)
        resume(escs)
