"""A request the host sent while it was alone on the bus (the ESC switched off) is never judged as if sent on time
(R20, issue #36): a real adapter holds it until the ESC's controller is up. With an echo its answer is timed from the
echo (stamped when the frame went out at last); without one the answer's delay is INCONCLUSIVE, saying why, never a
FAIL.

Played by ``ckesc emulate --host-alone hold`` in its own process (it holds the host's frames as SocketCAN does, and
echoes them when they go out), reached through python-can's socketcand client, with its echo and without
(``--no-echo-own``), its power switched through its control channel; and with an echo by the simulated lane with
acknowledgement on (the CAN model holds the frame and echoes it when the ESC's controller takes it)."""

from __future__ import annotations

import pytest
from procs import Emulator

from ckesc.bench import sim_lane
from ckesc.bench.dut import Dut, echo_probe
from ckesc.bench.lanes import BusLane
from ckesc.bench.outcomes import Verdict
from ckesc.bench.power import ControlPower
from ckesc.bench.profile import DEFAULT_BUS_ERROR_S, DutProfile
from ckesc.bench.sim_lane import SimLane
from ckesc.protocol import catalogue as cat
from conformance.answers import check_answer_slot

pytestmark = pytest.mark.realtime  # wall-clock timing with real processes: one at a time under xdist (tests/conftest.py)

BENCHES = {"simulated": True, "emulate-echo": True, "emulate-no-echo": False}  # -> whether the host's frames echo


@pytest.fixture
def bench(monkeypatch, tmp_path):
    made = []

    def start(kind: str) -> Dut:
        if kind == "simulated":
            monkeypatch.setattr(sim_lane, "SIM_CAN", {"ack": True})  # SocketCAN's: acknowledgement, 10 frames of queue
            lane = SimLane(nodes=(1,))
        else:
            emu = Emulator(tmp_path, "--host-alone", "hold", *([] if BENCHES[kind] else ["--no-echo-own"]))
            made.append(emu)
            lane = BusLane({"interface": "socketcand", "channel": "can0", "host": "127.0.0.1", "port": emu.port,
                            "tcp_tune": True}, ControlPower("127.0.0.1", emu.control), timing_error=DEFAULT_BUS_ERROR_S)
            first = lane.recv(5.0)  # the ESC's controller is up (else the hub would hold the probe itself)
            assert first is not None and first.is_rx, first
            assert lane.find_echo(echo_probe()) is BENCHES[kind]
        made.append(lane)
        dut = Dut(lane, DutProfile.load("emulator"), node_id=1)
        assert dut.wait_for("msg1", 3.0) is not None  # the emulated ESC has booted
        return dut

    yield start
    for thing in reversed(made):
        thing.close()


@pytest.mark.parametrize("kind", list(BENCHES))
def test_an_answer_to_a_query_held_while_the_esc_was_off_is_never_failed(bench, kind):
    dut = bench(kind)
    echo = BENCHES[kind]
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
        assert dut.record.measurements and not any("switched off" in line for line in dut.record.inconclusive)
    else:
        assert sent.bus_time is None and not dut.record.measurements
        [line] = dut.record.inconclusive
        assert "not judged: the request was sent while the ESC was switched off" in line and "no echo" in line, line
        assert "\n" not in line


def test_a_request_sent_with_the_esc_up_is_not_held(bench):
    dut = bench("emulate-no-echo")
    sent = dut.broadcast("get_esc_id", {"option": 0}, layout="query")
    assert sent.alone is None and sent.held is None


@pytest.mark.parametrize("kind", list(BENCHES))
def test_a_request_sent_while_the_esc_boots_gets_its_answer(bench, kind):
    """Sent at power-on (the supply's wait for the boot left out), the request is held until the ESC's controller is
    up: the host waits for it that long, then for its answer, never calling it unanswered meanwhile."""
    dut = bench(kind)
    dut.supply.power_off()
    dut.lane.wait_power(0.3)
    dut.lane.power.on()
    ex = dut.request("get_major_configuration", {"option": 0})
    assert ex.sent.alone == "the ESC was switched off" and dut.lane.alone is None
    assert ex.response is not None, "no answer to a request held until the ESC's controller was up"
    assert ex.response.timestamp - ex.sent.host_time > 0.1  # later than request()'s own timeout from the send
