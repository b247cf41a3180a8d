"""The host reads its own CAN adapter over a real connection (R20, issue #36; ckesc/bench/adapter.py): ``ckesc emulate``
in its own process plays the host's adapter on its socketcand hub (ckesc/emulator/hub_can.py): a host frame held in a
bus short is tried through it, the adapter goes bus-off and is restarted after SocketCAN's restart-ms, and each is an
error frame as socketcand carries it (``< error CLASS SEC.USEC >``: the class only, no data bytes). The lane
(BusLane, python-can's stock socketcand client) reads them: a short longer than the adapter's bus-off threshold (32
bit errors, 1.4 ms at 500 kbit/s) while the host has a frame to send is the one-line bench ERROR, saying how the
adapter recovered.

What socketcand cannot carry: an error-passive (an error frame whose class is CAN_ERR_CRTL says which state in its
data, which socketcand drops) and python-can's ``bus.state`` (its socketcand client keeps none). Those are tested in
process, on ``ckesc-sim`` (test_adapter_state.py)."""

from __future__ import annotations

import time

import can
import pytest
from procs import Emulator

from ckesc.bench.lanes import BusFault, BusLane
from ckesc.bench.power import NoPower
from ckesc.bench.profile import DEFAULT_BUS_ERROR_S
from ckesc.emulator.control import control_request
from ckesc.emulator.hub_can import HOST_RESTART_S
from ckesc.session.verdicts import BENCH_FAILED

pytestmark = pytest.mark.realtime  # wall-clock timing with real processes: one at a time under xdist (tests/conftest.py)

QUERY = can.Message(arbitration_id=0x10F28180, data=bytes([0, 0xC0]), is_extended_id=True)  # GET_ESC_ID, broadcast


def _lane(emu: Emulator) -> BusLane:
    lane = BusLane({"interface": "socketcand", "host": "127.0.0.1", "port": emu.port, "channel": "can0",
                    "tcp_tune": True, "ignore_config": True}, NoPower(), timing_error=DEFAULT_BUS_ERROR_S)
    lane.alone = None  # the ESC is up: the adapter's trouble is the bench's
    return lane


def _relay(emu: Emulator, on: bool) -> None:
    """A relay across CANH-CANL closed or opened (``ckesc control bus short on|off``'s request)."""
    control_request(emu.control, {"cmd": "bus_fault", "kind": "short", "on": on})


def _reports_until(lane: BusLane, seconds: float) -> list[can.Message]:
    """What the lane reads for ``seconds`` (a bounded read: an adapter's state shows within it, never a hang)."""
    out, end = [], time.monotonic() + seconds
    while time.monotonic() < end:
        if (msg := lane.recv(0.01)) is not None:
            out.append(msg)
    return out


def _faults_until(lane: BusLane, seconds: float) -> list[can.Message]:
    """What the lane reads for ``seconds``, the bench ERRORs it raises meanwhile left in ``lane.recoveries``."""
    out, end = [], time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            out += _reports_until(lane, end - time.monotonic())
        except BusFault:
            pass
    return out


def test_a_short_that_sends_the_hosts_adapter_bus_off_is_a_one_line_bench_error_saying_it_recovered(tmp_path):
    with Emulator(tmp_path) as emu:
        lane = _lane(emu)
        try:
            assert any(not m.is_error_frame for m in _reports_until(lane, 1.0))  # the ESC reports
            _relay(emu, True)
            lane.bus.send(QUERY)  # held in the short: the adapter tries it
            try:
                with pytest.raises(BusFault) as raised:
                    _reports_until(lane, 2.0)
            finally:
                _relay(emu, False)
            again = _faults_until(lane, 1.0)  # each bus-off until the relay opened is said, then the ESC reports
        finally:
            lane.close()
    line = str(raised.value)
    assert "\n" not in line and isinstance(raised.value, BENCH_FAILED)
    assert line.startswith("the host's CAN adapter went bus-off under this test (SocketCAN error frame 240#00)"), line
    took = int(line.split("it recovered by itself in ")[1].split(" ms")[0])
    assert HOST_RESTART_S * 1000 * 0.9 <= took <= HOST_RESTART_S * 1000 + 200, line  # the hub's restart-ms
    assert "restart-ms" in line and lane.recoveries[0] == line
    assert all(r.startswith("the host's CAN adapter went bus-off") for r in lane.recoveries), lane.recoveries
    assert [m for m in again if not m.is_error_frame]


def test_a_short_while_the_host_sends_nothing_says_nothing(tmp_path):
    """The adapter tries nothing in the short: no error of its own (its receive errors are not played)."""
    with Emulator(tmp_path) as emu:
        lane = _lane(emu)
        try:
            _reports_until(lane, 0.5)
            _relay(emu, True)
            try:
                heard = _reports_until(lane, 0.5)
            finally:
                _relay(emu, False)
        finally:
            lane.close()
    assert not [m for m in heard if m.is_error_frame] and not lane.recoveries
