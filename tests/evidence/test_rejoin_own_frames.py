"""The host's own frame inside a held burst on a bench without echo (ckesc/evidence/rules.py, R20): stamped by the
host's clock at its send, before the bus took it, it neither counts as a clock jump (within the host clock's stated
error) nor moves the bus's end back, so the burst the ESC held stays one busy stretch (OBSERVE) and no R9 gap is
judged across it."""

from __future__ import annotations

from ckesc.evidence import BusRules
from ckesc.protocol.frame import encode, frame_bits
from ckesc.protocol.ids import HOST_NODE_ID

from .test_rejoin import _held_burst
from .test_rules import BITRATE, feed, stated, stream


def _burst_with_the_hosts_frame(early: float) -> list:
    """The held burst with the host's own query heard in its middle, stamped ``early`` before the frame it follows,
    as a bench without echo stamps it by the host's clock (its send, within the host clock's error)."""
    rules = BusRules(bitrate=BITRATE, complete=True, power_known=True, tolerance=0.002, own_error=0.004)
    t = stated(rules, 1, 0.0)
    out = stream(rules, 1, [t + 0.02 * i for i in range(10)])
    rules.rejoined(BITRATE)
    found, end = _held_burst(rules, t + 0.02 * 9 + 0.5, list(range(12, 18)))
    query = encode("get_esc_id", {"option": 0}, source=HOST_NODE_ID, transfer_id=5, layout="query")
    out += found + feed(rules, query, end - early, own=True)
    found, end = _held_burst(rules, end + frame_bits(len(query.data)) / BITRATE, list(range(18, 24)))
    return out + found + stream(rules, 1, [end + 0.015 + 0.02 * i for i in range(6)], start_tid=24)


def test_the_hosts_own_frame_stamped_by_its_clock_does_not_end_the_held_burst():
    """Without echo the host's frame is stamped when it was sent, before the bus took it: up to the host clock's
    error (not a clock jump), and the bus stays busy until the latest frame's end (an R9 FAIL on a conforming ESC in
    Set Baud's section without echo, in real time, where the host asks while the held reports go)."""
    assert _burst_with_the_hosts_frame(0.0) == []
    assert _burst_with_the_hosts_frame(0.0019) == []  # within the bus stamps' own error
    assert _burst_with_the_hosts_frame(0.003) == []  # beyond it, within the host clock's
