"""The host back on the bus (ckesc/evidence/rejoin.py, R20): the reports an ESC held while nobody at its bit rate
acknowledged them come at once when the host reopens there; that first busy stretch is OBSERVE (no R9 gap, F3 or R19
from it) and R9 resumes after it with R9a-gaps grace. Without :meth:`rejoined` the same trace FAILs, and a report
late after the stretch still does."""

from __future__ import annotations

from ckesc.evidence import BusRules
from ckesc.protocol.frame import frame_bits

from .test_rules import BITRATE, checks, feed, msg1, stated, stream

FRAME_S = frame_bits(8) / BITRATE  # a msg1's bus time (7 bytes plus the tail)


def _held_burst(rules: BusRules, t: float, tids: list[int]) -> tuple[list, float]:
    """The ESC's held msg1s back to back from ``t`` (each stamped at its end); returns the violations and the end."""
    out = []
    for tid in tids:
        t += FRAME_S
        out += feed(rules, msg1(1, tid), t)
    return out, t


def _trace(rules: BusRules, *, rejoin: bool, late: float = 0.0) -> list:
    """20 ms reports; the host leaves and comes back (``rejoin``: the lane says so); 8 held reports whose transfer ids
    skip (the ESC's queue dropped some) at once; then the reports on their grid again, the fourth ``late`` late."""
    t = stated(rules, 1, 0.0)
    out = stream(rules, 1, [t + 0.02 * i for i in range(10)])
    t += 0.02 * 9 + 0.5  # the host away for half a second
    if rejoin:
        rules.rejoined(BITRATE)
    found, end = _held_burst(rules, t, [12, 13, 14, 15, 16, 17, 25, 26])
    out += found
    grid = [end + 0.015 + 0.02 * i for i in range(8)]
    grid[4:] = [g + late for g in grid[4:]]
    return out + stream(rules, 1, grid, start_tid=27)


def test_the_held_burst_after_the_host_rejoined_is_not_judged():
    assert _trace(BusRules(bitrate=BITRATE, complete=True, power_known=True), rejoin=True) == []


def test_without_the_rejoin_the_same_burst_breaks_r9_and_f3():
    found = checks(_trace(BusRules(bitrate=BITRATE, complete=True, power_known=True), rejoin=False))
    assert "report-interval" in found and "transfer-id" in found


def test_a_report_late_after_the_held_burst_is_still_caught():
    found = _trace(BusRules(bitrate=BITRATE, complete=True, power_known=True), rejoin=True, late=0.005)
    assert checks(found) == ["report-interval"] and found[0].rules[0] == "R9"


def test_the_reader_tells_the_held_stretch_and_the_framing_f3_takes_it_alone():
    """The framing section's F3 count (``conformance/test_s4_1_framing.py``) asks the reader which frames were held
    (:meth:`~ckesc.evidence.rejoin.Rejoin.held_stretches`) instead of waiting a broadcast window before its capture:
    the held reports (their transfer ids skip: R20, OBSERVE) and the pairs across them are not counted; the same
    capture without the reader's word FAILs F3, and a skip after the stretch is still found."""
    from conformance.test_s4_1_framing import counting_problems
    from conformance.wire import HeardFrame, Traffic

    def capture(rejoin: bool, after_tids: list[int]) -> tuple[list[HeardFrame], Traffic]:
        rules, heard = BusRules(bitrate=BITRATE, complete=True, power_known=True), []

        def hear(tid: int, t: float) -> None:
            wire = msg1(1, tid)
            feed(rules, wire, t)
            heard.append(HeardFrame(wire.arbitration_id, bytes(wire.data), t))

        t = stated(rules, 1, 0.0)
        for i in range(10):
            hear(i, t + 0.02 * i)
        t += 0.02 * 9 + 0.5
        if rejoin:
            rules.rejoined(BITRATE)
        for tid in (12, 13, 25, 26):  # held, back to back
            t += FRAME_S
            hear(tid, t)
        for i, tid in enumerate(after_tids):
            hear(tid, t + 0.015 + 0.02 * i)
        return heard, Traffic(1, 0, heard, {}, {}, tuple(rules.held_stretches()))

    heard, traffic = capture(True, [27, 28, 29])
    ((first, last),) = traffic.held
    assert heard[9].timestamp < first < heard[10].timestamp and last == heard[13].timestamp  # the first held frame's start
    assert counting_problems(heard, traffic.adjacent)[0] == []
    assert counting_problems(heard)[0], "without the reader's word the held stretch FAILs F3"
    heard, traffic = capture(True, [27, 29, 30])
    assert [h.transfer_id for h, _ in counting_problems(heard, traffic.adjacent)[0]] == [29]
    heard, traffic = capture(False, [27, 28, 29])
    assert traffic.held == () and counting_problems(heard, traffic.adjacent)[0]
