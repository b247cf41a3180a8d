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
