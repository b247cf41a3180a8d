"""A request the host sent while it was alone on the bus (the ESC switched off) is never judged as if sent on time
(R20, issue #36): a real adapter holds it until the ESC's controller is up. With an echo its answer is timed from the
echo (stamped when the frame went out at last); without one the answer's delay is INCONCLUSIVE, saying why, never a
FAIL.

With an echo: the simulated lane with acknowledgement on (the CAN model holds the frame and echoes it when the ESC's
controller takes it). Without: the real-time emulator holding the host's frames as SocketCAN does (``--host-alone
hold``) on python-can's virtual bus, the lane's end opened without its echo (the virtual bus's own echo would come at
the send, not when the emulator lets the frame go), the ESC's power switched by the emulator's own switch."""

from __future__ import annotations

import itertools
import os

import can
import pytest

from ckesc.bench import sim_lane
from ckesc.bench.dut import Dut, echo_probe
from ckesc.bench.lanes import BusLane
from ckesc.bench.outcomes import Verdict
from ckesc.bench.power_control import PowerControl
from ckesc.bench.profile import DEFAULT_BUS_ERROR_S, DutProfile
from ckesc.bench.sim_lane import SimLane
from ckesc.emulator.emulated_bench import EmulatedBench
from ckesc.emulator.realtime import RealtimeEmulator
from ckesc.protocol import catalogue as cat
from conformance.answers import check_answer_slot

pytestmark = pytest.mark.realtime  # wall-clock timing with real threads: one at a time under xdist (tests/conftest.py)

_channels = itertools.count()


class EmulatorSwitch(PowerControl):
    """The in-process real-time emulator's own power switch."""

    name = "emulator switch"

    def __init__(self, emu: RealtimeEmulator) -> None:
        self.emu = emu

    def off(self) -> None:
        self.emu.power_off()

    def on(self) -> None:
        self.emu.power_on()


@pytest.fixture
def bench(monkeypatch):
    made = []

    def start(echo: bool) -> Dut:
        if echo:
            monkeypatch.setattr(sim_lane, "SIM_CAN", {"ack": True})  # SocketCAN's: acknowledgement, 10 frames of queue
            lane = SimLane(nodes=(1,))
            made.append((None, lane))
            return _dut(lane)
        channel = f"ckesc-held-{os.getpid()}-{next(_channels)}"
        emu_bus = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True, ignore_config=True)
        emu = RealtimeEmulator(EmulatedBench((1,)), bus=emu_bus, own_bus=True, host_alone="hold").start()
        lane = BusLane({"interface": "virtual", "channel": channel, "receive_own_messages": echo, "ignore_config": True},
                       EmulatorSwitch(emu), timing_error=DEFAULT_BUS_ERROR_S)
        made.append((emu, lane))
        assert lane.find_echo(echo_probe()) is echo
        return _dut(lane)

    yield start
    for emu, lane in made:
        lane.close()
        if emu is not None:
            emu.close()


def _dut(lane) -> Dut:
    dut = Dut(lane, DutProfile.load("emulator"), node_id=1)
    assert dut.wait_for("msg1", 3.0) is not None  # the emulated ESC has booted
    return dut


@pytest.mark.parametrize("echo", [True, False], ids=["echo", "no-echo"])
def test_an_answer_to_a_query_held_while_the_esc_was_off_is_never_failed(bench, echo):
    dut = bench(echo)
    dut.supply.power_off()
    dut.lane.wait_power(0.3)
    sent = dut.broadcast("get_esc_id", {"option": 0}, layout="query")
    assert sent.alone == "the ESC was switched off"
    dut.wait(0.2)  # held meanwhile (read: an echo would come when it goes out)
    on = dut.supply.power_on()
    assert dut.lane.alone is None  # the ESC reports again: it acknowledges the host's frames
    reply = dut.wait_for("get_esc_id", 2 * cat.ANSWER_DELAY_MAX_S, where=lambda f: f.layout.name == "reply")
    if reply is None:  # (it may have answered before its reports: read what came)
        reply = next((f for f in dut.frames("get_esc_id", since=sent.host_time, source=1) if f.layout.name == "reply"), None)
    assert reply is not None, "the emulated ESC did not answer the query it met at its power-up"
    assert reply.timestamp - sent.host_time > on - sent.host_time > cat.ANSWER_DELAY_MAX_S  # late, from the send
    check_answer_slot(dut, reply, sent, 1, "GET_ESC_ID query held while the ESC was off", "4.4.3-4")
    failed = [m for m in dut.record.measurements if m.verdict == Verdict.FAIL]
    assert not failed, failed
    if echo:  # timed from the echo: when the frame went out at last, as the ESC's controller came up
        assert sent.bus_time is not None and sent.bus_time >= on and sent.held is None
        assert not dut.record.inconclusive and dut.record.measurements
    else:
        assert sent.bus_time is None and not dut.record.measurements
        [line] = dut.record.inconclusive
        assert "not judged: the request was sent while ESC was switched off" in line and "no echo" in line, line
        assert "\n" not in line


def test_a_request_sent_with_the_esc_up_is_not_held(bench):
    dut = bench(False)
    sent = dut.broadcast("get_esc_id", {"option": 0}, layout="query")
    assert sent.alone is None and sent.held is None
