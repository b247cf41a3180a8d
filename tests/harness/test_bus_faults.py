"""Bus faults mid-run (issue #11): a send that raises as a bus-off, full or unplugged adapter's does ends
that test as an ERROR naming the bus state, the lane reopens the bus and the run goes on, or, when the
bus stays gone, the run aborts with its own status (3).

The failing adapters are real python-can interfaces (:mod:`flaky_bus`: socketcand and virtual buses
whose send raises ``can.CanOperationError`` after N frames), registered as python-can registers any
third-party interface: in-process in python-can's table, and for a ``ckesc run`` process through a
``can.interface`` entry point; the DUT is the emulator.
"""

from __future__ import annotations

import itertools
import json
import os
import subprocess
from pathlib import Path

import can
import flaky_bus
import pytest
from procs import CKESC, Emulator
from procs import env as _env

from ckesc.bench import lanes
from ckesc.bench.dut import Dut
from ckesc.bench.lanes import BenchGone, BusFault, BusLane
from ckesc.bench.power import NoPower
from ckesc.bench.profile import DEFAULT_BUS_ERROR_S, DutProfile
from ckesc.emulator.emulated_bench import EmulatedBench
from ckesc.emulator.realtime import RealtimeEmulator

pytestmark = pytest.mark.realtime  # wall-clock timing with real processes: one at a time under xdist (tests/conftest.py)

_channels = itertools.count()


@pytest.fixture
def flaky(monkeypatch):
    """Open a lane on the ``flaky-virtual`` interface (registered here) with the real-time emulator on the
    same virtual channel."""
    monkeypatch.setitem(can.interfaces.BACKENDS, "flaky-virtual", ("flaky_bus", "FlakyVirtual"))
    monkeypatch.setattr(can.util, "VALID_INTERFACES", can.util.VALID_INTERFACES | {"flaky-virtual"})
    monkeypatch.setattr(lanes, "REOPEN_PAUSE_S", 0.05)
    flaky_bus.reset()
    made = []

    def start(fail_after: int, recover: bool = True, full_tries: int = 0) -> Dut:
        channel = f"ckesc-flaky-{os.getpid()}-{next(_channels)}"
        emu_bus = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True, ignore_config=True)
        emu = RealtimeEmulator(EmulatedBench((1,)), bus=emu_bus, own_bus=True).start()
        lane = BusLane({"interface": "flaky-virtual", "channel": channel, "fail_after": fail_after, "recover": recover,
                        "full_tries": full_tries, "ignore_config": True}, NoPower(), timing_error=DEFAULT_BUS_ERROR_S)
        made.append((emu, lane))
        dut = Dut(lane, DutProfile.load("emulator"), node_id=1)
        assert dut.wait_for("msg1", 3.0) is not None  # the emulated ESC has booted
        return dut

    yield start
    for emu, lane in made:
        try:
            lane.close()
        except Exception:  # noqa: BLE001 - a lane whose bus is gone may not close cleanly
            pass
        emu.close()
    flaky_bus.reset()


def test_a_send_that_raises_is_a_bus_fault_naming_the_state_and_the_lane_reopens(flaky):
    dut = flaky(fail_after=1)
    dut.ask("set_freq", {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0})
    with pytest.raises(BusFault, match=r"CanOperationError: flaky: transmit failed, the controller is bus-off; "
                                       r"bus state ERROR\); the lane reopened it"):
        dut.ask("set_freq", {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0})
    assert len(dut.lane.recoveries) == 1 and "bus state ERROR" in dut.lane.recoveries[0]
    # the reopened bus works: the DUT answers again
    assert dut.ask("set_freq", {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0})["msg1_interval"] == 10


def test_a_full_queue_that_drains_is_waited_for_and_the_frame_goes(flaky):
    """SocketCAN's ENOBUFS (a burst of more than the queue): the lane tries again as the queue drains, the test's
    frame goes and is answered; no fault, no reopening."""
    dut = flaky(fail_after=1, full_tries=5)
    read = {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0}
    dut.ask("set_freq", read)
    assert dut.ask("set_freq", read)["msg1_interval"] == 10  # (its first 5 tries met a full queue)
    assert dut.lane.recoveries == []


def test_a_queue_that_stays_full_is_a_bus_fault_after_the_wait(flaky):
    dut = flaky(fail_after=1, full_tries=10**9)
    read = {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0}
    dut.ask("set_freq", read)
    with pytest.raises(BusFault, match=r"CanOperationError: Failed to transmit: No buffer space available"):
        dut.ask("set_freq", read)


def test_a_throttle_stream_whose_send_fails_ends_the_test_at_its_next_read(flaky):
    dut = flaky(fail_after=20)
    dut.throttle_stream("raw_command_12b", {"channels": [0] * 4, "group": 0}, 0.0025)
    with pytest.raises(BusFault, match="bus-off"):
        dut.wait(1.0)  # the stream's 20th frame fails in its thread; the test's next read says so
    dut.stop_throttle()
    assert dut.reports_heard(0.1) > 0  # the reopened bus reads


def test_a_bus_that_cannot_be_reopened_is_bench_gone(flaky):
    dut = flaky(fail_after=0, recover=False)
    with pytest.raises(BenchGone, match=r"the CAN bus failed .*bus-off.* could not be reopened \(3 tries: "
                                        r"CanInitializationError: flaky: no such device"):
        dut.broadcast("get_esc_id", {"option": 0}, layout="query")


# ------------------------------------------------------------------------------------------ ckesc run
def _registered(tmp: Path) -> dict[str, str]:
    """The environment of a ``ckesc run`` in which python-can finds the ``flaky`` interface the way it
    finds any third-party one: a ``can.interface`` entry point of an installed distribution."""
    dist = tmp / "site" / "flaky_bus-0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: flaky-bus\nVersion: 0\n")
    (dist / "entry_points.txt").write_text("[can.interface]\nflaky = flaky_bus:FlakySocketcand\n")
    env = _env(tmp)
    env["PYTHONPATH"] = os.pathsep.join([str(tmp / "site"), str(Path(flaky_bus.__file__).parent),
                                         env.get("PYTHONPATH", "")])
    return env


def _run(tmp: Path, port: int, *config: str) -> tuple[subprocess.CompletedProcess, dict, str]:
    reports = tmp / "reports"
    done = subprocess.run([*CKESC, "run", "--dut", "bus", "--can-interface", "flaky", "--can-channel", "can0",
                           "--can-config", "host=127.0.0.1", "--can-config", f"port={port}", "--node-id", "1",
                           "--profile", "emulator", "-q", "--trace-format", "none", "--reports", str(reports),
                           *(a for c in config for a in ("--can-config", c)), "--", "-k", "test_s4_4_22_set_freq"],
                          cwd=tmp, env=_registered(tmp), capture_output=True, text=True, timeout=600)
    run = reports / "latest"
    return done, json.loads((run / "results.json").read_text()), (run / "summary.txt").read_text()


@pytest.fixture
def emulator(tmp_path):
    with Emulator(tmp_path) as emu:
        yield emu.port


def test_ckesc_run_errors_the_test_under_a_bus_fault_and_goes_on(tmp_path, emulator):
    done, doc, summary = _run(tmp_path, emulator, "fail_after=60")
    faults = [i for i, r in enumerate(doc["results"]) if "BusFault" in r["message"]]
    assert len(faults) == 1, done.stdout[-3000:]
    fault = doc["results"][faults[0]]
    assert fault["outcome"] == "ERROR" and "bus state ERROR" in fault["message"] and "bus-off" in fault["message"]
    assert "the CAN bus failed under this test" in fault["message"] and "the lane reopened it" in fault["message"]
    assert doc["info"]["incomplete"].startswith("subset")  # the selection, not aborted
    # the run went on, on the reopened bus (on a loaded machine a slow answer may ERROR another test, as on any bench)
    assert sum(r["outcome"] == "PASS" for r in doc["results"][faults[0] + 1:]) >= 5, done.stdout[-3000:]
    assert done.returncode == 1 and "bus failures recovered" in summary


def test_ckesc_run_aborts_when_the_bus_stays_gone(tmp_path, emulator):
    done, doc, summary = _run(tmp_path, emulator, "fail_after=60", "recover=False")
    assert done.returncode == 3, done.stdout[-3000:]
    assert doc["info"]["incomplete"].startswith("aborted: the CAN bus failed"), doc["info"]["incomplete"]
    assert "could not be reopened" in doc["info"]["incomplete"] and "no such device" in doc["info"]["incomplete"]
    assert doc["not_run"] and "ABORTED" in summary
