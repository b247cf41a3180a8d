"""The host's link (ckesc/bench/link.py): a request's answer window runs from when the request reached the bus.

A loaded host can stall between reading the lane clock and handing a frame to the adapter (190 ms was seen in
a real-time run under load): the answer then comes well after ``host time + timeout`` though the DUT answered
in time, and the test ERRORed with "no answer". The echo of the request says when it left; the window runs
from there. Played in simulated time: the host's send stalls by advancing the simulated clock first.
"""

from __future__ import annotations

from ckesc.bench.dut import Dut
from ckesc.bench.profile import DutProfile
from ckesc.bench.sim_lane import SimLane

STALL_S = 0.19


class _StallingSend:
    """The lane's bus, whose send() holds the frame back ``STALL_S`` of lane time (a host not scheduled)."""

    def __init__(self, sim) -> None:
        self.sim = sim
        self.stall = False

    def send(self, msg, timeout=None):
        if self.stall:
            self.sim.advance(STALL_S)
        self.sim.send(msg, timeout)

    def __getattr__(self, name):
        return getattr(self.sim, name)


def _dut(lane: SimLane) -> tuple[Dut, _StallingSend]:
    tap = _StallingSend(lane.sim)
    lane.bus = tap
    d = Dut(lane, DutProfile(name="test"), node_id=1)
    d.wait(0.5)  # booted, reporting
    return d, tap


def test_a_request_held_back_by_the_host_is_still_answered():
    lane = SimLane(nodes=(1,))
    try:
        d, tap = _dut(lane)
        tap.stall = True
        ex = d.request("esc_information", {"option": 0})
        assert ex.sent.bus_time is not None and ex.sent.bus_time - ex.sent.host_time >= STALL_S
        assert ex.response is not None, "the answer came in time after the request reached the bus"
        assert ex.delay is not None and 0 <= ex.delay <= 0.064  # measured from the bus time, as ever
    finally:
        lane.close()


def test_no_answer_is_still_no_answer_after_the_bus_time_window():
    lane = SimLane(nodes=(1,))
    try:
        d, tap = _dut(lane)
        tap.stall = True
        ex = d.request("esc_information", {"option": 0}, destination=9)  # no ESC 9: nothing answers
        assert ex.response is None
        assert d.now() >= ex.sent.bus_time + 0.1  # waited the whole window from the bus time
    finally:
        lane.close()
