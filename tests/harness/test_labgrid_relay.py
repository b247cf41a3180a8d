"""The bus-fault relay through labgrid (``--bus-fault-cmd labgrid``, ckesc/bench/labgrid_relay.py; R20, issue #36),
for real on this machine: a labgrid environment file whose target has labgrid's own ``HttpDigitalOutputDriver`` on
an ``HttpDigitalOutput`` resource, the relay an HTTP server (``labgrid_lab.BusRelay``) whose contacts short a running
``ckesc emulate``'s bus through its control channel. ``ckesc run`` opens the relay with the bench, closes it for each
short of the R20 bus tests and opens it again, whatever happens: at the end, and on Ctrl-C in the middle of a short.

Not tried here: a relay board on USB or GPIO (``HIDRelayDriver``, ``GpioDigitalOutputDriver``: no such hardware on
this machine); the code path is the same ``DigitalOutputProtocol.set``. Without labgrid (the ``rig`` extra) the
labgrid tests skip and say so."""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
from labgrid_lab import BusRelay
from procs import CKESC, Emulator, realtime_profile
from procs import env as proc_env

from ckesc.bench.errors import PreflightError
from ckesc.bench.station import BenchOptions, build
from ckesc.emulator.control import control_request

needs_labgrid = pytest.mark.skipif(importlib.util.find_spec("labgrid") is None,
                                   reason='labgrid is not installed (pip install -e ".[rig]")')
pytestmark = [pytest.mark.realtime, needs_labgrid]

ROOT = Path(__file__).resolve().parents[2]
R20_BUS = str(ROOT / "conformance" / "test_robustness_r20_bus.py")


@pytest.fixture
def bench(tmp_path):
    """A running emulator (a DUT on a bus that echoes) and the labgrid relay across its bus."""
    with Emulator(tmp_path) as emu:
        relay = BusRelay(emu.control)
        try:
            yield emu, relay
        finally:
            relay.close()


def _env(tmp: Path) -> dict[str, str]:
    return dict(proc_env(tmp), NO_PROXY="127.0.0.1", no_proxy="127.0.0.1")  # requests (labgrid's HTTP driver) goes direct


def _args(tmp: Path, emu: Emulator, relay: BusRelay) -> list[str]:
    return ["run", R20_BUS, "-q", "--trace-format", "none", "--reports", str(tmp / "reports"),
            *emu.bench(realtime_profile(tmp)), "--allow-motor-spin", "--bus-fault-cmd", "labgrid",
            "--labgrid-env", str(relay.env_file(tmp))]


# slow while undiagnosed: the section's bit-rate test FAILs now and then in real time with 'a reset the host did not
# make (msg1)' (R19) on the conforming emulator: 2 of 3 CI runs on 2026-12-03, and 1 to 2 of 3 copies run at once,
# with the reader of 211d0fb as with today's (the closing note of that day); the relay's own tests below stay in CI
@pytest.mark.slow
def test_the_r20_shorts_go_through_the_labgrid_relay(tmp_path, bench):
    emu, relay = bench
    done = subprocess.run([*CKESC, *_args(tmp_path, emu, relay)], cwd=tmp_path, env=_env(tmp_path),
                          capture_output=True, text=True, timeout=600)
    doc = json.loads((tmp_path / "reports" / "latest" / "results.json").read_text())
    outcomes = {r["nodeid"].split("::")[-1]: (r["outcome"], r.get("message") or "") for r in doc["results"]}
    status = control_request(emu.control, {"cmd": "status"})
    assert outcomes["test_reports_go_on_after_a_bus_fault[short]"][0] == "PASS", outcomes
    assert outcomes["test_comm_flag_rises_through_a_bus_short_and_clears"][0] == "PASS", outcomes
    skipped, why = outcomes["test_reports_go_on_after_a_bus_fault[other_bitrate]"]
    assert skipped == "SKIPPED" and "a relay shorts the bus only" in why, why
    # opened with the bench, closed and opened for each short, opened again with the bench's close
    assert relay.switched == [0, 1, 0, 1, 0, 0], relay.switched
    assert status["bus_counters"]["bus_faults"] == 2 and status["bus_fault"] is None
    assert done.returncode == 0, done.stdout[-3000:]


@pytest.mark.slow
def test_ctrl_c_in_the_middle_of_a_short_opens_the_relay(tmp_path, bench):
    """Ctrl-C (SIGINT to the run) as the relay closes: the run stops, the relay is open and the bus free after."""
    emu, relay = bench
    proc = subprocess.Popen([*CKESC, *_args(tmp_path, emu, relay), "--", "-k", "short"], cwd=tmp_path, env=_env(tmp_path),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    relay.on_close = lambda: os.kill(proc.pid, signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
    status = control_request(emu.control, {"cmd": "status"})
    assert relay.switched[:2] == [0, 1] and relay.switched[-1] == 0 and not relay.closed, (relay.switched, out[-2000:])
    assert status["bus_fault"] is None and status["escs"][0]["can"]["state"] == "ERROR-ACTIVE", status
    assert proc.returncode != 0, out[-2000:]


def _target_without_relay(tmp: Path) -> Path:
    path = tmp / "norelay.yaml"
    path.write_text("targets:\n  esc:\n    drivers: {}\n")
    return path


def test_a_target_without_a_relay_driver_is_refused_before_any_test(tmp_path, bench):
    emu, _ = bench
    start = time.monotonic()
    with pytest.raises(PreflightError, match=r"has no relay driver \(DigitalOutputProtocol"):
        build(BenchOptions(**_options(emu), bus_fault_cmd="labgrid", labgrid_env=str(_target_without_relay(tmp_path))))
    assert time.monotonic() - start < 30


def _options(emu: Emulator) -> dict:
    return {"dut": "bus", "can_interface": "socketcand", "can_channel": "can0",
            "can_config": ("host=127.0.0.1", f"port={emu.port}"), "node_id": 1}


@pytest.mark.parametrize(("given", "said"), [
    ({"bus_fault_cmd": "relay on"}, "needs {seconds}"),
    ({"bus_fault_cmd": "no-such-relay-tool {seconds}"}, "program 'no-such-relay-tool' not found"),
    ({"bus_fault_cmd": "labgrid"}, "--bus-fault-cmd labgrid needs --labgrid-env FILE"),
    ({"bus_fault_cmd": "labgrid", "labgrid_env": "/nonexistent/env.yaml"}, "no such file"),
])
def test_a_bus_fault_command_is_checked_before_anything_is_opened(given, said):
    with pytest.raises(PreflightError, match=said):
        build(BenchOptions(dut="bus", can_interface="virtual", **given))


def test_the_emulators_bus_faults_are_the_suites_own():
    with pytest.raises(PreflightError, match="--bus-fault-cmd is for --dut bus"):
        build(BenchOptions(bus_fault_cmd="relay {seconds}"))


RELAY = "    drivers:\n      HttpDigitalOutputDriver: {}\n"
#: a labgrid set-up mistake, the environment file that makes it, the target named (None: the file's only one) and
#: the one-line error ``--power labgrid`` and ``--bus-fault-cmd labgrid`` both give (what names the driver aside)
SETUP_MISTAKES = [
    pytest.param("targets: [esc\n", None, "--labgrid-env {env}: not a labgrid environment file: ", id="not-yaml"),
    pytest.param(f"targets:\n  a:\n{RELAY}  b:\n{RELAY}", None, "--labgrid-env {env} has targets a, b: name one with "
                 "--labgrid-target", id="several-targets"),
    pytest.param(f"targets:\n  esc:\n{RELAY}", "other", "--labgrid-env {env}: no target 'other' (targets: esc)",
                 id="no-such-target"),
    pytest.param("targets:\n  esc:\n    drivers:\n      NetworkPowerDriver: {}\n      HttpDigitalOutputDriver: {}\n",
                 None, "--labgrid-env {env}: target esc of {env}: NoResourceFoundError: binding ", id="unbound-driver"),
]


@pytest.mark.parametrize(("text", "target", "said"), SETUP_MISTAKES)
def test_the_relay_and_the_power_take_their_labgrid_target_alike(tmp_path, text, target, said):
    """The relay and the power open their target's driver through one helper (labgrid_power.environment and
    open_driver): each set-up mistake is the same one-line PreflightError for both, naming the file and the target."""
    from ckesc.bench.labgrid_power import open_power
    from ckesc.bench.labgrid_relay import open_relay

    env = tmp_path / "env.yaml"
    env.write_text(text)
    options = {"power": "labgrid", "labgrid_env": str(env), "labgrid_target": target}
    errors = []
    for opening in (lambda: open_relay(str(env), target), lambda: open_power(options.get)):
        with pytest.raises(PreflightError) as caught:
            opening()
        errors.append(str(caught.value))
    said = said.format(env=env)
    assert all(e.startswith(said) and "\n" not in e for e in errors), errors
