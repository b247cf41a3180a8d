"""BusLane, the lane of a real python-can bus (SocketCAN, socketcand): its clock and its bit rate.

The lane's clock is the epoch clock the bus stamps frames with, held back where the host is behind
the bus (a loaded machine, a VM); these tests drive it with python-can's ``virtual`` interface
(``preserve_timestamps``: each frame carries the stamp the test gives it, as a kernel stamp would)
and a fake wall clock, so nothing here waits or reads the real time.
"""

from __future__ import annotations

import itertools
import shlex
import socket
import sys
from pathlib import Path
from types import SimpleNamespace

import can
import pytest

from ckesc.bench import lanes
from ckesc.bench.lanes import BusLane
from ckesc.bench.power import NoPower

pytestmark = pytest.mark.realtime  # wall-clock timing with real processes: one at a time under xdist (tests/conftest.py)

_CHANNELS = itertools.count()
EXT = {"is_extended_id": True}


class FakeClock:
    """``time`` as lanes.py sees it: the wall clock is whatever the test sets."""

    def __init__(self, t: float) -> None:
        self.t = t
        self.monotonic_values: list[float] = []

    def time(self) -> float:
        return self.t

    def monotonic(self) -> float:
        return self.monotonic_values.pop(0) if self.monotonic_values else self.t


@pytest.fixture
def clock(monkeypatch) -> FakeClock:
    c = FakeClock(100.0)
    monkeypatch.setattr(lanes, "time", SimpleNamespace(time=c.time, monotonic=c.monotonic))
    return c


@pytest.fixture
def channel() -> str:
    return f"ckesc-test-bus-lane-{next(_CHANNELS)}"


@pytest.fixture
def lane(clock, channel):
    lane = BusLane({"interface": "virtual", "channel": channel, "preserve_timestamps": True}, NoPower(), timing_error=0.15)
    yield lane
    lane.close()


@pytest.fixture
def esc(channel):
    """The DUT's end of the bus: what it sends carries the stamp the test gives it."""
    bus = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
    yield bus
    bus.shutdown()


def frame(arbitration_id: int, timestamp: float) -> can.Message:
    return can.Message(arbitration_id=arbitration_id, data=b"\xc0", timestamp=timestamp, **EXT)


def test_lane_opens_the_bus_with_receive_own_messages(lane):
    assert lane.bus_kwargs["receive_own_messages"] is True  # the host's requests are timed by their echo
    assert lane.clock == "bus timestamp" and lane.timing_error == 0.15


def test_now_is_the_wall_clock_when_the_host_is_not_behind(lane, esc, clock):
    assert lane.now() == 100.0
    esc.send(frame(0x101, 99.5))  # a backlog nobody read: lane time is not dragged back to it
    assert lane.now() == 100.0
    clock.t = 100.25
    assert lane.now() == 100.25


def test_after_a_read_lane_time_does_not_pass_a_frame_already_arrived(lane, esc, clock):
    esc.send(frame(0x101, 100.00))
    esc.send(frame(0x102, 100.05))
    clock.t = 100.5  # the host was descheduled; both frames wait in the socket
    first = lane.recv(0)
    assert (first.arbitration_id, first.timestamp) == (0x101, 100.00)
    assert lane.now() == 100.05  # a deadline at 100.06 is not judged passed before the 100.05 frame is read
    second = lane.recv(0)
    assert (second.arbitration_id, second.timestamp) == (0x102, 100.05)  # the frame now() looked at, in order
    assert lane.now() == 100.5  # nothing more arrived: the wall clock
    assert lane.recv(0) is None


def test_after_a_send_lane_time_does_not_pass_what_arrived_since(lane, esc, clock):
    lane.bus.send(frame(0x100, 100.0))  # the host's request; its echo carries the send's stamp
    esc.send(frame(0x101, 100.02))  # the answer
    clock.t = 100.4  # the host reads the clock late
    assert lane.now() == 100.0  # a window started "now" after the command includes its answer
    assert lane.now() == 100.4  # a hold is for one reading of the clock
    assert [lane.recv(0).arbitration_id for _ in range(2)] == [0x100, 0x101]


def test_a_backlog_from_before_a_send_does_not_hold_lane_time_before_the_send(lane, esc, clock):
    esc.send(frame(0x101, 99.0))
    lane.bus.send(frame(0x100, 100.0))
    clock.t = 100.3
    assert lane.now() == 100.0  # the send's time, not the older backlog's
    assert lane.recv(0).timestamp == 99.0  # the backlog is still read, first


def test_lane_time_never_runs_ahead_of_the_wall_clock(lane, esc, clock):
    lane.bus.send(frame(0x100, 100.0))
    esc.send(frame(0x101, 100.2))  # stamped after the host's clock (another clock's stamp)
    lane.recv(0)  # the echo
    assert lane.now() == 100.0


def test_wait_power_drains_what_a_powered_off_bus_still_shows(lane, esc, clock):
    esc.send(frame(0x101, 100.0))
    esc.send(frame(0x102, 100.1))
    lane.recv(0)
    lane.now()  # looks at (and keeps) the 0x102 frame
    clock.monotonic_values = [0.0, 0.0, 0.0, 1.0]  # two reads inside the 0.3 s, then past it
    lane.wait_power(0.3)
    assert lane.recv(0) is None  # neither the kept frame nor the unread one is handed out after the cycle
    assert lane.now() == clock.t


def test_reopen_runs_the_bitrate_command_and_reopens_at_the_new_rate(lane, esc, clock, tmp_path):
    out = tmp_path / "bitrate"
    lane.bitrate_cmd = shlex.join([sys.executable, "-c", "import sys; open(sys.argv[1], 'w').write(sys.argv[2])",
                                   str(out), "{bitrate}"])
    assert lane.can_change_bitrate
    lane.reopen(1_000_000)
    assert out.read_text() == "1000000"
    assert lane.bitrate == 1_000_000 and lane.bus_kwargs["bitrate"] == 1_000_000
    esc.send(frame(0x101, 100.0))  # the reopened bus is on the same channel, and reads
    assert lane.recv(0).arbitration_id == 0x101


def test_a_failing_bitrate_command_leaves_the_lane_usable_at_the_old_rate(lane, esc):
    lane.bitrate_cmd = shlex.join([sys.executable, "-c", "import sys; sys.exit('no such interface')"])
    old = lane.bitrate
    with pytest.raises(RuntimeError, match=r"bit rate command .* failed \(1\): no such interface"):
        lane.reopen(250_000)
    assert lane.bitrate == old and "bitrate" not in lane.bus_kwargs
    esc.send(frame(0x101, 100.0))
    assert lane.recv(0).arbitration_id == 0x101


def test_socketcan_without_a_bitrate_command_refuses_another_rate(monkeypatch, clock, channel):
    # this kernel may have no SocketCAN: the socketcan bus is a virtual one, BusLane only reads its name
    real_bus = can.Bus
    monkeypatch.setattr(lanes.can, "Bus", lambda **kw: real_bus(**dict(kw, interface="virtual")))
    lane = BusLane({"interface": "socketcan", "channel": channel}, NoPower(), timing_error=0.0)
    try:
        assert not lane.can_change_bitrate  # Set Baud's tests skip, naming --can-bitrate-cmd
        with pytest.raises(RuntimeError, match="--can-bitrate-cmd"):
            lane.reopen(1_000_000)
        lane.reopen(lane.bitrate)  # the same rate: just a reopen
        assert lane.bitrate == lanes.DEFAULT_BITRATE
    finally:
        lane.close()


def test_a_socket_gets_a_receive_buffer_for_a_stalled_host():
    # SocketCAN needs AF_CAN, which this kernel may lack: the same socket option on a UDP socket
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        default = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        granted = lanes.enlarge_receive_buffer(sock)
        assert granted == sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        rmem = Path("/proc/sys/net/core/rmem_max")
        rmem_max = int(rmem.read_text()) if rmem.exists() else 0
        # forced (CAP_NET_ADMIN) the kernel doubles the request; else it is capped at rmem_max (doubled)
        assert granted >= min(lanes.SOCKETCAN_RCVBUF, max(rmem_max, default)), (default, granted, rmem_max)
