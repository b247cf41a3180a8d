"""The host survives the simulated CAN (issue #36, R20): with acknowledgement on, a full transmit queue and the host's
own bus-off end the test as the bench's failure (:class:`~ckesc.bench.lanes.BusFault`, an ERROR whose one line names
them), never a FAIL or a hang; a frame held while the ESC was off is timed by its echo. The verdict of a BusFault is
told by its type (``ckesc/session/verdicts.py``: ``BENCH_FAILED``)."""

from __future__ import annotations

import can
import pytest

from ckesc.bench import sim_lane
from ckesc.bench.lanes import BusFault
from ckesc.bench.sim_lane import SimLane
from ckesc.protocol import canbus
from ckesc.session.verdicts import BENCH_FAILED


@pytest.fixture
def lane(monkeypatch):
    monkeypatch.setattr(sim_lane, "SIM_CAN", {"ack": True})  # SocketCAN's: acknowledgement, 10 frames of queue
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
    assert "10 frame(s) waiting: nobody acknowledged them" in line
    assert isinstance(raised.value, BENCH_FAILED)


def test_a_burst_past_the_queue_is_a_bus_fault_too(lane):
    """The ESC listens, but eleven frames at one instant do not fit (as a host faster than the bus meets SocketCAN)."""
    with pytest.raises(BusFault, match=r"ERROR-ACTIVE, TEC 0, 10 frame\(s\) waiting: sent faster than the bus carries them"):
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
