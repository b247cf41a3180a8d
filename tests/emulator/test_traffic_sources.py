"""Other nodes on the simulated bus (ckesc.protocol.traffic, SimWorld.add_source): their frames take
bus time and contend by arbitration, so the queueing a load causes is real in the simulated lane."""

import math

import can
import pytest

from ckesc.emulator import sim_bus
from ckesc.protocol.frame import WireFrame, frame_bits
from ckesc.protocol.traffic import PeriodicFrames, TrafficSource, bus_load


@pytest.fixture
def bus():
    b = can.Bus(interface="ckesc-sim", channel="traffic-test", nodes=[1], receive_own_messages=False)
    yield b
    b.shutdown()
    sim_bus.discard("traffic-test")


def test_a_periodic_source_hands_over_what_is_due_stamped_with_its_due_time():
    src = PeriodicFrames("p", [WireFrame(0x100, b"\x01"), WireFrame(0x100, b"\x02")], period=0.01, until=0.035)
    assert isinstance(src, TrafficSource)
    assert src.next_due() == 0.0
    got = src.take_due(0.025)
    assert [(f.timestamp, f.data) for f in got] == [(0.0, b"\x01"), (0.01, b"\x02"), (0.02, b"\x01")]
    assert src.next_due() == pytest.approx(0.03)
    assert len(src.take_due(1.0)) == 1 and src.next_due() == math.inf


def test_the_host_hears_a_source_and_its_frames_start_on_its_own_clock(bus):
    bus.advance(1.0)
    world = sim_bus.world("traffic-test")
    world.add_source(PeriodicFrames("other-node", [WireFrame(0x1F000, b"\xAA\xBB")], period=0.1, until=0.25))
    heard = []
    while bus.now() < 1.5:
        m = bus.recv(0.5)
        if m is not None and m.arbitration_id == 0x1F000:
            heard.append(round(m.timestamp - 1.0, 6))
    # each frame arrives at its due time plus its frame time (nothing else contends at those instants
    # unless an ESC report does; the ESC's reports at 1 s are not on these instants)
    frame_s = frame_bits(2) / 500000
    assert heard[:3] == pytest.approx([0.0 + frame_s, 0.1 + frame_s, 0.2 + frame_s], abs=1e-3)
    assert world.source_stats["other-node"]["frames"] == 3
    with pytest.raises(ValueError, match="already"):
        world.add_source(PeriodicFrames("other-node", [WireFrame(1, b"")], period=1))


def test_a_loading_source_delays_a_lower_priority_frame_by_arbitration(bus):
    """Half load of high-priority frames: the ESC's reports still go out, later by queueing only."""
    world = sim_bus.world("traffic-test")
    period = frame_bits(8) / 500000 / 0.5  # half the bus, 8-byte frames
    world.add_source(PeriodicFrames("load", [WireFrame(0x10, bytes(8))], period=period, until=2.0))
    bus.advance(2.0)
    st = world.source_stats["load"]
    assert bus_load(int(st["frames"]), 2.0, 500000, dlc=8) == pytest.approx(0.5, rel=0.01)
    assert st["busy_s"] == pytest.approx(1.0, rel=0.01)
