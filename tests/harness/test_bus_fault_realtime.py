"""Bus faults in real time (R20, issue #36): ``ckesc control bus`` shorts the bus of a running ``ckesc emulate``
(ckesc/emulator/hub_can.py plays the ESCs' controllers on its hub), and ``ckesc run`` runs the R20 bus tests
(conformance/test_robustness_r20_bus.py) on the real-time lane instead of SKIPping them: with echo (``--lane
realtime``, the bench's hook takes the emulator's own control) and without (the emulator reached as a bus, the
fault through ``--bus-fault-cmd "ckesc control ... bus {kind} {seconds}"``, as a real bench's command). Every part
a real process on 127.0.0.1; the faults ``no_busoff_recovery`` and ``busoff_recovery_resets`` are caught in real
time as in simulated time (the same verdicts)."""

from __future__ import annotations

import json
import shlex
import subprocess
from pathlib import Path

import can
import pytest
from procs import CKESC, Emulator, realtime_profile
from procs import env as _env

from ckesc.emulator.control import control_request
from ckesc.protocol.canbus import recovery_seconds
from ckesc.protocol.catalogue import DEFAULT_BITRATE
from ckesc.protocol.frame import frame_bits

pytestmark = pytest.mark.realtime  # wall-clock timing with real processes: one at a time under xdist (tests/conftest.py)

R20_BUS = "conformance/test_robustness_r20_bus.py"
ROOT = Path(__file__).resolve().parents[2]
TESTS = {"test_reports_go_on_after_a_bus_fault[short]", "test_reports_go_on_after_a_bus_fault[other_bitrate]",
         "test_comm_flag_rises_through_a_bus_short_and_clears"}
#: the R20 file's tests that a faultless run gives: the bus faults' and R20's bit-rate test (which needs no bus fault)
RUN = TESTS | {"test_an_esc_at_another_bit_rate_takes_nothing"}


def _run(tmp: Path, name: str, *args: str) -> tuple[int, dict[str, tuple[str, str]], dict]:
    reports = tmp / name
    done = subprocess.run([*CKESC, "run", str(ROOT / R20_BUS), "-q", "--trace-format", "none", "--reports",
                           str(reports), *args], cwd=tmp, env=_env(tmp), capture_output=True, text=True, timeout=600)
    results = reports / "latest" / "results.json"
    assert results.exists(), done.stdout[-3000:] + done.stderr[-3000:]
    doc = json.loads(results.read_text())
    return done.returncode, {r["nodeid"].split("::")[-1]: (r["outcome"], r.get("message") or "") for r in doc["results"]}, doc


def _ckesc_control(emu: Emulator, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*CKESC, "control", "--port", str(emu.control), *args], capture_output=True, text=True,
                          timeout=60)


def test_ckesc_control_shorts_the_emulators_bus_and_its_esc_comes_back_after_recovery(tmp_path):
    """Nothing reaches the bus while it is shorted; the ESC, bus-off since its first report in the short, sends
    again 128 x 11 bits after the bus is free (its first frame stamped at its end), and the status says so."""
    with Emulator(tmp_path) as emu:
        bus = can.Bus(interface="socketcand", host="127.0.0.1", port=emu.port, channel="can0", tcp_tune=True,
                      ignore_config=True)
        try:
            assert bus.recv(5.0) is not None  # booted, reporting
            done = _ckesc_control(emu, "bus", "short", "0.3")
            assert done.returncode == 0, done.stderr
            answer = json.loads(done.stdout)
            frames = []
            while (msg := bus.recv(0.2)) is not None and msg.timestamp < answer["ended"] + 0.1:
                frames.append(msg)
        finally:
            bus.shutdown()
        status = control_request(emu.control, {"cmd": "status"})
        twice = [_ckesc_control(emu, "bus", "short", "on") for _ in range(2)]
        off = _ckesc_control(emu, "bus", "short", "off")
    assert answer["ended"] - answer["started"] == pytest.approx(0.3)
    assert not [m for m in frames if answer["started"] + 0.001 < m.timestamp < answer["ended"]]
    first = min(m.timestamp for m in frames if m.timestamp >= answer["ended"])
    # stamped at its end: the recovery, then the frame's own bits (the emulator stamps a frame's due time exactly)
    assert first - answer["ended"] == pytest.approx(recovery_seconds(DEFAULT_BITRATE) + frame_bits(8) / DEFAULT_BITRATE,
                                                     abs=frame_bits(8) / DEFAULT_BITRATE)
    assert status["bus_counters"]["esc_bus_off"] == 1 and status["bus_counters"]["esc_recovered"] == 1
    assert status["escs"][0]["can"]["state"] == "ERROR-ACTIVE" and status["bus_fault"] is None
    assert twice[0].returncode == 0 and twice[1].returncode == 1
    assert twice[1].stderr.strip() == "ckesc control: error: a bus fault (short) is on until ended"
    assert off.returncode == 0 and json.loads(off.stdout)["was_on"] is True


def test_the_r20_bus_tests_run_in_real_time_with_the_emulators_own_control(tmp_path):
    code, outcomes, doc = _run(tmp_path, "echo", "--lane", "realtime")
    assert doc["info"]["echo"] is True
    assert set(outcomes) == RUN and {o for o, _ in outcomes.values()} == {"PASS"}, outcomes
    assert code == 0


@pytest.mark.slow
def test_the_r20_bus_tests_run_without_echo_through_a_bus_fault_command(tmp_path):
    """The emulator as a third-party DUT on a bus that does not echo the host's frames; the fault through the
    command a real bench gives (here ``ckesc control``'s)."""
    with Emulator(tmp_path, "--no-echo-own") as emu:
        cmd = shlex.join([*CKESC, "control", "--port", str(emu.control), "bus"]) + " {kind} {seconds}"
        code, outcomes, doc = _run(tmp_path, "no-echo", *emu.bench(realtime_profile(tmp_path)), "--allow-motor-spin",
                                   "--bus-fault-cmd", cmd)
        status = control_request(emu.control, {"cmd": "status"})
    assert doc["info"]["echo"] is False
    assert set(outcomes) == RUN and {o for o, _ in outcomes.values()} == {"PASS"}, outcomes
    assert status["bus_counters"]["bus_faults"] == 3 and status["bus_counters"]["esc_recovered"] >= 2
    assert code == 0


@pytest.mark.parametrize("fault", [
    "busoff_recovery_resets",
    pytest.param("no_busoff_recovery", marks=pytest.mark.slow),
])
def test_a_bus_off_fault_is_caught_in_real_time(tmp_path, fault):
    """Each fault FAILs every R20 bus test, as in simulated time."""
    code, outcomes, _ = _run(tmp_path, fault, "--lane", "realtime", "--emulator-faults", fault)
    failed = {name for name, (outcome, _) in outcomes.items() if outcome == "FAIL"}
    assert failed == TESTS, outcomes
    for name in failed:
        assert outcomes[name][1].startswith("[R20-"), outcomes[name]
    assert {o for name, (o, _) in outcomes.items() if name not in failed} <= {"PASS"}, outcomes
    assert code == 1
