"""The host reads its own CAN adapter's state (R20, issue #36; ckesc/bench/adapter.py): a bus-off, or an error-passive
while the ESC is up, is the bench's failure under the test (BusFault: an ERROR, one line naming it), recovered where
the interface can; error-passive while the host is alone on the bus (the ESC off) is what a lone host's frames do, and
a bus fault a test causes on purpose is excused. The real-time lane (BusLane) on ``ckesc-sim``, the python-can
interface this project ships, which plays ``bus.state`` and SocketCAN's error frames: nothing mocked."""

from __future__ import annotations

import itertools
import os
import time

import can
import pytest

from ckesc.bench import adapter
from ckesc.bench.lanes import BenchGone, BusFault, BusLane
from ckesc.bench.power import NoPower
from ckesc.bench.profile import DEFAULT_BUS_ERROR_S
from ckesc.emulator import sim_bus
from ckesc.session.verdicts import BENCH_FAILED

_channels = itertools.count()
QUERY = can.Message(arbitration_id=0x10F28180, data=bytes([0, 0xC0]), is_extended_id=True)


@pytest.fixture
def lane():
    made = []

    def open_lane(**sim) -> BusLane:
        channel = f"ckesc-adapter-{os.getpid()}-{next(_channels)}"
        made.append(channel)
        bus = BusLane({"interface": "ckesc-sim", "channel": channel, "nodes": "1", "error_frames": True,
                       "ignore_config": True, **sim}, NoPower(), timing_error=DEFAULT_BUS_ERROR_S)
        bus.bus.advance(0.5)  # the ESC booted: it acknowledges the host's frames
        return bus

    yield open_lane
    for channel in made:
        sim_bus.discard(channel)


def _read(lane: BusLane, seconds: float = 0.3) -> None:
    end = time.monotonic() + seconds  # a bounded read: what the adapter says shows within it, never a hang
    while time.monotonic() < end:
        lane.recv(0.001)


def _short(lane: BusLane) -> None:
    lane.bus.world.short(0.01)
    lane.bus.send(QUERY)  # tried through the short: 32 bit errors, bus-off


def test_a_bus_off_adapter_that_recovers_by_itself_is_a_bus_fault_naming_both(lane):
    bus = lane()
    _short(bus)
    with pytest.raises(BusFault) as raised:
        _read(bus)
    line = str(raised.value)
    assert "\n" not in line and isinstance(raised.value, BENCH_FAILED)
    assert line.startswith("the host's CAN adapter went bus-off under this test (SocketCAN error frame 240#"), line
    assert "it recovered by itself in" in line and "restart-ms" in line, line
    assert bus.recoveries == [line]
    _read(bus)  # said once: the adapter is back


def test_a_bus_off_adapter_without_automatic_recovery_is_restarted_by_the_lane(lane, monkeypatch):
    monkeypatch.setattr(adapter, "ADAPTER_RECOVERY_S", 0.05)
    bus = lane(auto_recovery=False)
    _short(bus)
    with pytest.raises(BusFault) as raised:
        _read(bus)
    line = str(raised.value)
    assert "did not restart by itself within 0.05 s (no restart-ms?) and the lane restarted it (the interface's " \
           "restart())" in line and "ip link set CHANNEL type can bitrate N restart-ms 100" in line, line
    assert bus.bus.state is can.BusState.ACTIVE


def test_an_adapter_that_stays_bus_off_ends_the_run_saying_how_to_recover_it(lane, monkeypatch):
    monkeypatch.setattr(adapter, "ADAPTER_RECOVERY_S", 0.05)
    bus = lane(auto_recovery=False)
    monkeypatch.setattr(sim_bus.SimEscBus, "restart", None)  # an interface without a restart of its own (SocketCAN's)
    _short(bus)
    with pytest.raises(BenchGone) as raised:
        _read(bus)
    line = str(raised.value)
    assert "\n" not in line and "did not recover within 0.05 s: python-can has no generic restart" in line, line
    assert "restart-ms 100" in line and "type can restart`" in line, line


@pytest.mark.parametrize("alone", [None, "the ESC was switched off"], ids=["esc-up", "host-alone"])
def test_error_passive_is_the_benchs_failure_only_while_the_esc_is_up(lane, alone):
    bus = lane()
    bus.bus.power_off()  # nobody acknowledges the host's frames: its TEC climbs to 128 (the ACK exception keeps it there)
    bus.alone = alone
    bus.bus.send(QUERY)
    if alone is not None:
        _read(bus)
        assert bus.adapter.state.name == "PASSIVE"  # read, and said nothing
        return
    with pytest.raises(BusFault) as raised:
        _read(bus)
    assert str(raised.value).startswith("the host's CAN adapter is error-passive under this test (SocketCAN error "
                                        "frame 204#") and "though the ESC is up" in str(raised.value)


def test_a_bus_fault_the_test_causes_is_excused(lane):
    bus = lane()
    bus.adapter.excuse("the bus fault (short) this test caused", 0.0)
    _short(bus)
    _read(bus)  # bus-off and its recovery within the excuse: nothing said
    assert bus.adapter.state.name == "ACTIVE" and not bus.recoveries
