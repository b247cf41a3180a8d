"""The explorer's judge reads R8, R9 and R9a as the suite does (issue #28: it now calls ckesc.protocol.judgements).
Each case is one place where the judge and the suite disagreed before, judged as INTERPRETATIONS.md reads it."""

from __future__ import annotations

from ckesc.explore.judge import Params, _comm_fault_expected, _interval_finding
from ckesc.explore.oracle import State

INTERVALS = {"msg1": 0.020, "msg2": 0.100, "msg3": 0.500}


def _state(t: float = 0.0) -> State:
    return State(t, "set_freq", "normal", dict(INTERVALS), 0, "set_freq")


def _r9(stamps: list[float], jitter: float = 0.0) -> list:
    return _interval_finding(_state(), "msg1", stamps, stamps[-1] + 1.0, 0.020, 0.0, Params(jitter=jitter))


def test_a_declared_jitter_enters_the_mean_at_its_two_ends_over_the_gaps():
    """R9 (amended 2026-12-02, as the suite reads it, ``judgements.r9_mean``): the DUT's declared jitter widens the
    mean of n gaps by twice the jitter over n, its two ends only. MSG1 every 21.5 ms instead of 20 over four gaps
    fails with no jitter and with 0.5 ms (1.25 ms of bound); with 50 ms declared the bound over four gaps exceeds a
    quarter of the interval and the mean is not judged (OBSERVE), which the judge says by no finding."""
    stamps = [0.1 + k * 0.0215 for k in range(6)]
    assert _r9(stamps) and _r9(stamps, jitter=0.0005)
    assert not _r9(stamps, jitter=0.050)
    assert not _r9([0.1 + k * 0.020 for k in range(6)], jitter=0.050)


def test_the_mean_is_held_to_the_suite_s_bound_not_one_of_the_judge_s_own():
    """Issue #35 item 2: the judge adds no tolerance of its own. It gave the mean a frame's bus access on top of the
    bench's error (twice a frame over the gaps, 0.1 ms over five); the suite's R9 (``conformance.telemetry``,
    ``judgements.r9_mean`` with the lane's error) does not, and the suite's reading won: MSG1 every 21.05 ms over
    five gaps in simulated time is R9 to both."""
    from ckesc.protocol.judgements import r9_judged, r9_mean

    stamps = [0.1 + k * 0.02105 for k in range(7)]
    assert not r9_mean(r9_judged(stamps), 0.020, error=0.0).ok  # the suite's
    assert [f.requirements for f in _r9(stamps)] == [["R9"]]


def test_the_gap_to_the_third_report_is_judged():
    """R9a-gaps: the gaps up to and including the second report after the event are OBSERVE, the gap from the
    second to the third is R9's (the judge skipped it too, from its ``[2:]``)."""
    assert _r9([0.010, 0.030, 0.055, 0.075, 0.095])  # second to third 25 ms: the mean of three gaps 21.7 ms
    assert not _r9([0.010, 0.035, 0.055, 0.075, 0.095])  # first to second 25 ms: not judged


def test_the_comm_loss_flag_is_never_due_before_200_ms_whatever_the_jitter():
    """R8: set no earlier than 200 ms after the last command. The MSG1 that carries the flag may come late by the
    DUT's jitter, which widens the late edge only (as the suite's test does); the judge widened both."""
    state = State(0.0, "start", "normal", dict(INTERVALS))
    p = Params(jitter=0.010)
    last = 1.0
    assert _comm_fault_expected(last + 0.195, [last], [0.0], state, p) is False
    assert _comm_fault_expected(last + 0.2285, [last], [0.0], state, p) is None  # within one interval + jitter
    assert _comm_fault_expected(last + 0.235, [last], [0.0], state, p) is True


# (a reset across a malformed frame is the reader's, R19 with R17: tests/evidence/test_taken.py)
