"""The host survives the simulated CAN (issue #36, R20): the lane's SocketCAN defaults (acknowledgement, a FIFO queue
of 10); a burst of more than the queue waits for room while the bus carries it; a queue nobody empties and the host's
own bus-off end the test as the bench's failure (:class:`~ckesc.bench.lanes.BusFault`, an ERROR whose one line names
them), never a FAIL or a hang; a frame held while the ESC was off is timed by its echo. The verdict of a BusFault is
told by its type (``ckesc/session/verdicts.py``: ``BENCH_FAILED``)."""

from __future__ import annotations

import can
import pytest

from ckesc.bench import sim_lane
from ckesc.bench.lanes import BusFault, room_wait_s
from ckesc.bench.sim_lane import SimLane
from ckesc.protocol import canbus
from ckesc.protocol.frame import frame_bits, new_wire
from ckesc.protocol.traffic import PeriodicFrames
from ckesc.session.verdicts import BENCH_FAILED


@pytest.fixture
def lane():
    assert sim_lane.SIM_CAN == {}  # the lane's bus as ckesc-sim opens it: SocketCAN's defaults
    lane = SimLane(nodes=(1,))
    lane.wait_power(0.5)
    while lane.recv(0) is not None:
        pass
    yield lane
    lane.close()


def _query(n: int) -> can.Message:
    return can.Message(arbitration_id=0x10F28180, data=bytes([0, 0xC0 | n]), is_extended_id=True)


def test_a_full_queue_is_a_bus_fault_naming_it(lane):
    lane.sim.power_off()
    for n in range(canbus.DEFAULT_TXQUEUELEN):
        lane.bus.send(_query(n))
    lane.wait_power(0.1)
    with pytest.raises(BusFault) as raised:
        lane.bus.send(_query(10))
    line = str(raised.value)
    assert "\n" not in line and "No buffer space available" in line and "ERROR-PASSIVE" in line
    # waited for room as long as a queue of 10 may take (lane.dut_boot_s 0 here: no DUT boot time declared)
    assert f"10 frame(s) waiting after {room_wait_s(lane.bitrate) * 1000:.3f} ms: nobody acknowledged them" in line
    assert isinstance(raised.value, BENCH_FAILED)


def test_a_burst_past_the_queue_waits_for_room_and_goes_in_order(lane):
    """The ESC listens: the eleventh frame at one instant waits until the first has left the queue (as a careful host
    on SocketCAN retries ENOBUFS), then every frame is on the bus in the order sent."""
    t0 = lane.now()
    for n in range(canbus.DEFAULT_TXQUEUELEN + 1):
        lane.bus.send(_query(n))
    first_end = t0 + frame_bits(2) / lane.bitrate
    assert lane.now() == pytest.approx(first_end)  # the eleventh went in as the first was acknowledged
    echoes = []
    while (msg := lane.recv(0.01)) is not None:
        if not msg.is_rx:
            echoes.append(msg.data[1] & 0x1F)
    assert echoes == list(range(canbus.DEFAULT_TXQUEUELEN + 1))


def test_a_burst_that_the_bus_does_not_carry_in_time_is_a_bus_fault(lane):
    """A queue that stays full longer than :func:`~ckesc.bench.lanes.room_wait_s` (here a node that takes the bus with
    frames of a higher priority than the host's) is the bench's failure, naming the wait."""
    frame = new_wire((0x00000001, bytes(8), 0.0, True))  # priority 0: above every frame of the host's
    lane.sim.world.add_source(PeriodicFrames("babbler", [frame], period=frame_bits(8) / lane.bitrate / 2))
    with pytest.raises(BusFault, match=r"ERROR-ACTIVE, TEC 0, 10 frame\(s\) waiting after 26\.\d+ ms: sent faster than the bus"):
        for n in range(canbus.DEFAULT_TXQUEUELEN + 1):
            lane.bus.send(_query(n))


def test_the_hosts_bus_off_is_a_bus_fault(lane):
    lane.sim.world.short(0.01)
    lane.bus.send(_query(0))
    with pytest.raises(BusFault, match=r"^the host's CAN controller is bus-off \(TEC 256, 1 time\(s\)"):
        for _ in range(100):  # a bounded read: the fault shows within the short, never a hang
            lane.recv(0.0005)


def test_a_held_frame_is_timed_by_its_echo(lane):
    lane.sim.power_off()
    sent_at = lane.now()
    lane.bus.send(_query(1))
    lane.wait_power(0.2)
    lane.sim.power_on()
    ready = lane.sim.bench.escs[0].state.ready_at
    echo = None
    while echo is None and (msg := lane.recv(0.5)) is not None:
        echo = msg if not msg.is_rx else None
    assert echo is not None and bytes(echo.data) == bytes(_query(1).data)
    assert echo.timestamp >= ready >= sent_at + 0.2
