"""The simulated bus as CAN hardware makes it (ckesc/emulator/sim_bus.py, sim_can.py; issue #36, R20): a frame needs
another node's acknowledgement, a lone host holds its frames and meets the ESC with them at its power-up, a full
transmit queue raises ENOBUFS, a short sends transmitters bus-off and they recover; ``ack=False`` is the old bus."""

from __future__ import annotations

import errno
import itertools

import can
import pytest

from ckesc.emulator import sim_bus
from ckesc.protocol import canbus

_channels = itertools.count()


@pytest.fixture
def open_bus():
    opened = []

    def make(**kwargs):
        channel = f"sim-can-{next(_channels)}"
        bus = can.Bus(interface="ckesc-sim", channel=channel, nodes=[1], receive_own_messages=True, ignore_config=True,
                      **kwargs)
        opened.append((bus, channel))
        return bus

    yield make
    for bus, channel in opened:
        bus.shutdown()
        sim_bus.discard(channel)


def _query(n: int = 0) -> can.Message:
    return can.Message(arbitration_id=0x10F28180 + n, data=bytes([0, 0xC0 | n]), is_extended_id=True)


def _drain(bus, seconds: float) -> list[can.Message]:
    out, end = [], bus.now() + seconds
    while (m := bus.recv(max(end - bus.now(), 0.0))) is not None:
        out.append(m)
    return out


def test_a_lone_host_holds_its_frames_until_the_esc_listens(open_bus):
    bus = open_bus()
    bus.advance(0.5)
    _drain(bus, 0.0)
    bus.power_off()
    sent_at = bus.now()
    for n in range(3):
        bus.send(_query(n))
    assert _drain(bus, 0.2) == []  # nobody acknowledges: nothing is sent, not even the echo
    ctl = bus.controller
    assert (ctl.tec, ctl.state, len(ctl)) == (128, canbus.ErrorState.PASSIVE, 3)
    assert bus.state is can.BusState.PASSIVE
    bus.power_on()
    ready = bus.bench.escs[0].state.ready_at
    echoes = [m for m in _drain(bus, 0.5) if not m.is_rx]
    assert [m.arbitration_id for m in echoes] == [_query(n).arbitration_id for n in range(3)]  # in order
    assert echoes[0].timestamp >= ready > sent_at + 0.2  # a held frame's time is its echo's, not its send's
    assert bus.state is can.BusState.ACTIVE and bus.controller.tec < 128


def test_a_full_queue_raises_enobufs(open_bus):
    bus = open_bus()
    bus.advance(0.5)
    bus.power_off()
    for n in range(canbus.DEFAULT_TXQUEUELEN):
        bus.send(_query(n))
    with pytest.raises(can.CanOperationError, match="No buffer space available") as raised:
        bus.send(_query(10))
    assert raised.value.error_code == errno.ENOBUFS


def test_without_acknowledgement_a_lone_frame_goes_out(open_bus):
    bus = open_bus(ack=False)
    bus.advance(0.5)
    bus.power_off()
    bus.send(_query())
    assert len([m for m in _drain(bus, 0.01) if not m.is_rx]) == 1  # its echo: sent though nobody listened


@pytest.mark.parametrize("auto", [True, False])
def test_a_short_sends_the_host_bus_off_and_it_recovers(open_bus, auto):
    bus = open_bus(error_frames=True, auto_recovery=auto)
    bus.advance(0.5)
    _drain(bus, 0.0)
    bus.world.short(0.01)  # 32 tries of 18 to 26 bits: bus-off after 1.4 ms, back 2.8 ms later, and so on
    bus.send(_query())
    errors = [m for m in _drain(bus, 0.003) if m.is_error_frame]
    assert bus.state is can.BusState.ERROR
    assert [m.arbitration_id for m in errors][-1] == canbus.CAN_ERR_BUSOFF | canbus.CAN_ERR_CNT
    assert all(not m.is_extended_id and len(m.data) == canbus.CAN_ERR_DLC for m in errors)
    later = _drain(bus, 0.02)
    if auto:
        assert bus.state is can.BusState.ACTIVE
        assert any(m.is_error_frame and m.data[1] == canbus.CAN_ERR_CRTL_ACTIVE for m in later)
        assert any(not m.is_rx and not m.is_error_frame for m in later)  # the held frame went out after all
    else:
        assert bus.state is can.BusState.ERROR
        bus.restart()
        assert bus.state is can.BusState.ACTIVE
        assert any(not m.is_rx and not m.is_error_frame for m in _drain(bus, 0.01))
